// A part of the scene moves rigidly in the middle of a run (SceneEditor::MovePart, followed
// by the CPU projector): tracking stays accurate and no map point stays where a moved vertex
// used to be.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/scene_editor.h"
#include "slam_sim.h"

namespace m2s::slam {
namespace {

using testing::ComputeAte;
using testing::DefaultOptions;

constexpr VertexId kRoomPoints = 2500;
constexpr int kFrames = 180;
constexpr int kBoxPoints = 150;

// Points on the surface of a 0.8 m box standing in the middle of the room: the part that moves.
std::vector<Eigen::Vector3f> BoxPoints(int per_box, uint64_t seed) {
  uint64_t state = seed * 0x9E3779B97F4A7C15ull + 7;
  auto uniform = [&state](double lo, double hi) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return lo + (hi - lo) * static_cast<double>(state >> 11) / static_cast<double>(1ull << 53);
  };
  std::vector<Eigen::Vector3f> points;
  const Eigen::Vector3d centres[] = {{0.0, 0.0, 0.4}};
  for (const Eigen::Vector3d& centre : centres) {
    for (int i = 0; i < per_box; ++i) {
      Eigen::Vector3d p(uniform(-0.4, 0.4), uniform(-0.4, 0.4), uniform(-0.4, 0.4));
      const int axis = i % 3;
      p[axis] = (i / 3) % 2 ? 0.4 : -0.4;
      if (axis == 2 && p[axis] < 0) p[axis] = 0.4;  // no points under the box
      points.push_back((centre + p).cast<float>());
    }
  }
  return points;
}

TEST(MovingPart, TrackingHoldsAndTheMapForgetsTheOldPlace) {
  SceneEditor editor(testing::MakePointRoom(kRoomPoints));
  const std::vector<Eigen::Vector3f> boxes = BoxPoints(kBoxPoints, 5);
  ASSERT_TRUE(editor.AddPart("boxes", boxes, {}).ok());
  ProjectorOptions popts;
  popts.num_threads = 1;
  auto projector = CpuProjector::Create(editor.scene(), popts);
  ASSERT_TRUE(projector.ok()) << projector.error();

  // Half a turn around the boxes' middle at 2 m, eyes at 1.2 m, looking at the middle with a
  // slow sway: the part is in view throughout, and so are the walls behind it.
  std::vector<TimedPose> poses;
  for (int k = 0; k < kFrames; ++k) {
    const double t = k / 30.0, angle = 0.5 + 0.35 * t;
    const Eigen::Vector3d eye(2.0 * std::cos(angle), 2.0 * std::sin(angle), 1.2);
    const Eigen::Vector3d target(0.3 * std::sin(1.3 * t), 0.0, 0.5);
    const Eigen::Vector3d forward = (target - eye).normalized();
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    Eigen::Matrix3d rotation;
    rotation << right, forward.cross(right), forward;
    poses.push_back({t, Pose3(rotation, eye)});
  }
  auto trajectory = Trajectory::FromPoses(std::move(poses));
  ASSERT_TRUE(trajectory.ok()) << trajectory.error();
  const Camera camera;
  const size_t move_at = trajectory->size() * 3 / 5;
  const Pose3 shift(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ())),
                    Eigen::Vector3d(0.3, 0.0, 0.0));
  std::vector<Eigen::Vector3f> old_positions;

  auto system = System::Create(DefaultOptions(camera));
  ASSERT_TRUE(system.ok()) << system.error();
  std::vector<ProjectedVertex> projected;
  double moved_fraction_sum = 0.0;
  int moved_fraction_frames = 0, lost = 0;
  for (size_t i = 0; i < trajectory->size(); ++i) {
    if (i == move_at) {
      auto change = editor.MovePart("boxes", shift);
      ASSERT_TRUE(change.ok()) << change.error();
      EXPECT_EQ(change->moved_ids.size(), boxes.size());  // every id kept
      old_positions = boxes;
      ASSERT_TRUE((*projector)->ApplyChange(editor.scene(), *change).ok());
    }
    const Pose3& pose = (*trajectory)[i].world_from_camera;
    ASSERT_TRUE((*projector)->Project(pose, camera, &projected).ok());
    Frame frame;
    frame.seq = static_cast<int64_t>(i);
    frame.timestamp = (*trajectory)[i].timestamp;
    frame.ground_truth_world_from_camera = pose;
    int on_boxes = 0;
    for (const ProjectedVertex& v : projected) {
      frame.features.push_back({v.id, Eigen::Vector2f(v.u, v.v)});
      on_boxes += v.id >= kRoomPoints ? 1 : 0;
    }
    if (i >= move_at && !projected.empty()) {
      moved_fraction_sum += static_cast<double>(on_boxes) / static_cast<double>(projected.size());
      ++moved_fraction_frames;
    }
    lost += (*system)->Track(frame).state == TrackingState::kLost ? 1 : 0;
  }
  const auto ate = ComputeAte((*system)->Trajectory());
  const MapDelta map = (*system)->FullMap();
  // Map error against the current positions (Sim3-aligned to the truth), and the map points
  // of moved vertices still near their old place.
  double sse = 0.0, worst_moved = 0.0;
  int near_old = 0, moved_points = 0;
  for (size_t k = 0; k < map.point_ids.size(); ++k) {
    const VertexId id = map.point_ids[k];
    const Eigen::Vector3d p = ate.truth_from_estimate * map.point_positions[k].cast<double>();
    const double error = (p - editor.scene().positions[id].cast<double>()).norm();
    sse += error * error;
    if (id >= kRoomPoints) {
      ++moved_points;
      worst_moved = std::max(worst_moved, error);
      if ((p - old_positions[id - kRoomPoints].cast<double>()).norm() < 0.1) ++near_old;
    }
  }
  const double map_rmse = std::sqrt(sse / std::max<size_t>(1, map.point_ids.size()));
  std::printf(
      "moved part: %.0f %% of the visible vertices after the move; lost %d, ATE %.3g m, %zu "
      "points (%d of the moved part, %d near their old place, worst %.3g m), map error %.3g m\n",
      100.0 * moved_fraction_sum / std::max(1, moved_fraction_frames), lost, ate.rmse,
      map.point_ids.size(), moved_points, near_old, worst_moved, map_rmse);
  // Noise-free: measured ATE 1e-7 m and map error 3e-7 m; without the moved points forgotten
  // every map point of the box stays at its old place (map error 0.14 m).
  EXPECT_EQ(lost, 0);
  EXPECT_LT(ate.rmse, 1e-4);
  EXPECT_GT(moved_points, 0);
  EXPECT_EQ(near_old, 0);
  EXPECT_LT(map_rmse, 1e-4);
}

}  // namespace
}  // namespace m2s::slam
