// Hand-held and drone motion (motion.h): deterministic for a seed, inside the room with the
// clearances, out of obstacles, with the documented speed and turn-rate character.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/motion.h"

namespace m2s {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A furnished 6 m x 5 m room: a table in the middle, a cabinet and a partition.
std::vector<Eigen::AlignedBox2d> Furniture() {
  return {Eigen::AlignedBox2d(Eigen::Vector2d(-0.7, -0.4), Eigen::Vector2d(0.7, 0.4)),
          Eigen::AlignedBox2d(Eigen::Vector2d(2.4, 1.5), Eigen::Vector2d(3.0, 2.5)),
          Eigen::AlignedBox2d(Eigen::Vector2d(-1.6, -2.5), Eigen::Vector2d(-1.5, -0.8))};
}

double ObstacleDistance(const std::vector<Eigen::AlignedBox2d>& obstacles,
                        const Eigen::Vector2d& p) {
  double d = 1e9;
  for (const Eigen::AlignedBox2d& box : obstacles) d = std::min(d, box.exteriorDistance(p));
  return d;
}

double AngleBetween(const Pose3& a, const Pose3& b) {
  return a.rotation().angularDistance(b.rotation());
}

void ExpectSame(const Trajectory& a, const Trajectory& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].timestamp, b[i].timestamp);
    EXPECT_EQ(a[i].world_from_camera.translation(), b[i].world_from_camera.translation());
    EXPECT_EQ(a[i].world_from_camera.rotation().coeffs(),
              b[i].world_from_camera.rotation().coeffs());
  }
}

HandheldMotionOptions Handheld(uint64_t seed) {
  HandheldMotionOptions o;
  o.seed = seed;
  o.duration_s = 40.0;
  o.obstacles = Furniture();
  o.targets = {Eigen::Vector3d(0.0, 0.0, 0.8), Eigen::Vector3d(2.7, 2.0, 1.0)};
  return o;
}

DroneMotionOptions Drone(uint64_t seed) {
  DroneMotionOptions o;
  o.seed = seed;
  o.duration_s = 20.0;
  o.obstacles = Furniture();
  return o;
}

TEST(HandheldMotionTest, DeterministicInsideTheRoomAndLookingAtTargets) {
  for (uint64_t seed : {1, 2, 3}) {
    const HandheldMotionOptions o = Handheld(seed);
    Expected<Trajectory> a = GenerateHandheldMotion(o);
    ASSERT_TRUE(a.ok()) << a.error();
    Expected<Trajectory> b = GenerateHandheldMotion(o);
    ASSERT_TRUE(b.ok());
    ExpectSame(*a, *b);
    EXPECT_EQ(a->size(), 40u * 30u + 1u);
    double max_rate = 0.0, path = 0.0, min_target_distance = 1e9;
    for (size_t i = 0; i < a->size(); ++i) {
      const Pose3& pose = (*a)[i].world_from_camera;
      const Eigen::Vector3d c = pose.translation();
      EXPECT_GT(c.x(), -3.0 + o.wall_clearance_m - 0.02);
      EXPECT_LT(c.x(), 3.0 - o.wall_clearance_m + 0.02);
      EXPECT_GT(c.y(), -2.5 + o.wall_clearance_m - 0.02);
      EXPECT_LT(c.y(), 2.5 - o.wall_clearance_m + 0.02);
      EXPECT_GT(c.z(), o.min_height_m - 0.02);
      EXPECT_LT(c.z(), o.max_height_m + 0.02);
      EXPECT_GT(ObstacleDistance(o.obstacles, c.head<2>()), o.obstacle_clearance_m - 0.02);
      for (const Eigen::Vector3d& t : o.targets) {
        min_target_distance = std::min(min_target_distance, (t - c).head<2>().norm());
      }
      if (i > 0) {
        const Pose3& prev = (*a)[i - 1].world_from_camera;
        path += (c - prev.translation()).norm();
        max_rate = std::max(max_rate, AngleBetween(prev, pose) * 30.0);
      }
    }
    // Closer to objects than a walking head, slow, and shaking but without whip pans.
    EXPECT_LT(min_target_distance, 1.0);
    EXPECT_GT(path / 40.0, 0.15);
    EXPECT_LT(path / 40.0, 0.5);
    EXPECT_LT(max_rate, 200.0 * kPi / 180.0);
  }
}

