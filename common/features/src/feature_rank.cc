#include "m2s/common/feature_rank.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace m2s {

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

FeatureGrid FeatureGrid::ForImage(int width, int height) {
  FeatureGrid grid;
  if (width <= 0 || height <= 0) return grid;
  grid.cols = kGridCols;
  grid.rows = std::max(1, static_cast<int>(std::lround(kGridCols * static_cast<double>(height) /
                                                       static_cast<double>(width))));
  grid.cell_width = static_cast<double>(width) / grid.cols;
  grid.cell_height = static_cast<double>(height) / grid.rows;
  return grid;
}

uint32_t BalancedLevels(std::span<const uint32_t> count, int budget) {
  auto whole_levels_size = [&](uint32_t level) {
    size_t total = 0;
    for (const uint32_t k : count) total += std::min(k, level);
    return total;
  };
  uint32_t lo = 0, hi = count.empty() ? 0 : *std::max_element(count.begin(), count.end());
  while (lo < hi) {  // the largest level that fits
    const uint32_t mid = lo + (hi - lo + 1) / 2;
    if (whole_levels_size(mid) <= static_cast<size_t>(std::max(budget, 0))) {
      lo = mid;
    } else {
      hi = mid - 1;
    }
  }
  return lo;
}

std::vector<uint32_t> BalancedTakes(std::span<const uint32_t> count, uint32_t levels, int budget,
                                    std::span<const uint64_t> next_rank) {
  std::vector<uint32_t> take(count.size());
  std::vector<std::pair<uint64_t, uint32_t>> candidates;  // (next rank, cell)
  size_t kept = 0;
  for (size_t c = 0; c < count.size(); ++c) {
    take[c] = std::min(count[c], levels);
    kept += take[c];
    if (count[c] > levels) candidates.emplace_back(next_rank[c], static_cast<uint32_t>(c));
  }
  const size_t room = static_cast<size_t>(std::max(budget, 0));
  const size_t rest = kept >= room ? 0 : std::min(candidates.size(), room - kept);
  std::nth_element(candidates.begin(), candidates.begin() + static_cast<ptrdiff_t>(rest),
                   candidates.end());
  for (size_t k = 0; k < rest; ++k) ++take[candidates[k].second];
  return take;
}

std::vector<uint32_t> SelectBalanced(std::span<const VertexId> ids, std::span<const int> cells,
                                     int budget) {
  const size_t n = ids.size();
  std::vector<uint32_t> kept;
  if (budget <= 0 || n <= static_cast<size_t>(budget)) {
    kept.resize(n);
    std::iota(kept.begin(), kept.end(), 0u);
    return kept;
  }
  int num_cells = 0;
  for (const int c : cells) num_cells = std::max(num_cells, c + 1);
  std::vector<uint32_t> count(static_cast<size_t>(num_cells), 0);
  for (const int c : cells) ++count[static_cast<size_t>(c)];
  const uint32_t levels = BalancedLevels(count, budget);
  // One pass keeps the levels + 1 lowest-ranked features of every cell in a max-heap of that
  // size (a view of millions of features needs no per-feature storage); ranks are distinct,
  // so the result does not depend on the features' order.
  struct Ranked {
    uint64_t rank;
    uint32_t index;
    bool operator<(const Ranked& o) const { return rank < o.rank; }
  };
  std::vector<uint32_t> begin(count.size() + 1, 0);
  for (size_t c = 0; c < count.size(); ++c)
    begin[c + 1] = begin[c] + std::min(count[c], levels + 1);
  std::vector<Ranked> lowest(begin.back());
  std::vector<uint32_t> filled(count.size(), 0);
  for (size_t i = 0; i < n; ++i) {
    const auto c = static_cast<size_t>(cells[i]);
    const uint64_t rank = FeatureRank(ids[i]);
    Ranked* heap = lowest.data() + begin[c];
    const uint32_t size = begin[c + 1] - begin[c];
    if (filled[c] < size) {
      heap[filled[c]++] = {rank, static_cast<uint32_t>(i)};
      if (filled[c] == size) std::make_heap(heap, heap + size);
    } else if (rank < heap[0].rank) {
      std::pop_heap(heap, heap + size);
      heap[size - 1] = {rank, static_cast<uint32_t>(i)};
      std::push_heap(heap, heap + size);
    }
  }
  // Every cell keeps its `levels` lowest-ranked features, and the fuller cells' next ones
  // share the rest of the budget by rank.
  std::vector<uint64_t> next_rank(count.size(), 0);
  for (size_t c = 0; c < count.size(); ++c) {
    std::sort(lowest.begin() + begin[c], lowest.begin() + begin[c + 1]);
    if (count[c] > levels) next_rank[c] = lowest[begin[c] + levels].rank;
  }
  const std::vector<uint32_t> take = BalancedTakes(count, levels, budget, next_rank);
  for (size_t c = 0; c < count.size(); ++c) {
    for (uint32_t k = 0; k < take[c]; ++k) kept.push_back(lowest[begin[c] + k].index);
  }
  std::sort(kept.begin(), kept.end());
  return kept;
}

size_t KeepBalanced(int budget, const FeatureGrid& grid, std::vector<VertexFeature>* features) {
  const size_t n = features->size();
  if (budget <= 0 || n <= static_cast<size_t>(budget)) return 0;
  BalancedSelector selector;
  const std::vector<uint32_t>& kept = selector.Select(
      n, [features](size_t i) { return (*features)[i].id; },
      [features](size_t i) {
        const Eigen::Vector2f& uv = (*features)[i].uv;
        return std::pair(uv.x(), uv.y());
      },
      grid, budget);
  for (size_t k = 0; k < kept.size(); ++k) (*features)[k] = (*features)[kept[k]];
  features->resize(kept.size());
  return n - kept.size();
}

}  // namespace m2s
