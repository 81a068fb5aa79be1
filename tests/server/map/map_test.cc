#include "map/map.h"

#include <cstdio>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

namespace m2s::slam {
namespace {

// Three keyframes seeing overlapping ids; points 0..9 are seen by all, 10..14 by the first two.
void Populate(Map* map) {
  map->Write([](MapData& m) {
    for (KeyframeId k = 0; k < 3; ++k) {
      Keyframe kf;
      kf.id = k;
      kf.seq = 10 * k;
      kf.timestamp = 0.5 * k;
      kf.world_from_camera = Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * k, 0, 0));
      for (VertexId v = 0; v < 20; ++v) {
        kf.ids.push_back(v);
        kf.uvs.emplace_back(10.0 * v, 5.0 * k);
      }
      m.AddKeyframe(std::move(kf));
    }
    for (VertexId v = 0; v < 15; ++v) {
      m.AddPoint(v, Eigen::Vector3d(v, 1, 2), 0);
      m.AddObservation(v, 0);
      m.AddObservation(v, 1);
      if (v < 10) m.AddObservation(v, 2);
    }
  });
}

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

TEST(Map, SaveLoadRoundTrip) {
  Map map;
  Populate(&map);
  const Camera camera;
  const std::string path = ::testing::TempDir() + "/m2s_map_test.m2smap";
  ASSERT_TRUE(map.Save(path, camera).ok());
  Map loaded;
  const Status s = loaded.Load(path, camera);
  ASSERT_TRUE(s.ok()) << s.message();
  const MapDelta a = map.FullDelta(), b = loaded.FullDelta();
  EXPECT_EQ(a.point_ids, b.point_ids);
  EXPECT_EQ(a.point_positions, b.point_positions);
  ASSERT_EQ(a.keyframes.size(), b.keyframes.size());
  loaded.Read([](const MapData& m) {
    EXPECT_EQ(m.point(3)->observers, (std::vector<KeyframeId>{0, 1, 2}));
    EXPECT_EQ(m.keyframe(1)->uvs[7], Eigen::Vector2d(70.0, 5.0));
    EXPECT_EQ(m.keyframe(2)->seq, 20);
  });
  EXPECT_TRUE(loaded.TakeDelta().full);
  std::remove(path.c_str());
}

TEST(Map, LoadRejectsBadFilesWithClearErrors) {
  const Camera camera;
  Map map;
  Populate(&map);
  const std::string path = ::testing::TempDir() + "/m2s_map_bad.m2smap";
  ASSERT_TRUE(map.Save(path, camera).ok());
  Map target;
  Camera other = camera;
  other.fx += 1.0;
  Status s = target.Load(path, other);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("camera"), std::string::npos) << s.message();

  // Truncated file.
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
  }
  s = target.Load(path, camera);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("truncated"), std::string::npos) << s.message();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << "not a map at all";
  }
  s = target.Load(path, camera);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not a Mesh2SLAM map"), std::string::npos) << s.message();
  EXPECT_FALSE(target.Load(path + ".missing", camera).ok());
  target.Read([](const MapData& m) { EXPECT_TRUE(m.empty()); });  // untouched on failure
  std::remove(path.c_str());
}

}  // namespace
}  // namespace m2s::slam