TEST(HandheldMotionTest, TheCameraLooksAtATarget) {
  const HandheldMotionOptions o = Handheld(4);
  Expected<Trajectory> motion = GenerateHandheldMotion(o);
  ASSERT_TRUE(motion.ok()) << motion.error();
  // Outside gaze turns the optical axis points at one of the targets, within the shake.
  int near_target = 0;
  for (const TimedPose& p : *motion) {
    const Eigen::Vector3d axis = p.world_from_camera.rotation() * Eigen::Vector3d::UnitZ();
    double best = kPi;
    for (const Eigen::Vector3d& t : o.targets) {
      const Eigen::Vector3d ray = (t - p.world_from_camera.translation()).normalized();
      best = std::min(best, std::acos(std::clamp(axis.dot(ray), -1.0, 1.0)));
    }
    near_target += best < 12.0 * kPi / 180.0 ? 1 : 0;
  }
  EXPECT_GT(near_target, static_cast<int>(0.7 * motion->size()));
}

TEST(DroneMotionTest, DeterministicInsideTheRoomSmoothAndFast) {
  for (uint64_t seed : {1, 2, 3}) {
    const DroneMotionOptions o = Drone(seed);
    Expected<Trajectory> a = GenerateDroneMotion(o);
    ASSERT_TRUE(a.ok()) << a.error();
    Expected<Trajectory> b = GenerateDroneMotion(o);
    ASSERT_TRUE(b.ok());
    ExpectSame(*a, *b);
    double max_speed = 0.0, path = 0.0, max_rate = 0.0;
    for (size_t i = 0; i < a->size(); ++i) {
      const Pose3& pose = (*a)[i].world_from_camera;
      const Eigen::Vector3d c = pose.translation();
      EXPECT_GT(c.x(), -3.0 + o.wall_clearance_m - 0.02);
      EXPECT_LT(c.x(), 3.0 - o.wall_clearance_m + 0.02);
      EXPECT_GT(c.y(), -2.5 + o.wall_clearance_m - 0.02);
      EXPECT_LT(c.y(), 2.5 - o.wall_clearance_m + 0.02);
      EXPECT_GE(c.z(), o.min_altitude_m - 1e-9);
      EXPECT_LE(c.z(), o.max_altitude_m + 1e-9);
      EXPECT_GT(ObstacleDistance(o.obstacles, c.head<2>()), o.obstacle_clearance_m - 0.02);
      if (i > 0) {
        const Pose3& prev = (*a)[i - 1].world_from_camera;
        const double step = (c - prev.translation()).norm();
        path += step;
        max_speed = std::max(max_speed, step * 30.0);
        max_rate = std::max(max_rate, AngleBetween(prev, pose) * 30.0);
      }
    }
    EXPECT_LT(max_speed, o.cruise_speed_mps + 0.05);
    EXPECT_GT(path / o.duration_s, 0.6);  // faster than a walking head on average
    // Yaw-rate bound plus the slow look-around and bank.
    EXPECT_LT(max_rate, (o.max_yaw_rate_deg_s + 15.0) * kPi / 180.0);
  }
}

TEST(DroneMotionTest, StartsFromRest) {
  Expected<Trajectory> motion = GenerateDroneMotion(Drone(5));
  ASSERT_TRUE(motion.ok()) << motion.error();
  const double first_step =
      ((*motion)[1].world_from_camera.translation() - (*motion)[0].world_from_camera.translation())
          .norm();
  EXPECT_LT(first_step * 30.0, 0.2);
}

TEST(GeneratedMotionTest, RejectsBadOptionsAndImpossibleRooms) {
  HandheldMotionOptions handheld = Handheld(1);
  handheld.min_distance_m = 2.0;
  handheld.max_distance_m = 1.0;
  EXPECT_FALSE(GenerateHandheldMotion(handheld).ok());
  DroneMotionOptions drone = Drone(1);
  drone.min_altitude_m = 2.6;  // above the ceiling margin of a 2.7 m room
  EXPECT_FALSE(GenerateDroneMotion(drone).ok());
  drone = Drone(1);
  drone.obstacles = {Eigen::AlignedBox2d(Eigen::Vector2d(-3, -2.5), Eigen::Vector2d(3, 2.5))};
  Expected<Trajectory> blocked = GenerateDroneMotion(drone);
  ASSERT_FALSE(blocked.ok());
  EXPECT_NE(blocked.error().find("drone motion"), std::string::npos);
}

}  // namespace
}  // namespace m2s
