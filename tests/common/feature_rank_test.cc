#include "m2s/common/feature_rank.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <set>

#include <gtest/gtest.h>

namespace m2s {
namespace {

TEST(FeatureRank, DistinctIdsHaveDistinctRanks) {
  std::set<uint64_t> ranks;
  for (VertexId id = 0; id < 100000; ++id) ranks.insert(FeatureRank(id));
  EXPECT_EQ(ranks.size(), 100000u);
  EXPECT_NE(FeatureRank(0xffffffffu), FeatureRank(0));
}

TEST(FeatureRank, ThresholdKeepsExactlyTheBudget) {
  std::vector<VertexId> ids(3000);
  std::iota(ids.begin(), ids.end(), 7);
  for (const int budget : {1, 10, 999, 2999}) {
    const uint64_t t = FeatureRankThreshold(ids, budget);
    const auto kept =
        std::count_if(ids.begin(), ids.end(), [t](VertexId id) { return FeatureRank(id) <= t; });
    EXPECT_EQ(kept, budget);
  }
  EXPECT_EQ(FeatureRankThreshold(ids, 0), std::numeric_limits<uint64_t>::max());
  EXPECT_EQ(FeatureRankThreshold(ids, 3000), std::numeric_limits<uint64_t>::max());
}

TEST(FeatureRank, KeepLowestRankedMatchesASortByRank) {
  std::vector<VertexFeature> features;
  for (int i = 50000; i > 0; i -= 7) {
    const auto id = static_cast<VertexId>(i);
    features.push_back({id, {float(id % 640), 3.f}});
  }
  std::vector<VertexId> expected;
  for (const VertexFeature& f : features) expected.push_back(f.id);
  std::sort(expected.begin(), expected.end(),
            [](VertexId a, VertexId b) { return FeatureRank(a) < FeatureRank(b); });
  expected.resize(800);
  const size_t before = features.size();
  EXPECT_EQ(KeepLowestRanked(800, &features), before - 800);
  ASSERT_EQ(features.size(), 800u);
  std::vector<VertexId> kept;
  for (const VertexFeature& f : features) {
    EXPECT_EQ(f.uv.x(), float(f.id % 640));
    kept.push_back(f.id);
  }
  EXPECT_TRUE(std::is_sorted(kept.rbegin(), kept.rend()));  // input order preserved
  std::sort(kept.begin(), kept.end());
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(kept, expected);
}

// The balanced selection as its definition reads, by rounds: round L takes the L-th
// lowest-ranked feature of every cell that has one, lowest rank first, until the budget is
// spent. Returns the kept ids, sorted.
std::vector<VertexId> BalancedByRounds(const std::vector<VertexFeature>& features,
                                       const FeatureGrid& grid, int budget) {
  std::map<int, std::vector<VertexId>> by_cell;
  for (const VertexFeature& f : features) by_cell[grid.CellOf(f.uv.x(), f.uv.y())].push_back(f.id);
  for (auto& [cell, ids] : by_cell) {
    std::sort(ids.begin(), ids.end(),
              [](VertexId a, VertexId b) { return FeatureRank(a) < FeatureRank(b); });
  }
  std::vector<VertexId> kept;
  for (size_t round = 0; kept.size() < static_cast<size_t>(budget); ++round) {
    std::vector<VertexId> candidates;
    for (const auto& [cell, ids] : by_cell) {
      if (round < ids.size()) candidates.push_back(ids[round]);
    }
    if (candidates.empty()) break;
    std::sort(candidates.begin(), candidates.end(),
              [](VertexId a, VertexId b) { return FeatureRank(a) < FeatureRank(b); });
    for (VertexId id : candidates) {
      if (kept.size() == static_cast<size_t>(budget)) break;
      kept.push_back(id);
    }
  }
  std::sort(kept.begin(), kept.end());
  return kept;
}

std::vector<VertexId> SortedIds(const std::vector<VertexFeature>& features) {
  std::vector<VertexId> ids;
  for (const VertexFeature& f : features) ids.push_back(f.id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

// A 640 x 480 view of a cluttered scene: a dense scanned object covering a 120 x 100 px patch
// (`dense` vertices) in front of sparse walls (`sparse` vertices spread over the image).
std::vector<VertexFeature> ClutteredView(int dense, int sparse, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.f, 640.f), v(0.f, 480.f);
  std::uniform_real_distribution<float> pu(400.f, 520.f), pv(300.f, 400.f);
  std::vector<VertexFeature> features;
  VertexId id = 1000;
  for (int i = 0; i < sparse; ++i) features.push_back({id++, {u(rng), v(rng)}});
  for (int i = 0; i < dense; ++i) features.push_back({id++, {pu(rng), pv(rng)}});
  std::shuffle(features.begin(), features.end(), rng);
  return features;
}

TEST(FeatureGrid, CellsCoverTheImage) {
  const FeatureGrid grid = FeatureGrid::ForImage(640, 480);
  EXPECT_EQ(grid.cols, 16);
  EXPECT_EQ(grid.rows, 12);
  EXPECT_EQ(grid.CellOf(0, 0), 0);
  EXPECT_EQ(grid.CellOf(39.99, 39.99), 0);
  EXPECT_EQ(grid.CellOf(40.0, 0), 1);
  EXPECT_EQ(grid.CellOf(0, 40.0), 16);
  EXPECT_EQ(grid.CellOf(639.9, 479.9), 16 * 12 - 1);
  // Outside the image (the validator's margin) and NaN stay in the grid.
  EXPECT_EQ(grid.CellOf(-2.0, -2.0), 0);
  EXPECT_EQ(grid.CellOf(641.0, 481.0), 16 * 12 - 1);
  EXPECT_EQ(grid.CellOf(std::nan(""), 100.0), 2 * 16);
  const FeatureGrid wide = FeatureGrid::ForImage(1920, 1080);
  EXPECT_EQ(wide.cols, 16);
  EXPECT_EQ(wide.rows, 9);
}

TEST(BalancedSelection, MatchesTheSelectionByRounds) {
  const FeatureGrid grid = FeatureGrid::ForImage(640, 480);
  for (const uint32_t seed : {1u, 2u, 3u}) {
    const std::vector<VertexFeature> view = ClutteredView(6000, 400, seed);
    for (const int budget : {1, 150, 999, 2000, 6399}) {
      std::vector<VertexFeature> kept = view;
      EXPECT_EQ(KeepBalanced(budget, grid, &kept), view.size() - budget);
      EXPECT_EQ(SortedIds(kept), BalancedByRounds(view, grid, budget)) << seed << " " << budget;
    }
  }
}

TEST(BalancedSelection, KeepsEverythingWithinTheBudgetAndTheInputOrder) {
  const FeatureGrid grid = FeatureGrid::ForImage(640, 480);
  const std::vector<VertexFeature> view = ClutteredView(100, 50, 4);
  std::vector<VertexFeature> kept = view;
  EXPECT_EQ(KeepBalanced(150, grid, &kept), 0u);
  EXPECT_EQ(KeepBalanced(0, grid, &kept), 0u);  // 0: no budget
  ASSERT_EQ(kept.size(), view.size());
  EXPECT_EQ(KeepBalanced(60, grid, &kept), 90u);
  // The survivors keep their relative order and their coordinates.
  size_t j = 0;
  for (const VertexFeature& f : kept) {
    while (j < view.size() && view[j].id != f.id) ++j;
    ASSERT_LT(j, view.size()) << "order changed at id " << f.id;
    EXPECT_EQ(view[j].uv, f.uv);
  }
}

TEST(BalancedSelection, IndependentOfTheFeatureOrder) {
  const FeatureGrid grid = FeatureGrid::ForImage(640, 480);
  std::vector<VertexFeature> a = ClutteredView(3000, 300, 5);
  std::vector<VertexFeature> b = a;
  std::reverse(b.begin(), b.end());
  KeepBalanced(800, grid, &a);
  KeepBalanced(800, grid, &b);
  EXPECT_EQ(SortedIds(a), SortedIds(b));
}

// A client sending the balanced selection of M features and a server keeping N <= M of them
// end with the server's selection of the full view.
TEST(BalancedSelection, IsNested) {
  const FeatureGrid grid = FeatureGrid::ForImage(640, 480);
  for (const uint32_t seed : {6u, 7u}) {
    const std::vector<VertexFeature> view = ClutteredView(5000, 500, seed);
    for (const auto& [m, n] : {std::pair{4000, 2000}, {2000, 1999}, {1000, 150}, {600, 599}}) {
      std::vector<VertexFeature> sent = view, direct = view;
      KeepBalanced(m, grid, &sent);
      KeepBalanced(n, grid, &sent);
      KeepBalanced(n, grid, &direct);
      EXPECT_EQ(SortedIds(sent), SortedIds(direct)) << m << " -> " << n;
    }
  }
}

// The rank selection keeps features in proportion to density: a dense object starves the
// sparse walls. The balanced selection keeps every sparse vertex.
TEST(BalancedSelection, ADenseObjectDoesNotStarveTheSparseWalls) {
  const FeatureGrid grid = FeatureGrid::ForImage(640, 480);
  const int sparse = 300, dense = 20000, budget = 1500;
  const std::vector<VertexFeature> view = ClutteredView(dense, sparse, 8);
  auto sparse_kept = [&](const std::vector<VertexFeature>& kept) {
    // Sparse features have the ids 1000 .. 1000 + sparse - 1, and lie outside the patch or in it.
    return std::count_if(kept.begin(), kept.end(), [&](const VertexFeature& f) {
      return f.id < static_cast<VertexId>(1000 + sparse);
    });
  };
  std::vector<VertexFeature> by_rank = view, balanced = view;
  KeepLowestRanked(budget, &by_rank);
  KeepBalanced(budget, grid, &balanced);
  // Rank: about budget * sparse / (sparse + dense) = 22 sparse features.
  EXPECT_LT(sparse_kept(by_rank), 50);
  // Balanced: the sparse cells (about 2 features each) are below the water level; the patch
  // (about 12 cells) gets the rest. Sparse features inside the patch compete with the dense
  // ones, so a few of them may go.
  int sparse_in_patch = 0;
  for (const VertexFeature& f : view) {
    const bool in_patch = f.uv.x() >= 400 && f.uv.x() < 520 && f.uv.y() >= 300 && f.uv.y() < 400;
    if (f.id < static_cast<VertexId>(1000 + sparse) && in_patch) ++sparse_in_patch;
  }
  EXPECT_GE(sparse_kept(balanced), sparse - sparse_in_patch);
  EXPECT_EQ(balanced.size(), static_cast<size_t>(budget));
}

// Consecutive views of a moving camera keep mostly the same vertices: the property the rank
// selection has and tracking relies on.
TEST(BalancedSelection, ConsecutiveViewsKeepMostlyTheSameVertices) {
  const FeatureGrid grid = FeatureGrid::ForImage(640, 480);
  const std::vector<VertexFeature> view = ClutteredView(8000, 800, 9);
  std::vector<VertexFeature> next;
  for (VertexFeature f : view) {  // the camera pans by 3 px: everything shifts, a strip leaves
    f.uv.x() -= 3.f;
    if (f.uv.x() >= 0.f) next.push_back(f);
  }
  std::vector<VertexFeature> a = view, b = next;
  KeepBalanced(1500, grid, &a);
  KeepBalanced(1500, grid, &b);
  const std::vector<VertexId> ia = SortedIds(a), ib = SortedIds(b);
  std::vector<VertexId> common;
  std::set_intersection(ia.begin(), ia.end(), ib.begin(), ib.end(), std::back_inserter(common));
  const double shared = static_cast<double>(common.size()) / ia.size();
  std::printf("consecutive views share %.1f %% of the selection\n", 100.0 * shared);
  EXPECT_GT(shared, 0.9);
}

}  // namespace
}  // namespace m2s
