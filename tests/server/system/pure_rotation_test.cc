// Tracking through pure camera rotation: a camera that stands still and turns towards a part of
// the scene the map never saw (a head looking around) must keep its pose. New features have
// no parallax there, so the map cannot grow until the camera moves again; the rotation is
// fitted to the bearings the frame shares with the reference keyframe.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/numeric.h"
#include "slam_sim.h"
#include "tracking/rotation_only.h"

namespace m2s::slam {
namespace {

using testing::ComputeAte;
using testing::DefaultOptions;
using testing::MakePointRoom;
using testing::ProjectFrames;
using testing::SimOptions;

constexpr double kFps = 30.0;
constexpr double kWalkS = 1.0;  // sideways walk (initialisation), then the turn
constexpr double kTurnS = 2.0;  // 180 degrees about the vertical

Eigen::Vector3d Forward(double yaw) { return {std::sin(yaw), std::cos(yaw), 0.0}; }

// Walks 0.4 m along x looking at the +y wall, stops and turns to face the -y wall.
Trajectory MakeWalkAndTurn() {
  std::vector<TimedPose> poses;
  for (int i = 0; i < static_cast<int>((kWalkS + kTurnS) * kFps); ++i) {
    const double t = i / kFps;
    const double x = -0.2 + 0.4 * std::min(t, kWalkS) / kWalkS;
    const double yaw = t < kWalkS ? 0.0 : M_PI * (t - kWalkS) / kTurnS;
    const Eigen::Vector3d eye(x, 0.0, 1.5);
    poses.push_back({t, LookAt(eye, eye + Forward(yaw), Eigen::Vector3d::UnitZ())});
  }
  auto trajectory = Trajectory::FromPoses(std::move(poses));
  EXPECT_TRUE(trajectory.ok()) << trajectory.error();
  return *trajectory;
}

double AngleDeg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return Eigen::AngleAxisd(a.conjugate() * b).angle() * 180.0 / M_PI;
}

TEST(PureRotation, TurningTowardsAnUnmappedWallKeepsTracking) {
  const Scene scene = MakePointRoom(3000);
  const Camera camera;
  SimOptions sim;
  sim.budget = 0;
  sim.occlusion = false;
  const Trajectory truth = MakeWalkAndTurn();
  const std::vector<Frame> frames = ProjectFrames(scene, truth, camera, sim);
  auto system = System::Create(DefaultOptions(camera));
  ASSERT_TRUE(system.ok()) << system.error();
  bool initialised = false;
  int lost = 0;
  for (const Frame& frame : frames) {
    ASSERT_GE(frame.features.size(), 100u);  // the view is never empty
    const TrackResult r = (*system)->Track(frame);
    const bool tracked = r.state == TrackingState::kOk || r.state == TrackingState::kRelocalized;
    initialised = initialised || tracked;
    if (initialised && !tracked) ++lost;
  }
  ASSERT_TRUE(initialised);
  EXPECT_EQ(lost, 0);
  // The turn's poses: the centre stays put and the heading follows the truth.
  const std::vector<TrajectoryEntry> trajectory = (*system)->Trajectory();
  const testing::AteResult ate = ComputeAte(trajectory);
  EXPECT_LT(ate.rmse, 1e-3);
  // Rotations relative to the first tracked frame (the centres lie on a line, which leaves the
  // aligned world's roll about it free).
  int turned = 0;
  std::optional<TrajectoryEntry> first;
  for (const TrajectoryEntry& e : trajectory) {
    if (e.state != TrackingState::kOk && e.state != TrackingState::kRelocalized) continue;
    if (!first) first = e;
    const Eigen::Quaterniond estimated =
        first->world_from_camera.rotation().conjugate() * e.world_from_camera.rotation();
    const Eigen::Quaterniond expected =
        first->ground_truth_world_from_camera->rotation().conjugate() *
        e.ground_truth_world_from_camera->rotation();
    EXPECT_LT(AngleDeg(estimated, expected), 0.05) << "frame " << e.seq;
    turned += e.timestamp > kWalkS + 0.75 * kTurnS ? 1 : 0;
  }
  EXPECT_GT(turned, 10);  // the far end of the turn, where no mapped point is in view
}

// A quick turn made while the camera keeps walking (a drone yawing in flight): the bearings to
// the reference keyframe fit a rotation about a fixed centre for a while, but the camera is not
// there. Every frame that gets a pose must be near the truth; frames the map cannot place are
// lost.
TEST(PureRotation, TurningWhileWalkingIsNeverFrozenInPlace) {
  const Scene scene = MakePointRoom(3000);
  const Camera camera;
  SimOptions sim;
  sim.budget = 0;
  sim.occlusion = false;
  constexpr double kSpeed = 0.3;       // m/s, along x (with a slight sway: a non-degenerate path)
  constexpr double kQuickTurnS = 0.5;  // 180 degrees
  std::vector<TimedPose> poses;
  for (int i = 0; i < static_cast<int>((kWalkS + kQuickTurnS + 1.0) * kFps); ++i) {
    const double t = i / kFps;
    const double x = -0.3 + kSpeed * t;
    const double yaw = M_PI * std::clamp((t - kWalkS) / kQuickTurnS, 0.0, 1.0);
    const Eigen::Vector3d eye(x, 0.1 * std::sin(t), 1.5 + 0.05 * std::sin(3.0 * t));
    poses.push_back({t, LookAt(eye, eye + Forward(yaw), Eigen::Vector3d::UnitZ())});
  }
  auto truth = Trajectory::FromPoses(std::move(poses));
  ASSERT_TRUE(truth.ok()) << truth.error();
  const std::vector<Frame> frames = ProjectFrames(scene, *truth, camera, sim);
  auto system = System::Create(DefaultOptions(camera));
  ASSERT_TRUE(system.ok()) << system.error();
  for (const Frame& frame : frames) (*system)->Track(frame);
  // The first map's frames, in the truth's frame by the similarity of its frames before the
  // turn (exact features: those poses are exact).
  const testing::ErrorsAfter first_map = testing::ErrorsAlignedBefore(
      (*system)->Trajectory(), /*map_id=*/0, static_cast<int64_t>(kWalkS * kFps));
  ASSERT_GE(first_map.aligned_on, 10u);
  // A rotation-only pose is off by the distance walked since the last measured one: at most
  // 2 % of the keyframe's median depth (2.5 m), 5 cm, by the tracker's rule. Measured: 4.4 cm;
  // frozen in place without the rule, 13 cm.
  std::printf("worst centre error of the first map: %.4f m over %zu frames\n", first_map.worst(),
              first_map.entries.size());
  EXPECT_LT(first_map.worst(), 0.06);
}

// Bearings of random points seen from two cameras: `moved` shifts the second one's centre.
struct TwoViews {
  Pose3 first_world_from_camera;
  Pose3 second_world_from_camera;
  std::vector<VertexId> first_ids;
  std::vector<Eigen::Vector2d> first_uvs;
  SortedFeatures second;
};

TwoViews MakeTwoViews(const Camera& camera, const Eigen::Vector3d& moved) {
  TwoViews v;
  const Eigen::Vector3d eye(0.0, 0.0, 1.5);
  v.first_world_from_camera = LookAt(eye, eye + Forward(0.0), Eigen::Vector3d::UnitZ());
  v.second_world_from_camera =
      LookAt(eye + moved, eye + moved + Forward(0.3), Eigen::Vector3d::UnitZ());
  const Pose3 first_cfw = v.first_world_from_camera.Inverse();
  const Pose3 second_cfw = v.second_world_from_camera.Inverse();
  uint64_t state = 7;
  auto uniform = [&state](double lo, double hi) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return lo + (hi - lo) * static_cast<double>(state >> 11) / static_cast<double>(1ull << 53);
  };
  for (VertexId id = 0; id < 400; ++id) {
    const Eigen::Vector3d p(uniform(-1.5, 2.5), uniform(0.8, 2.0), uniform(0.5, 2.5));
    const Eigen::Vector3d a = first_cfw * p, b = second_cfw * p;
    if (a.z() <= 0.1 || b.z() <= 0.1) continue;
    const Eigen::Vector2d ua = camera.Project(a), ub = camera.Project(b);
    if (!camera.InImage(ua.x(), ua.y()) || !camera.InImage(ub.x(), ub.y())) continue;
    v.first_ids.push_back(id);
    v.first_uvs.push_back(ua);
    v.second.ids.push_back(id);
    v.second.uvs.push_back(ub);
  }
  return v;
}

