#include "map/map.h"

#include <gtest/gtest.h>

#include "map_test_util.h"

namespace m2s::slam {
namespace {

TEST(Map, CovisibilityAndObservationCounts) {
  Map map;
  Populate(&map);
  map.Read([](const MapData& m) {
    EXPECT_EQ(m.keyframe(0)->num_points, 15);
    EXPECT_EQ(m.keyframe(2)->num_points, 10);
    const auto cov = m.Covisible(0, 1);
    ASSERT_EQ(cov.size(), 2u);
    EXPECT_EQ(cov[0], (std::pair<KeyframeId, int>{1, 15}));
    EXPECT_EQ(cov[1], (std::pair<KeyframeId, int>{2, 10}));
    EXPECT_EQ(m.KeyframesWithFeature(19)->size(), 3u);
    EXPECT_EQ(m.point(3)->last_observer(), 2u);
  });
}

TEST(Map, DeltasAreCoalescedAndFullAfterClear) {
  Map map;
  Populate(&map);
  MapDelta d = map.TakeDelta();
  EXPECT_FALSE(d.full);
  EXPECT_EQ(d.base_revision, 0u);
  EXPECT_EQ(d.keyframes.size(), 3u);
  EXPECT_EQ(d.point_ids.size(), 15u);
  EXPECT_TRUE(map.TakeDelta().empty());

  map.Write([](MapData& m) {
    m.SetPointPosition(3, Eigen::Vector3d(0, 0, 1));
    m.RemovePoint(4);
    m.AddPoint(4, Eigen::Vector3d(1, 1, 1), 1);  // re-added: an upsert, not a removal
    m.RemovePoint(5);
    m.RemoveKeyframe(2, KeyframeLink{1, Pose3()});
  });
  d = map.TakeDelta();
  EXPECT_EQ(d.base_revision + 1, d.revision);
  EXPECT_EQ(d.point_ids, (std::vector<VertexId>{0, 1, 2, 3, 4, 6, 7, 8, 9}));  // lost kf 2 obs
  EXPECT_EQ(d.removed_points, std::vector<VertexId>{5});
  EXPECT_EQ(d.removed_keyframes, std::vector<KeyframeId>{2});
  EXPECT_FLOAT_EQ(d.point_positions[3].z(), 1.0f);
  map.Read([](const MapData& m) {
    // The removed keyframe resolves through its link.
    const auto pose = m.ResolveKeyframePose(2);
    ASSERT_TRUE(pose.has_value());
    EXPECT_NEAR(pose->translation().x(), 0.1, 1e-12);
    EXPECT_EQ(m.keyframe(1)->num_points, 13);  // 15 - point 5 - point 4 (re-added unobserved)
  });

  const MapDelta full = map.FullDelta();
  EXPECT_TRUE(full.full);
  EXPECT_EQ(full.keyframes.size(), 2u);
  EXPECT_EQ(full.point_ids.size(), 14u);
  EXPECT_TRUE(map.TakeDelta().empty());  // FullDelta does not disturb TakeDelta

  map.Clear();
  d = map.TakeDelta();
  EXPECT_TRUE(d.full);
  EXPECT_TRUE(d.keyframes.empty());
  EXPECT_EQ(map.NextKeyframeId(), 0u);  // never touched by Populate (ids were given)
  EXPECT_EQ(map.NextKeyframeId(), 1u);
}

}  // namespace
}  // namespace m2s::slam
