// A fixed ranking of vertex ids, for bounded, id-stable subsets of a frame's features, and the
// balanced selection built on it.
//
// A 640x480 view of a dense mesh sees ~10^4 vertices; SLAM needs ~10^3 (exact association, no
// outliers to outvote). Each vertex id gets a fixed pseudo-random rank (a bijective 64-bit mix
// of the id, so ranks do not follow the mesh's vertex order); a frame keeps the `budget`
// features of lowest rank. The subset is therefore the same in every view (a vertex kept in
// one view is kept in every view where fewer than `budget` visible vertices outrank it), spread
// uniformly over the image, and independent of the features' order. The client may send only
// that subset and the server selects the same one (slam::Options::feature_budget).
//
//   const uint64_t threshold = FeatureRankThreshold(ids, 2000);
//   keep feature i  <=>  FeatureRank(ids[i]) <= threshold
//
// Balanced selection (SelectBalanced, KeepBalanced) removes the rank selection's one weakness:
// it keeps features in proportion to vertex density, so a dense scanned object takes the whole
// budget and sparse walls get almost none. The image is cut into a grid (FeatureGrid); within
// each cell the features are ordered by rank, and a feature's *level* is its place in that
// order (1 for the lowest-ranked feature of its cell). Features are kept by level, then by rank:
// first the lowest-ranked feature of every non-empty cell, then the second of every cell that
// has one, and so on, until the budget is spent. Cells with few features keep all of them and
// leave their share to the others. The selection stays id-stable (a feature's level changes
// only when features of lower rank enter or leave its cell), independent of feature order,
// and nested: selecting N features from the selection of M >= N gives the selection of N, so
// a client that sends a larger budget and a server that keeps a smaller one still agree.
//
//   const FeatureGrid grid = FeatureGrid::ForImage(camera.width, camera.height);
//   KeepBalanced(2000, grid, &features);   // at most 2000, spread over the grid
#pragma once

#include <cmath>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "m2s/common/types.h"

namespace m2s {

// The rank of a vertex id (lower is kept first). Distinct ids have distinct ranks: splitmix64's
// finaliser, bijective on 64 bits. Inline: a large view asks it for millions of vertices.
inline uint64_t FeatureRank(VertexId id) {
  uint64_t z = static_cast<uint64_t>(id) + 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// The highest rank kept when the `budget` lowest-ranked of `ids` (distinct) are kept:
// exactly min(budget, ids.size()) ids have FeatureRank(id) <= the result. UINT64_MAX (keep
// everything) when budget <= 0 or ids.size() <= budget.
uint64_t FeatureRankThreshold(std::span<const VertexId> ids, int budget);

// Keeps the `budget` lowest-ranked features, in their order (all when budget <= 0); the ids
// must be distinct. Returns the number removed.
size_t KeepLowestRanked(int budget, std::vector<VertexFeature>* features);

// Equal cells over an image: kGridCols across, rows in proportion to the aspect ratio (16 x 12
// at 4:3). Client and server derive it from the session's camera, so they agree.
struct FeatureGrid {
  static constexpr int kGridCols = 16;
  int cols = 1;
  int rows = 1;
  double cell_width = 1.0;
  double cell_height = 1.0;

  static FeatureGrid ForImage(int width, int height);
  int num_cells() const { return cols * rows; }
  // The cell of (u, v); points outside the image (within a validation margin) go to the
  // nearest cell; NaN goes to cell 0. Inline: a large view asks it for millions of features.
  int CellOf(double u, double v) const {
    return Index(v, cell_height, rows) * cols + Index(u, cell_width, cols);
  }

 private:
  static int Index(double x, double step, int count) {
    const double i = std::floor(x / step);
    if (!(i >= 0.0)) return 0;  // negative or NaN
    return i >= count - 1 ? count - 1 : static_cast<int>(i);
  }
};

// Balanced selection (see the top of this file): the indices of the kept features, ascending.
// `cells[i]` is feature i's cell (FeatureGrid::CellOf); ids must be distinct. Every index is
// kept when budget <= 0 or there are not more than `budget` features.
std::vector<uint32_t> SelectBalanced(std::span<const VertexId> ids, std::span<const int> cells,
                                     int budget);

// SelectBalanced's rule on per-cell counts, for callers that gather each cell's lowest ranks
// themselves (CpuProjector::ProjectBalanced). Whole levels: the largest L, at most the largest
// count, with sum over cells of min(count[c], L) <= budget (budget >= 0).
uint32_t BalancedLevels(std::span<const uint32_t> count, int budget);
// How many of each cell's lowest-ranked features the selection keeps: min(count[c], levels),
// and one more in the cells whose next feature is among the lowest-ranked of the cells' next
// features, as many as the budget leaves (next_rank[c]: the rank of cell c's next feature,
// read where count[c] > levels; ranks distinct). `levels` is BalancedLevels(count, budget).
std::vector<uint32_t> BalancedTakes(std::span<const uint32_t> count, uint32_t levels, int budget,
                                    std::span<const uint64_t> next_rank);

// Balanced selection over any feature layout, with buffers kept between calls (a view of
// millions of features allocates nothing per frame in steady state).
class BalancedSelector {
 public:
  // The indices (ascending) SelectBalanced keeps among n features; feature i has the id
  // id_of(i) and the image point uv_of(i), a pair (u, v).
  template <typename IdOf, typename UvOf>
  const std::vector<uint32_t>& Select(size_t n, IdOf id_of, UvOf uv_of, const FeatureGrid& grid,
                                      int budget) {
    ids_.resize(n);
    cells_.resize(n);
    for (size_t i = 0; i < n; ++i) {
      ids_[i] = id_of(i);
      const auto [u, v] = uv_of(i);
      cells_[i] = grid.CellOf(u, v);
    }
    kept_ = SelectBalanced(ids_, cells_, budget);
    return kept_;
  }

 private:
  std::vector<VertexId> ids_;
  std::vector<int> cells_;
  std::vector<uint32_t> kept_;
};

// Keeps the features SelectBalanced chooses, in their order. Returns the number removed.
size_t KeepBalanced(int budget, const FeatureGrid& grid, std::vector<VertexFeature>* features);

}  // namespace m2s
