// Keyframe culling's selection on a small map with known observers: which keyframes are
// redundant, which are examined, which one a bounded map gives up, the link a culled keyframe
// leaves, and what culling one removes.
#include "mapping/keyframe_culling.h"

#include <gtest/gtest.h>

#include "covisibility_map.h"

namespace m2s::slam {
namespace {

using testing::MakeCovisibilityMap;

MapperOptions WithRedundancy(double fraction, int other_observers = 3) {
  MapperOptions o;
  o.keyframe_redundancy = fraction;
  o.keyframe_redundancy_observers = other_observers;
  return o;
}

// Keyframe 5 is the newest. Group 0 (seen by 0, 1) only; group 1 by 1, 2, 4, 5 (each of
// them sees its points with three others); group 2 by 3, 5; group 3 by 3, 4.
struct Culling {
  std::vector<std::vector<VertexId>> groups;
  MapData map = MakeCovisibilityMap(
      {0, 1, 2, 3, 4, 5}, {{20, {0, 1}}, {20, {1, 2, 4, 5}}, {20, {3, 5}}, {20, {3, 4}}}, &groups);
};

TEST(KeyframeCulling, RedundancyCountsPointsSeenByEnoughOthers) {
  const Culling c;
  const Redundancy two = MeasureRedundancy(c.map, 2, 3);
  EXPECT_EQ(two.observed, 20);
  EXPECT_EQ(two.redundant, 20);
  const Redundancy four = MeasureRedundancy(c.map, 4, 3);
  EXPECT_EQ(four.observed, 40);
  EXPECT_EQ(four.redundant, 20);  // group 3 has one other observer
  EXPECT_EQ(MeasureRedundancy(c.map, 4, 1).redundant, 40);
  EXPECT_EQ(MeasureRedundancy(c.map, 4, 4).redundant, 0);  // group 1 has three others
  const Redundancy three = MeasureRedundancy(c.map, 3, 3);
  EXPECT_EQ(three.observed, 40);
  EXPECT_EQ(three.redundant, 0);
  EXPECT_EQ(MeasureRedundancy(c.map, 99, 3).observed, 0);  // no such keyframe
}

TEST(KeyframeCulling, RedundantWhenTheFractionIsReached) {
  const Culling c;
  EXPECT_TRUE(IsRedundant(c.map, 2, WithRedundancy(1.0)));   // all its points
  EXPECT_FALSE(IsRedundant(c.map, 4, WithRedundancy(1.0)));  // half of them
  EXPECT_TRUE(IsRedundant(c.map, 4, WithRedundancy(0.5)));
  EXPECT_FALSE(IsRedundant(c.map, 3, WithRedundancy(0.1)));
  // Group 1's points have three other observers: not enough when more are asked for.
  EXPECT_FALSE(IsRedundant(c.map, 2, WithRedundancy(1.0, 4)));
  EXPECT_FALSE(IsRedundant(c.map, 2, MapperOptions()));  // the default asks for 20
  EXPECT_TRUE(IsRedundant(c.map, 4, WithRedundancy(1.0, 1)));
  const MapData empty = MakeCovisibilityMap({0, 1}, {});
  EXPECT_FALSE(IsRedundant(empty, 1, WithRedundancy(0.1)));  // observes nothing
}

TEST(KeyframeCulling, CandidatesAreTheNewestsNeighboursButTheFirstAndItself) {
  const Culling c;
  MapperOptions options;
  // 5's neighbours share 20 points each (ties: newer first); 0 shares nothing with 5.
  EXPECT_EQ(CullingCandidates(c.map, 5, options), (std::vector<KeyframeId>{4, 3, 2, 1}));
  options.local_ba_window = 2;
  EXPECT_EQ(CullingCandidates(c.map, 5, options), (std::vector<KeyframeId>{4, 3}));
  // The first keyframe is never a candidate.
  EXPECT_EQ(CullingCandidates(c.map, 1, MapperOptions()), (std::vector<KeyframeId>{5, 4, 2}));
}

TEST(KeyframeCulling, EachCullChangesTheNextDecision) {
  Culling c;
  const MapperOptions half = WithRedundancy(0.5);
  ASSERT_TRUE(IsRedundant(c.map, 4, half));
  CullKeyframe(&c.map, 2);
  // Group 1 lost an observer: 4 sees it with two others now.
  EXPECT_FALSE(IsRedundant(c.map, 4, half));
}

TEST(KeyframeCulling, BoundedMapGivesUpTheOldestButTheFirst) {
  const Culling c;
  MapperOptions options;
  options.max_keyframes = 6;
  EXPECT_FALSE(OldestBeyondBound(c.map, 5, options).has_value());
  options.max_keyframes = 5;
  EXPECT_EQ(OldestBeyondBound(c.map, 5, options), std::optional<KeyframeId>(1));
  EXPECT_FALSE(OldestBeyondBound(c.map, 1, options).has_value());  // never the newest
}

TEST(KeyframeCulling, LinkGoesToTheNearestWellCovisibleKeyframe) {
  const Culling c;
  // 2 shares group 1 with 1 (x = 0.1), 4 (x = 0.4) and 5; 1 is the nearest.
  const KeyframeLink link = CullLink(c.map, 2);
  EXPECT_EQ(link.parent, 1u);
  EXPECT_TRUE(link.parent_from_camera.translation().isApprox(Eigen::Vector3d(0.1, 0, 0)));
  // Without covisible keyframes: the previous one by id (the next one for the first).
  const MapData apart = MakeCovisibilityMap({3, 7, 9}, {{20, {3}}, {20, {7}}, {20, {9}}});
  EXPECT_EQ(CullLink(apart, 7).parent, 3u);
  EXPECT_EQ(CullLink(apart, 3).parent, 7u);
}

TEST(KeyframeCulling, CullingRemovesTheKeyframeAndThePointsItLeavesUnsupported) {
  Culling c;
  const Pose3 pose = c.map.keyframe(3)->world_from_camera;
  CullKeyframe(&c.map, 3);
  EXPECT_EQ(c.map.keyframe(3), nullptr);
  // Groups 2 and 3 are left with one observer each: gone; the others stay.
  for (const VertexId v : c.groups[2]) EXPECT_EQ(c.map.point(v), nullptr);
  for (const VertexId v : c.groups[3]) EXPECT_EQ(c.map.point(v), nullptr);
  for (const VertexId v : c.groups[1]) EXPECT_NE(c.map.point(v), nullptr);
  // Its trajectory entries resolve through the link.
  const std::optional<Pose3> resolved = c.map.ResolveKeyframePose(3);
  ASSERT_TRUE(resolved.has_value());
  EXPECT_TRUE(resolved->translation().isApprox(pose.translation()));
}

}  // namespace
}  // namespace m2s::slam
