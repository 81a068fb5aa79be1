#include "m2s/common/feature_rank.h"

#include <algorithm>
#include <limits>
#include <numeric>
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

}  // namespace
}  // namespace m2s
