// RefineFramePose and KeepObservations (server/system/system_common.h): a tracked frame
// re-solved on the map its observations refer to, against the known pose it was seen from.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "map/map.h"
#include "system/system_common.h"

namespace m2s::slam {
namespace {

constexpr KeyframeId kReference = 3;

MeasurementModel Model() {
  MeasurementModel m;
  m.camera = Camera::FromHorizontalFov(640, 480, 90.0);
  m.pixel_sigma = 0.5;
  return m;
}

// 300 points on a 4 m x 3 m wall 3-5 m in front of the origin (a staircase in depth) and one
// keyframe at the origin.
void MakeMap(Map* map) {
  map->Write([](MapData& m) {
    Keyframe kf;
    kf.id = kReference;
    std::vector<Eigen::Vector3d> points;
    for (VertexId v = 0; v < 300; ++v) {
      points.emplace_back(-2.0 + 4.0 * (v % 20) / 19.0, -1.5 + 3.0 * (v / 20) / 14.0,
                          3.0 + 0.5 * (v % 5));
      kf.ids.push_back(v);
      kf.uvs.push_back(Model().camera.Project(points.back()));
    }
    m.AddKeyframe(std::move(kf));
    for (VertexId v = 0; v < 300; ++v) {
      m.AddPoint(v, points[v], kReference);
      m.AddObservation(v, kReference);
    }
  });
}

// The record of a frame seen from `truth` (world_from_camera), its observations exact, its pose
// relative to the keyframe at the origin `tracked` (as tracking left it).
TrajectoryRecord SeenFrom(const Map& map, const MeasurementModel& model, const Pose3& truth,
                          const Pose3& tracked) {
  TrajectoryRecord r;
  r.state = TrackingState::kOk;
  r.reference = kReference;
  r.reference_from_camera = tracked;
  map.Read([&](const MapData& m) {
    for (const auto& [id, point] : m.points()) {
      const Eigen::Vector3d pc = truth.Inverse() * point.position;
      r.observed_ids.push_back(id);
      r.observed_uvs.push_back(model.camera.Project(pc).cast<float>());
    }
  });
  return r;
}

TEST(RefineFramePose, RecoversThePoseTheFrameWasSeenFrom) {
  Map map;
  MakeMap(&map);
  const MeasurementModel model = Model();
  const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d(0.3, -0.1, 0.2));
  // Tracked 4 cm and 0.6 degrees off (as against a map that was off there).
  const Pose3 tracked =
      truth * Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitX())),
                    Eigen::Vector3d(0.03, 0.0, -0.027));
  TrajectoryRecord r = SeenFrom(map, model, truth, tracked);
  map.Read([&](const MapData& m) { EXPECT_TRUE(RefineFramePose(model, m, &r)); });
  // The keyframe is at the origin: the relative pose is the world pose. The pixels are floats
  // (1e-4 px at 640 px): micrometres at 3-5 m.
  const Pose3 error = truth.Inverse() * r.reference_from_camera;
  EXPECT_LT(error.translation().norm(), 1e-5);
  EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle(), 1e-5);
}

TEST(RefineFramePose, LeavesKeyframesLostFramesAndFramesWithoutMappedObservations) {
  Map map;
  MakeMap(&map);
  const MeasurementModel model = Model();
  const Pose3 truth(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1, 0.0, 0.0));
  const Pose3 tracked(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.15, 0.0, 0.0));
  auto unchanged = [&](TrajectoryRecord r) {
    bool refined = true;
    map.Read([&](const MapData& m) { refined = RefineFramePose(model, m, &r); });
    EXPECT_FALSE(refined);
    EXPECT_EQ(r.reference_from_camera.translation(), tracked.translation());
  };
  TrajectoryRecord keyframe = SeenFrom(map, model, truth, tracked);
  keyframe.is_keyframe = true;  // refined by the bundle adjustment itself
  unchanged(keyframe);
  TrajectoryRecord lost = SeenFrom(map, model, truth, tracked);
  lost.state = TrackingState::kLost;
  unchanged(lost);
  TrajectoryRecord unmapped = SeenFrom(map, model, truth, tracked);
  for (VertexId& id : unmapped.observed_ids) id += 1000;  // points the map no longer has
  unchanged(unmapped);
  TrajectoryRecord none = SeenFrom(map, model, truth, tracked);
  none.observed_ids.clear();
  none.observed_uvs.clear();
  unchanged(none);
}

TEST(KeepObservations, KeepsAnEvenSubsetOrNone) {
  TrackerOutput out;
  for (VertexId v = 0; v < 600; ++v) {
    out.observed_ids.push_back(v);
    out.observed_uvs.emplace_back(v, 2.0 * v);
  }
  TrajectoryRecord kept;
  KeepObservations(out, 100, &kept);
  ASSERT_EQ(kept.observed_ids.size(), 100u);
  ASSERT_EQ(kept.observed_uvs.size(), 100u);
  for (size_t i = 0; i < 100; ++i) {
    EXPECT_EQ(kept.observed_ids[i], 6 * i);
    EXPECT_EQ(kept.observed_uvs[i], Eigen::Vector2f(6.0f * i, 12.0f * i));
  }
  TrajectoryRecord all;
  KeepObservations(out, 1000, &all);
  EXPECT_EQ(all.observed_ids.size(), 600u);
  TrajectoryRecord none;
  KeepObservations(out, 0, &none);
  EXPECT_TRUE(none.observed_ids.empty());
  EXPECT_TRUE(none.observed_uvs.empty());
}

}  // namespace
}  // namespace m2s::slam
