// Hand-held camera motion: viewpoints around one target at a time, reached by minimum-jerk
// segments; the gaze follows the target (moving smoothly to the next one) and shakes (sway,
// tremor, roll, translational jitter).
#include <algorithm>
#include <cmath>

#include "m2s/common/motion.h"
#include "motion_internal.h"

namespace m2s {
namespace {

using motion_internal::CameraPose;
using motion_internal::FreeSpace;
using motion_internal::kDegToRad;
using motion_internal::kMinJerkPeak;
using motion_internal::kPi;
using motion_internal::MinJerk;
using motion_internal::Random;
using motion_internal::WrapAngle;

constexpr int kMaxTries = 4000;
constexpr double kMinSegment_s = 1.2;  // shortest segment
constexpr double kGazeTurn_s = 1.2;    // shortest time the gaze takes to move to a new target
constexpr double kGazeRate = 45.0 * motion_internal::kDegToRad;  // mean gaze turn rate

struct Segment {
  double t0, duration, gaze_turn_s;
  double yaw_turn;  // signed yaw from the old target to the new one, seen from `from`
  Eigen::Vector3d from, to;
  Eigen::Vector3d target_before, target;
};

Expected<std::vector<Segment>> Plan(const HandheldMotionOptions& o,
                                    const std::vector<Eigen::Vector3d>& targets, Random& random) {
  const FreeSpace space(Eigen::AlignedBox2d(o.room.min().head<2>(), o.room.max().head<2>()),
                        o.wall_clearance_m, o.obstacles, o.obstacle_clearance_m);
  const double floor = o.room.min().z();
  const double top = std::min(o.max_height_m, o.room.sizes().z() - 0.3);
  // A viewpoint around `target` at a bearing near `bearing` (any bearing when unconstrained).
  auto viewpoint = [&](const Eigen::Vector3d& target, double bearing, double spread,
                       Eigen::Vector3d* out) {
    const double a = bearing + random.Uniform(-spread, spread);
    const double d = random.Uniform(o.min_distance_m, o.max_distance_m);
    const Eigen::Vector2d p = target.head<2>() + d * Eigen::Vector2d(std::cos(a), std::sin(a));
    *out = Eigen::Vector3d(p.x(), p.y(), floor + random.Uniform(o.min_height_m, top));
    return space.IsFree(p);
  };
  size_t target_index = static_cast<size_t>(random.Uniform(0.0, 1.0) * targets.size());
  target_index = std::min(target_index, targets.size() - 1);
  Eigen::Vector3d position;
  int tries = 0;
  while (!viewpoint(targets[target_index], 0.0, kPi, &position)) {
    if (++tries >= kMaxTries) {
      return Expected<std::vector<Segment>>::Error(
          "hand-held motion: no free viewpoint near the first target");
    }
  }
  std::vector<Segment> segments;
  double t = 0.0;
  Eigen::Vector3d gaze = targets[target_index];
  int views_left = o.viewpoints_per_target;
  int dead_ends = 0;
  while (t < o.duration_s) {
    if (views_left == 0 && targets.size() > 1) {
      size_t next = target_index;
      while (next == target_index) {
        next = std::min(targets.size() - 1,
                        static_cast<size_t>(random.Uniform(0.0, 1.0) * targets.size()));
      }
      target_index = next;
      views_left = o.viewpoints_per_target;
    }
    const Eigen::Vector3d& target = targets[target_index];
    const Eigen::Vector2d from_target = position.head<2>() - target.head<2>();
    const double bearing = std::atan2(from_target.y(), from_target.x());
    Eigen::Vector3d next;
    bool found = false;
    for (int i = 0; i < kMaxTries && !found; ++i) {
      // Orbit near the current bearing first, then anywhere around the target.
      const double spread = i < kMaxTries / 2 ? o.max_orbit_deg * kDegToRad : kPi;
      found = viewpoint(target, bearing, spread, &next) && (next - position).norm() > 0.25 &&
              space.SegmentFree(position.head<2>(), next.head<2>());
    }
    if (!found) {
      // No viewpoint of this target is reachable from here: try the next target.
      if (++dead_ends > static_cast<int>(targets.size()) + kMaxTries / 100) {
        return Expected<std::vector<Segment>>::Error(
            "hand-held motion: no reachable viewpoint (room too small or too cluttered)");
      }
      target_index = (target_index + 1) % targets.size();
      views_left = o.viewpoints_per_target;
      continue;
    }
    dead_ends = 0;
    // The gaze turns from the old target to the new one as seen from the segment's start.
    const Eigen::Vector3d old_ray = gaze - position, new_ray = target - position;
    const double yaw_turn =
        WrapAngle(std::atan2(new_ray.y(), new_ray.x()) - std::atan2(old_ray.y(), old_ray.x()));
    const double angle =
        std::abs(yaw_turn) + std::abs(std::atan2(new_ray.z(), new_ray.head<2>().norm()) -
                                      std::atan2(old_ray.z(), old_ray.head<2>().norm()));
    const double gaze_turn = std::max(kGazeTurn_s, angle / kGazeRate);
    const double duration =
        std::max({kMinSegment_s, gaze_turn, kMinJerkPeak * (next - position).norm() / o.speed_mps});
    segments.push_back({t, duration, gaze_turn, yaw_turn, position, next, gaze, target});
    t += duration;
    position = next;
    gaze = target;
    --views_left;
  }
  return segments;
}

}  // namespace

Status HandheldMotionOptions::Check() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (Status s = motion_internal::CheckRoomAndClearances(duration_s, rate_hz, room,
                                                         wall_clearance_m, obstacle_clearance_m);
      !s) {
    return s;
  }
  if (!positive(min_distance_m) || !(max_distance_m >= min_distance_m)) {
    return Status::Error("need 0 < min_distance_m <= max_distance_m");
  }
  if (!positive(min_height_m) || !(max_height_m >= min_height_m) ||
      min_height_m > room.sizes().z() - 0.3) {
    return Status::Error("need 0 < min_height_m <= max_height_m, 0.3 m below the ceiling");
  }
  if (!positive(speed_mps)) return Status::Error("speed_mps must be positive");
  if (viewpoints_per_target < 1) return Status::Error("viewpoints_per_target must be >= 1");
  if (!positive(max_orbit_deg) || !non_negative(sway_amplitude_deg) ||
      !non_negative(tremor_amplitude_deg) || !non_negative(roll_amplitude_deg) ||
      !non_negative(jitter_m)) {
    return Status::Error("orbit, sway, tremor, roll and jitter must be non-negative");
  }
  for (const Eigen::Vector3d& target : targets) {
    if (!target.allFinite()) return Status::Error("targets must be finite");
  }
  return Status::Ok();
}