TEST(PureRotation, SolveRotationOnlyRecoversATurnAndRefusesAMove) {
  const Camera camera;
  const TwoViews turned = MakeTwoViews(camera, Eigen::Vector3d::Zero());
  ASSERT_GE(turned.second.size(), 50u);
  // One wrong pixel among them: RANSAC leaves it out.
  SortedFeatures features = turned.second;
  features.uvs[3] += Eigen::Vector2d(40.0, -25.0);
  const auto r = SolveRotationOnly(camera, 2.0, turned.first_world_from_camera, turned.first_ids,
                                   turned.first_uvs, features);
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->shared, static_cast<int>(features.size()));
  EXPECT_EQ(r->inliers, r->shared - 1);
  const Pose3 expected = turned.second_world_from_camera.Inverse();
  EXPECT_LT(AngleDeg(r->camera_from_world.rotation(), expected.rotation()), 1e-6);
  EXPECT_LT((r->camera_from_world.translation() - expected.translation()).norm(), 1e-9);
  // 20 cm sideways, points 1-2 m away: the bearings do not fit one rotation.
  const TwoViews moved = MakeTwoViews(camera, Eigen::Vector3d(0.2, 0.0, 0.0));
  const auto m = SolveRotationOnly(camera, 2.0, moved.first_world_from_camera, moved.first_ids,
                                   moved.first_uvs, moved.second);
  ASSERT_TRUE(m.has_value());
  EXPECT_LT(m->inliers, m->shared / 2);
}

