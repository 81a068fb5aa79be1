#include "tracking/feature_budget.h"

#include <algorithm>
#include <vector>

namespace m2s::slam {

uint64_t FeatureRank(VertexId id) {
  // splitmix64's finaliser: bijective, so distinct ids never tie.
  uint64_t z = static_cast<uint64_t>(id) + 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

size_t ApplyFeatureBudget(int budget, SortedFeatures* features) {
  const size_t n = features->size();
  if (budget <= 0 || n <= static_cast<size_t>(budget)) return 0;
  const size_t keep = static_cast<size_t>(budget);
  std::vector<uint64_t> ranks(n);
  for (size_t i = 0; i < n; ++i) ranks[i] = FeatureRank(features->ids[i]);
  std::vector<uint64_t> sorted = ranks;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(keep - 1),
                   sorted.end());
  const uint64_t threshold = sorted[keep - 1];  // ranks are distinct: exactly `keep` are <= it
  size_t out = 0;
  for (size_t i = 0; i < n; ++i) {
    if (ranks[i] > threshold) continue;
    features->ids[out] = features->ids[i];
    features->uvs[out] = features->uvs[i];
    ++out;
  }
  features->ids.resize(out);
  features->uvs.resize(out);
  return n - out;
}

}  // namespace m2s::slam
