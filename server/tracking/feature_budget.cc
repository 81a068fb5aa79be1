#include "tracking/feature_budget.h"

#include "m2s/common/feature_rank.h"

namespace m2s::slam {

size_t ApplyFeatureBudget(int budget, SortedFeatures* features) {
  const size_t n = features->size();
  if (budget <= 0 || n <= static_cast<size_t>(budget)) return 0;
  const uint64_t threshold = FeatureRankThreshold(features->ids, budget);
  size_t out = 0;
  for (size_t i = 0; i < n; ++i) {
    if (FeatureRank(features->ids[i]) > threshold) continue;
    features->ids[out] = features->ids[i];
    features->uvs[out] = features->uvs[i];
    ++out;
  }
  features->ids.resize(out);
  features->uvs.resize(out);
  return n - out;
}

}  // namespace m2s::slam