Expected<Trajectory> GenerateHandheldMotion(const HandheldMotionOptions& o) {
  if (Status s = o.Check(); !s) return s.Prefixed("hand-held motion options: ");
  std::vector<Eigen::Vector3d> targets = o.targets;
  if (targets.empty()) {
    const Eigen::Vector3d centre = o.room.center();
    targets.emplace_back(centre.x(), centre.y(), o.room.min().z() + 1.0);
  }
  Random random(o.seed);
  Expected<std::vector<Segment>> segments = Plan(o, targets, random);
  if (!segments) return Expected<Trajectory>(segments.status());
  // Sway (slow), tremor (three fast components) and jitter, each with a random phase.
  double phase[12];
  for (double& p : phase) p = random.Uniform(0.0, 2.0 * kPi);
  auto wave = [&](double t, double hz, int k) { return std::sin(2.0 * kPi * hz * t + phase[k]); };

  const auto samples = static_cast<int64_t>(std::floor(o.duration_s * o.rate_hz + 1e-9)) + 1;
  std::vector<TimedPose> poses;
  poses.reserve(static_cast<size_t>(samples));
  size_t e = 0;
  for (int64_t k = 0; k < samples; ++k) {
    const double t = static_cast<double>(k) / o.rate_hz;
    while (e + 1 < segments->size() && t >= (*segments)[e + 1].t0) ++e;
    const Segment& s = (*segments)[e];
    const double tau = std::clamp((t - s.t0) / s.duration, 0.0, 1.0);
    Eigen::Vector3d eye = s.from + (s.to - s.from) * MinJerk(tau);
    eye += o.jitter_m * Eigen::Vector3d(0.6 * wave(t, 1.1, 0) + 0.4 * wave(t, 3.7, 1),
                                        0.6 * wave(t, 0.9, 2) + 0.4 * wave(t, 4.3, 3),
                                        0.6 * wave(t, 1.3, 4) + 0.4 * wave(t, 3.1, 5));
    // The gaze turns in yaw and pitch from the old target's direction to the new target's, both
    // seen from the current camera position (the horizon stays level through the turn).
    const double turn = MinJerk(std::clamp((t - s.t0) / s.gaze_turn_s, 0.0, 1.0));
    const Eigen::Vector3d old_ray = s.target_before - eye, new_ray = s.target - eye;
    const double old_yaw = std::atan2(old_ray.y(), old_ray.x());
    const double old_pitch = std::atan2(old_ray.z(), old_ray.head<2>().norm());
    // The yaw difference keeps the turning direction chosen at the segment's start.
    const double yaw_difference =
        s.yaw_turn + WrapAngle(std::atan2(new_ray.y(), new_ray.x()) - old_yaw - s.yaw_turn);
    const double gaze_yaw = old_yaw + turn * yaw_difference;
    const double gaze_pitch =
        old_pitch + turn * (std::atan2(new_ray.z(), new_ray.head<2>().norm()) - old_pitch);
    const double sway = o.sway_amplitude_deg * kDegToRad;
    const double tremor = o.tremor_amplitude_deg * kDegToRad;
    const double yaw =
        gaze_yaw + sway * wave(t, 0.31, 6) +
        tremor * (0.5 * wave(t, 2.3, 7) + 0.3 * wave(t, 4.1, 8) + 0.2 * wave(t, 6.7, 9));
    const double pitch = gaze_pitch + sway * wave(t, 0.23, 10) +
                         tremor * (0.6 * wave(t, 2.9, 11) + 0.4 * wave(t, 5.3, 7));
    const double roll =
        o.roll_amplitude_deg * kDegToRad * (0.8 * wave(t, 0.17, 8) + 0.2 * wave(t, 3.3, 9));
    poses.push_back({t, CameraPose(eye, yaw, pitch, roll)});
  }
  return Trajectory::FromPoses(std::move(poses));
}

}  // namespace m2s
