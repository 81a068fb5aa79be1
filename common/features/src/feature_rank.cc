#include "m2s/common/feature_rank.h"

#include <algorithm>
#include <limits>

namespace m2s {

uint64_t FeatureRank(VertexId id) {
  // splitmix64's finaliser: bijective on 64 bits, so distinct ids never tie.
  uint64_t z = static_cast<uint64_t>(id) + 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

uint64_t FeatureRankThreshold(std::span<const VertexId> ids, int budget) {
  if (budget <= 0 || ids.size() <= static_cast<size_t>(budget))
    return std::numeric_limits<uint64_t>::max();
  std::vector<uint64_t> ranks(ids.size());
  for (size_t i = 0; i < ids.size(); ++i) ranks[i] = FeatureRank(ids[i]);
  const auto kth = ranks.begin() + (budget - 1);
  std::nth_element(ranks.begin(), kth, ranks.end());
  return *kth;
}

size_t KeepLowestRanked(int budget, std::vector<VertexFeature>* features) {
  if (budget <= 0 || features->size() <= static_cast<size_t>(budget)) return 0;
  std::vector<VertexId> ids(features->size());
  for (size_t i = 0; i < ids.size(); ++i) ids[i] = (*features)[i].id;
  const uint64_t threshold = FeatureRankThreshold(ids, budget);
  const size_t before = features->size();
  std::erase_if(*features,
                [threshold](const VertexFeature& f) { return FeatureRank(f.id) > threshold; });
  return before - features->size();
}

}  // namespace m2s
