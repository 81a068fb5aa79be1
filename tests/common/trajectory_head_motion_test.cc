// GenerateHeadMotion / DefaultTrajectory: inside the room and away from furniture, smooth,
// moving from the first second, OpenCV camera axes with the world z up, deterministic.
#include <cmath>

#include <gtest/gtest.h>

#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"

namespace m2s {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

TEST(HeadMotion, DefaultTrajectoryIsAMinuteAt30HzInsideTheRoom) {
  const Trajectory t = DefaultTrajectory();
  const HeadMotionOptions options = DefaultHeadMotionOptions();
  ASSERT_EQ(t.size(), 1801u);
  EXPECT_EQ(t.start_time(), 0.0);
  EXPECT_NEAR(t.end_time(), 60.0, 1e-9);
  const RoomLayout layout = DefaultRoomLayout();
  for (const TimedPose& p : t) {
    const Eigen::Vector3d eye = p.world_from_camera.translation();
    const Eigen::Vector2d ground = eye.head<2>();
    ASSERT_GT(layout.room.exteriorDistance(eye), -1.0);  // finite
    EXPECT_GT((ground - layout.room.min().head<2>()).minCoeff(), 0.5) << p.timestamp;
    EXPECT_GT((layout.room.max().head<2>() - ground).minCoeff(), 0.5) << p.timestamp;
    for (const auto& obstacle : layout.obstacles) {
      EXPECT_GT(obstacle.exteriorDistance(ground), options.obstacle_clearance_m - 1e-9)
          << p.timestamp;
    }
    EXPECT_NEAR(eye.z(), 1.6, 0.05);
  }
}

TEST(HeadMotion, IsSmoothAndMovesFromTheFirstSecond) {
  const Trajectory t = DefaultTrajectory();
  const double dt = 1.0 / 30.0;
  double max_speed = 0.0, max_acceleration = 0.0, max_rate_deg = 0.0, max_rate_change_deg = 0.0;
  double previous_rate = 0.0;
  for (size_t i = 1; i + 1 < t.size(); ++i) {
    const Eigen::Vector3d a = t[i - 1].world_from_camera.translation();
    const Eigen::Vector3d b = t[i].world_from_camera.translation();
    const Eigen::Vector3d c = t[i + 1].world_from_camera.translation();
    max_speed = std::max(max_speed, (c - b).norm() / dt);
    max_acceleration = std::max(max_acceleration, (c - 2 * b + a).norm() / (dt * dt));
    const double rate = RotationAngle(t[i].world_from_camera.rotation().conjugate() *
                                      t[i + 1].world_from_camera.rotation()) /
                        dt * kRadToDeg;
    max_rate_deg = std::max(max_rate_deg, rate);
    if (i > 1) max_rate_change_deg = std::max(max_rate_change_deg, std::abs(rate - previous_rate));
    previous_rate = rate;
  }
  EXPECT_LT(max_speed, 1.0);         // walking_speed_mps = 0.9 peak, plus the bob
  EXPECT_LT(max_acceleration, 3.0);  // m/s^2: no jumps
  EXPECT_LT(max_rate_deg, 200.0);    // a brisk head turn, not a teleport
  EXPECT_LT(max_rate_change_deg, 15.0);
  EXPECT_GT(max_speed, 0.5);
  // Parallax for monocular initialisation: several centimetres within the first second.
  EXPECT_GT((t[30].world_from_camera.translation() - t[0].world_from_camera.translation()).norm(),
            0.05);
}

TEST(HeadMotion, CameraAxesAreOpenCvWithTheWorldZUp) {
  for (const TimedPose& p : DefaultTrajectory()) {
    const Eigen::Matrix3d r = p.world_from_camera.RotationMatrix();
    // Camera y (down) points down in the world, camera z (forward) stays near the horizon.
    EXPECT_LT(r.col(1).z(), -0.7) << p.timestamp;
    EXPECT_LT(std::abs(r.col(2).z()), 0.7) << p.timestamp;
    EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
  }
}

TEST(HeadMotion, DeterministicPerSeed) {
  HeadMotionOptions options = DefaultHeadMotionOptions();
  options.duration_s = 10.0;
  const Expected<Trajectory> a = GenerateHeadMotion(options);
  const Expected<Trajectory> b = GenerateHeadMotion(options);
  options.seed += 1;
  const Expected<Trajectory> c = GenerateHeadMotion(options);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  ASSERT_EQ(a->size(), 301u);
  double difference = 0.0;
  for (size_t i = 0; i < a->size(); ++i) {
    EXPECT_EQ((*a)[i].world_from_camera.translation(), (*b)[i].world_from_camera.translation());
    difference +=
        ((*a)[i].world_from_camera.translation() - (*c)[i].world_from_camera.translation()).norm();
  }
  EXPECT_GT(difference, 1.0);
}

TEST(HeadMotion, RejectsBadOptionsAndImpossibleRooms) {
  HeadMotionOptions options;
  Status why;
  EXPECT_TRUE((why = options.Check())) << why.message();
  options.rate_hz = 0.0;
  EXPECT_FALSE(GenerateHeadMotion(options).ok());
  options = {};
  options.room = Eigen::AlignedBox2d(Eigen::Vector2d(0, 0), Eigen::Vector2d(1.0, 1.0));
  EXPECT_NE(GenerateHeadMotion(options).error().find("wall clearance"), std::string::npos);
  options = {};
  options.obstacles = {options.room};  // furniture everywhere
  EXPECT_NE(GenerateHeadMotion(options).error().find("no free floor"), std::string::npos);
  options = {};
  options.pause_probability = 1.5;
  EXPECT_FALSE((why = options.Check()));
}

}  // namespace
}  // namespace m2s
