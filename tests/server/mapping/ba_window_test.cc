// The bundle adjustments' selection on small maps with known covisibility: which keyframes are
// optimised, which are held fixed, which points enter, and the problem built from it.
#include "mapping/ba_window.h"

#include <gtest/gtest.h>

#include "covisibility_map.h"

namespace m2s::slam {
namespace {

using testing::IdsOf;
using testing::MakeCovisibilityMap;
using testing::PointGroup;

std::vector<KeyframeId> Ids(const BaWindow& w, bool fixed) {
  std::vector<KeyframeId> out;
  for (const BaWindow::Member& k : w.keyframes) {
    if (k.fixed == fixed) out.push_back(k.id);
  }
  return out;
}

MapperOptions WithWindow(int keyframes, int max_points = 0) {
  MapperOptions o;
  o.local_ba_window = keyframes;
  o.local_ba_max_points = max_points;
  return o;
}

// Keyframe 5 is the newest. It shares 20 points with 4 and with 3, 16 with 2 and 10 with 1 (too
// few for a neighbour); 3 shares 20 with 0; 0 and 1 share 20 nobody else sees.
struct SixKeyframes {
  std::vector<std::vector<VertexId>> groups;
  MapData map = MakeCovisibilityMap(
      {0, 1, 2, 3, 4, 5},
      {{20, {4, 5}}, {20, {3, 5}}, {16, {2, 5}}, {10, {1, 5}}, {20, {0, 3}}, {20, {0, 1}}},
      &groups);
};

TEST(BaWindow, CovisibleNeighboursAreTheBestSharingOnes) {
  const SixKeyframes s;
  // Ties (4 and 3 share 20 each) go to the newer keyframe; 1 shares too few.
  EXPECT_EQ(CovisibleNeighbours(s.map, 5, 10), (std::vector<KeyframeId>{4, 3, 2}));
  EXPECT_EQ(CovisibleNeighbours(s.map, 5, 2), (std::vector<KeyframeId>{4, 3}));
  EXPECT_TRUE(CovisibleNeighbours(s.map, 5, 0).empty());
}

TEST(BaWindow, LocalWindowOptimisesTheNeighboursAndFixesTheOtherObservers) {
  const SixKeyframes s;
  const BaWindow w = SelectLocalBaWindow(s.map, 5, WithWindow(3));
  // Optimised: 5 and its two best neighbours; fixed: every other observer of their points
  // (2 and 1 through 5's points, 0 through 3's), each group in id order.
  ASSERT_EQ(w.keyframes.size(), 6u);
  EXPECT_EQ(Ids(w, false), (std::vector<KeyframeId>{3, 4, 5}));
  EXPECT_EQ(Ids(w, true), (std::vector<KeyframeId>{0, 1, 2}));
  EXPECT_FALSE(w.keyframes[0].fixed);
  EXPECT_EQ(w.keyframes[3].id, 0u);
  // Points: all the window sees; not the group only 0 and 1 see.
  EXPECT_EQ(w.points, IdsOf(s.groups, {0, 1, 2, 3, 4}));
  EXPECT_TRUE(w.rest.empty());

  const BaProblem problem = MakeBaProblem(s.map, w);
  ASSERT_EQ(problem.keyframes.size(), 6u);
  EXPECT_EQ(problem.points.size(), w.points.size());
  EXPECT_EQ(problem.observations.size(), 2u * w.points.size());  // every point seen twice
  for (const BaObservation& o : problem.observations) {
    const KeyframeId kf = problem.keyframes[o.keyframe_index].id;
    const VertexId point = problem.points[o.point_index].id;
    EXPECT_EQ(o.uv, *s.map.keyframe(kf)->Find(point));
  }
  EXPECT_TRUE(problem.keyframes[5].camera_from_world.translation().isApprox(
      Eigen::Vector3d(-0.2, 0, 0)));  // keyframe 2 at x = 0.2
}

TEST(BaWindow, FixedKeyframesAreCappedToTheMostSharing) {
  // 10 shares 20 points with 9 and k + 1 points with each k < 8 (too few for neighbours).
  std::vector<PointGroup> groups = {{20, {9, 10}}};
  for (KeyframeId k = 0; k < 8; ++k) groups.push_back({static_cast<int>(k) + 1, {k, 10}});
  const MapData m = MakeCovisibilityMap({0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10}, groups);
  const BaWindow w = SelectLocalBaWindow(m, 10, WithWindow(2));
  EXPECT_EQ(Ids(w, false), (std::vector<KeyframeId>{9, 10}));
  // At most 2 x window = 4 fixed: the four sharing most points, in id order.
  EXPECT_EQ(Ids(w, true), (std::vector<KeyframeId>{4, 5, 6, 7}));
}

TEST(BaWindow, WithoutOutsideObserversTheOldestWindowKeyframeHoldsTheGauge) {
  const MapData m = MakeCovisibilityMap({2, 3, 4}, {{20, {2, 3, 4}}});
  const BaWindow w = SelectLocalBaWindow(m, 4, WithWindow(12));
  ASSERT_EQ(w.keyframes.size(), 3u);
  EXPECT_EQ(w.keyframes[0].id, 2u);
  EXPECT_TRUE(w.keyframes[0].fixed);
  EXPECT_EQ(Ids(w, false), (std::vector<KeyframeId>{3, 4}));
}

TEST(BaWindow, PointCapKeepsAnEvenSubsetAndLeavesTheRest) {
  std::vector<std::vector<VertexId>> groups;
  const MapData m = MakeCovisibilityMap({0, 1}, {{80, {0, 1}}}, &groups);
  const BaWindow w = SelectLocalBaWindow(m, 1, WithWindow(12, /*max_points=*/10));
  std::vector<VertexId> kept, rest;
  for (VertexId i = 0; i < 80; ++i) (i % 8 == 0 ? kept : rest).push_back(groups[0][i]);
  EXPECT_EQ(w.points, kept);  // every eighth id
  EXPECT_EQ(w.rest, rest);
  EXPECT_EQ(MakeBaProblem(m, w).points.size(), 10u);
}

TEST(BaWindow, GlobalWindowHasEverythingWithTheFirstKeyframeFixed) {
  const SixKeyframes s;
  const BaWindow w = SelectGlobalBaWindow(s.map, /*max_points=*/0);
  EXPECT_EQ(Ids(w, true), (std::vector<KeyframeId>{0}));
  EXPECT_EQ(Ids(w, false), (std::vector<KeyframeId>{1, 2, 3, 4, 5}));
  EXPECT_EQ(w.points, IdsOf(s.groups, {0, 1, 2, 3, 4, 5}));
  EXPECT_TRUE(w.rest.empty());
  const BaWindow capped = SelectGlobalBaWindow(s.map, /*max_points=*/53);  // 106 points: step 2
  EXPECT_EQ(capped.points.size(), 53u);
  EXPECT_EQ(capped.rest.size(), 53u);
  EXPECT_EQ(capped.points.front(), 0u);
  EXPECT_EQ(capped.rest.front(), 1u);
}

TEST(BaWindow, YoungMapsHaveAtMostTenKeyframes) {
  std::vector<KeyframeId> ids;
  for (KeyframeId k = 0; k < 10; ++k) ids.push_back(k);
  MapData m = MakeCovisibilityMap(ids, {{20, {0, 1}}});
  EXPECT_TRUE(IsYoungMap(m));
  Keyframe kf;
  kf.id = 10;
  m.AddKeyframe(std::move(kf));
  EXPECT_FALSE(IsYoungMap(m));
}

}  // namespace
}  // namespace m2s::slam
