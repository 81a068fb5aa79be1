#include "tracking/feature_budget.h"

#include <vector>

namespace m2s::slam {

size_t ApplyFeatureBudget(int budget, const FeatureGrid& grid, SortedFeatures* features) {
  const size_t n = features->size();
  if (budget <= 0 || n <= static_cast<size_t>(budget)) return 0;
  std::vector<int> cells(n);
  for (size_t i = 0; i < n; ++i) cells[i] = grid.CellOf(features->uvs[i].x(), features->uvs[i].y());
  const std::vector<uint32_t> kept = SelectBalanced(features->ids, cells, budget);
  // `kept` is ascending, so compacting in place keeps the order by id.
  for (size_t k = 0; k < kept.size(); ++k) {
    features->ids[k] = features->ids[kept[k]];
    features->uvs[k] = features->uvs[kept[k]];
  }
  features->ids.resize(kept.size());
  features->uvs.resize(kept.size());
  return n - kept.size();
}

}  // namespace m2s::slam