TEST(PureRotation, PoseAtCentreRecoversTheRotationOfAKnownCentre) {
  // A camera at a known centre, turned 30 degrees about a tilted axis, sees points 1-3 m away;
  // given that centre, the rotation is the one that maps their directions onto its bearings.
  const Camera camera;
  const Eigen::Vector3d centre(0.4, -0.2, 1.5);
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(M_PI / 6.0, Eigen::Vector3d(0.2, 1.0, -0.3).normalized())
          .toRotationMatrix();
  const Pose3 camera_from_world(rotation, -(rotation * centre));
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  for (int i = 0; i < 40; ++i) {
    const Eigen::Vector3d in_camera(0.6 * std::sin(1.7 * i), 0.4 * std::cos(2.3 * i),
                                    1.0 + 0.05 * i);
    points.push_back(camera_from_world.Inverse() * in_camera);
    uvs.push_back(camera.Project(in_camera));
  }
  const std::optional<Pose3> pose = PoseAtCentre(camera, centre, points, uvs);
  ASSERT_TRUE(pose.has_value());
  EXPECT_LT(AngleDeg(pose->rotation(), camera_from_world.rotation()), 1e-9);
  EXPECT_LT((pose->Inverse().translation() - centre).norm(), 1e-12);
  // Every point on one ray from the centre: no rotation about it is determined.
  const std::vector<Eigen::Vector3d> on_ray = {centre + Eigen::Vector3d(0, 1, 0),
                                               centre + Eigen::Vector3d(0, 2, 0)};
  EXPECT_FALSE(PoseAtCentre(camera, centre, on_ray, {uvs[0], uvs[1]}).has_value());
}

}  // namespace
}  // namespace m2s::slam
