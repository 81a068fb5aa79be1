#include "tracking/feature_budget.h"

#include <algorithm>
#include <numeric>
#include <set>

#include <gtest/gtest.h>

#include "m2s/common/feature_rank.h"

namespace m2s::slam {
namespace {

SortedFeatures MakeFeatures(std::vector<VertexId> ids) {
  std::sort(ids.begin(), ids.end());
  SortedFeatures f;
  for (const VertexId id : ids) {
    f.ids.push_back(id);
    f.uvs.emplace_back(id % 640, id / 640 % 480);  // the uv travels with its id
  }
  return f;
}

const FeatureGrid kGrid = FeatureGrid::ForImage(640, 480);

// The client-side selection (KeepBalanced on wire features) of the same features: the
// reference the server must agree with.
std::set<VertexId> ClientSelection(const SortedFeatures& f, int budget) {
  std::vector<VertexFeature> wire;
  for (size_t i = 0; i < f.size(); ++i) wire.push_back({f.ids[i], f.uvs[i].cast<float>()});
  KeepBalanced(budget, kGrid, &wire);
  std::set<VertexId> ids;
  for (const VertexFeature& w : wire) ids.insert(w.id);
  return ids;
}

TEST(FeatureBudget, KeepsTheBalancedSelectionInIdOrderWithTheirUvs) {
  std::vector<VertexId> ids(5000);
  std::iota(ids.begin(), ids.end(), 100);
  for (VertexId& id : ids) id = id * 97 % 307200;  // spread over the whole image
  SortedFeatures f = MakeFeatures(ids);
  const std::set<VertexId> expected = ClientSelection(f, 700);
  EXPECT_EQ(ApplyFeatureBudget(700, kGrid, &f), 4300u);
  ASSERT_EQ(f.size(), 700u);
  ASSERT_EQ(f.uvs.size(), 700u);
  EXPECT_TRUE(std::is_sorted(f.ids.begin(), f.ids.end()));
  EXPECT_EQ(std::set<VertexId>(f.ids.begin(), f.ids.end()), expected);
  for (size_t i = 0; i < f.size(); ++i) {
    EXPECT_EQ(f.uvs[i], Eigen::Vector2d(f.ids[i] % 640, f.ids[i] / 640 % 480));
  }
}

TEST(FeatureBudget, ClientSideSelectionIsTheSameSubset) {
  // A client that keeps the balanced selection before sending (KeepBalanced on the unsorted
  // wire features) sends exactly what the server's budget would keep.
  std::vector<VertexFeature> wire;
  for (VertexId id = 90000; id > 1000; id -= 3) {
    wire.push_back({id, {static_cast<float>(id % 640), static_cast<float>(id / 640 % 480)}});
  }
  std::vector<VertexId> ids;
  for (const VertexFeature& f : wire) ids.push_back(f.id);
  SortedFeatures server = MakeFeatures(ids);
  ApplyFeatureBudget(500, kGrid, &server);
  EXPECT_EQ(KeepBalanced(500, kGrid, &wire), ids.size() - 500);
  std::vector<VertexId> sent;
  for (const VertexFeature& f : wire) sent.push_back(f.id);
  EXPECT_TRUE(std::is_sorted(sent.rbegin(), sent.rend()));  // the client's order is kept
  std::sort(sent.begin(), sent.end());
  EXPECT_EQ(sent, server.ids);
}

TEST(FeatureBudget, UnderBudgetOrZeroKeepsEverything) {
  SortedFeatures f = MakeFeatures({5, 9, 12});
  EXPECT_EQ(ApplyFeatureBudget(3, kGrid, &f), 0u);
  EXPECT_EQ(ApplyFeatureBudget(0, kGrid, &f), 0u);
  EXPECT_EQ(f.ids, (std::vector<VertexId>{5, 9, 12}));
}

TEST(FeatureBudget, OverlappingViewsKeepTheSameIds) {
  // Two views of one mesh sharing most vertices: an id kept in both views' intersection is
  // kept whenever it ranks under both thresholds, so the kept sets overlap like the views.
  std::vector<VertexId> a(20000), b;
  std::iota(a.begin(), a.end(), 0);
  for (VertexId id = 2000; id < 22000; ++id) b.push_back(id);  // 90 % shared
  SortedFeatures fa = MakeFeatures(a), fb = MakeFeatures(b);
  ApplyFeatureBudget(1000, kGrid, &fa);
  ApplyFeatureBudget(1000, kGrid, &fb);
  std::vector<VertexId> shared;
  std::set_intersection(fa.ids.begin(), fa.ids.end(), fb.ids.begin(), fb.ids.end(),
                        std::back_inserter(shared));
  // Expected ~900 (the 90 % overlap); an order-dependent or random pick would give ~45.
  EXPECT_GT(shared.size(), 800u);
}

TEST(FeatureBudget, SpreadsOverTheIdRange) {
  // Mesh ids follow the vertex order (often spatial): the rank must not, or a budget would
  // keep one corner of the scene.
  std::vector<VertexId> ids(50000);
  std::iota(ids.begin(), ids.end(), 0);
  SortedFeatures f = MakeFeatures(ids);
  ApplyFeatureBudget(1000, kGrid, &f);
  std::vector<int> per_decile(10, 0);
  for (const VertexId id : f.ids) ++per_decile[id / 5000];
  for (const int n : per_decile) {
    EXPECT_GT(n, 60);  // 100 expected, binomial sd ~9.5
    EXPECT_LT(n, 140);
  }
}

}  // namespace
}  // namespace m2s::slam
