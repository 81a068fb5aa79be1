// Helpers shared by the hand-held and drone motion generators (motion.h): a portable uniform
// random source, the minimum-jerk profile, free-space tests on the floor plan and the camera
// pose from yaw / pitch / roll.
#pragma once

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "m2s/common/geometry.h"
#include "m2s/common/status.h"

namespace m2s::motion_internal {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;
constexpr double kMinJerkPeak = 1.875;   // peak of d/dtau of the minimum-jerk profile
constexpr double kPathCheckStep = 0.05;  // metres between clearance checks along a segment

inline double MinJerk(double tau) { return tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau)); }
inline double WrapAngle(double a) { return std::remainder(a, 2.0 * kPi); }

// Uniform doubles from a std::mt19937_64 (its output is specified; std distributions are not).
class Random {
 public:
  explicit Random(uint64_t seed) : engine_(seed) {}
  double Uniform(double lo, double hi) {
    return lo + (hi - lo) * static_cast<double>(engine_() >> 11) * 0x1.0p-53;
  }

 private:
  std::mt19937_64 engine_;
};

// The checks the options of the hand-held and drone generators share: rate and duration, a
// finite room with space left inside the wall clearance, non-negative clearances.
template <typename Box>
Status CheckRoomAndClearances(double duration_s, double rate_hz, const Box& room,
                              double wall_clearance_m, double obstacle_clearance_m) {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!positive(duration_s) || !positive(rate_hz)) {
    return Status::Error("duration_s and rate_hz must be positive");
  }
  if (!room.min().allFinite() || !room.max().allFinite() || room.isEmpty()) {
    return Status::Error("room must be a finite, non-empty box");
  }
  if (!non_negative(wall_clearance_m) || !non_negative(obstacle_clearance_m)) {
    return Status::Error("clearances must be non-negative");
  }
  if ((room.sizes().template head<2>().array() <= 2.0 * wall_clearance_m).any()) {
    return Status::Error("room is smaller than twice the wall clearance");
  }
  return Status::Ok();
}

// The floor plan: a rectangle shrunk by the wall clearance, minus obstacle footprints grown by
// their clearance.
class FreeSpace {
 public:
  FreeSpace(const Eigen::AlignedBox2d& room, double wall_clearance,
            const std::vector<Eigen::AlignedBox2d>& obstacles, double obstacle_clearance)
      : free_(room.min().array() + wall_clearance, room.max().array() - wall_clearance),
        obstacles_(obstacles),
        obstacle_clearance_(obstacle_clearance) {}

  bool IsFree(const Eigen::Vector2d& p) const {
    if (!free_.contains(p)) return false;
    return std::all_of(obstacles_.begin(), obstacles_.end(), [&](const Eigen::AlignedBox2d& b) {
      return b.exteriorDistance(p) > obstacle_clearance_;
    });
  }
  bool SegmentFree(const Eigen::Vector2d& a, const Eigen::Vector2d& b) const {
    const int steps = std::max(1, static_cast<int>(std::ceil((b - a).norm() / kPathCheckStep)));
    for (int i = 0; i <= steps; ++i) {
      if (!IsFree(a + (b - a) * (static_cast<double>(i) / steps))) return false;
    }
    return true;
  }
  Eigen::Vector2d RandomPoint(Random& random) const {
    return {random.Uniform(free_.min().x(), free_.max().x()),
            random.Uniform(free_.min().y(), free_.max().y())};
  }
  const Eigen::AlignedBox2d& box() const { return free_; }

 private:
  Eigen::AlignedBox2d free_;
  std::vector<Eigen::AlignedBox2d> obstacles_;
  double obstacle_clearance_;
};

// world_from_camera for a camera at `eye` with yaw (about world z, 0 = looking along +x), pitch
// (positive = up) and roll (about the viewing direction), OpenCV camera axes, world z up.
inline Pose3 CameraPose(const Eigen::Vector3d& eye, double yaw, double pitch, double roll) {
  Eigen::Matrix3d world_from_level_camera;  // yaw = pitch = roll = 0: camera z along world +x
  world_from_level_camera << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const Eigen::Matrix3d r = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                            Eigen::AngleAxisd(-pitch, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                            world_from_level_camera *
                            Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return Pose3(r, eye);
}

}  // namespace m2s::motion_internal
