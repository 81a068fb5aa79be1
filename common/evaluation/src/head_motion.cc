// First-person head motion: minimum-jerk walks between random waypoints, a heading that turns
// towards the walking direction, smooth look-around oscillations, step bobbing and pauses.
#include <algorithm>
#include <cmath>
#include <random>

#include "m2s/common/check.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"
#include "motion_internal.h"

namespace m2s {
namespace {

using motion_internal::FreeSpace;
using motion_internal::kDegToRad;
using motion_internal::kMinJerkPeak;
using motion_internal::kPi;
using motion_internal::MinJerk;
using motion_internal::Random;
using motion_internal::WrapAngle;

constexpr double kTurnRate = 50.0 * kDegToRad;  // mean rate of the heading's turn to a new segment
constexpr double kMinTurn_s = 0.8;              // shortest turn
constexpr double kPreferredMaxTurn = 100.0 * kDegToRad;  // sharper turns only as a fallback
constexpr int kMaxTries = 2000;

// Derivative of the minimum-jerk profile on [0, 1].
double MinJerkRate(double tau) { return 30.0 * tau * tau * (1.0 - tau) * (1.0 - tau); }

struct Event {  // a walk from `from` to `to`, or a pause at `from` when from == to
  double t0, duration;
  Eigen::Vector2d from, to;
  double yaw_before, yaw;  // heading at the start and once turned
};

Expected<std::vector<Event>> Plan(const HeadMotionOptions& o, Random& random) {
  const FreeSpace planner(o.room, o.wall_clearance_m, o.obstacles, o.obstacle_clearance_m);
  Eigen::Vector2d position;
  int tries = 0;
  do {
    position = planner.RandomPoint(random);
  } while (!planner.IsFree(position) && ++tries < kMaxTries);
  if (tries >= kMaxTries) {
    return Expected<std::vector<Event>>::Error("head motion: no free floor space in the room");
  }
  std::vector<Event> events;
  double t = 0.0;
  double yaw = 0.0;
  while (t < o.duration_s) {
    Eigen::Vector2d next;
    bool found = false;
    for (int i = 0; i < kMaxTries && !found; ++i) {
      next = planner.RandomPoint(random);
      const double min_length = i < kMaxTries / 2 ? o.min_segment_m : 0.3 * o.min_segment_m;
      const bool gentle =
          events.empty() || i >= kMaxTries / 2 ||
          std::abs(WrapAngle(std::atan2(next.y() - position.y(), next.x() - position.x()) - yaw)) <=
              kPreferredMaxTurn;
      found = gentle && (next - position).norm() >= min_length && planner.IsFree(next) &&
              planner.SegmentFree(position, next);
    }
    if (!found) {
      return Expected<std::vector<Event>>::Error(
          "head motion: no reachable waypoint (room too small or too cluttered)");
    }
    const Eigen::Vector2d step = next - position;
    const double walk_yaw = std::atan2(step.y(), step.x());
    const double yaw_before = events.empty() ? walk_yaw : yaw;
    yaw = yaw_before + WrapAngle(walk_yaw - yaw_before);
    const double duration = kMinJerkPeak * step.norm() / o.walking_speed_mps;
    events.push_back({t, duration, position, next, yaw_before, yaw});
    t += duration;
    position = next;
    if (random.Uniform(0.0, 1.0) < o.pause_probability) {
      const double pause = o.pause_duration_s * random.Uniform(0.6, 1.4);
      events.push_back({t, pause, position, position, yaw, yaw});
      t += pause;
    }
  }
  return events;
}

// world_from_camera for a head at `eye` with yaw (about world z, 0 = looking along +x), pitch
// (positive = up) and roll (about the viewing direction), OpenCV camera axes, world z up.
Pose3 HeadPose(const Eigen::Vector3d& eye, double yaw, double pitch, double roll) {
  Eigen::Matrix3d world_from_level_camera;  // yaw = pitch = roll = 0: camera z along world +x
  world_from_level_camera << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const Eigen::Matrix3d r = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                            Eigen::AngleAxisd(-pitch, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                            world_from_level_camera *
                            Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return Pose3(r, eye);
}

}  // namespace

Status HeadMotionOptions::Check() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!positive(duration_s)) return Status::Error("duration_s must be positive");
  if (!positive(rate_hz)) return Status::Error("rate_hz must be positive");
  if (!room.min().allFinite() || !room.max().allFinite())
    return Status::Error("room must be finite");
  if (!non_negative(wall_clearance_m) || !non_negative(obstacle_clearance_m)) {
    return Status::Error("clearances must be non-negative");
  }
  if ((room.sizes().array() <= 2.0 * wall_clearance_m).any()) {
    return Status::Error("room is smaller than twice the wall clearance");
  }
  if (!positive(eye_height_m)) return Status::Error("eye_height_m must be positive");
  if (!positive(walking_speed_mps)) return Status::Error("walking_speed_mps must be positive");
  if (!positive(min_segment_m)) return Status::Error("min_segment_m must be positive");
  if (!non_negative(yaw_amplitude_deg) || !non_negative(pitch_amplitude_deg) ||
      !non_negative(roll_amplitude_deg) || !std::isfinite(pitch_bias_deg) ||
      std::abs(pitch_bias_deg) + pitch_amplitude_deg * 1.6 >= 85.0) {
    return Status::Error(
        "look-around amplitudes must be non-negative and keep |pitch| below 85 deg");
  }
  if (!positive(look_frequency_hz)) return Status::Error("look_frequency_hz must be positive");
  if (!(pause_probability >= 0.0 && pause_probability <= 1.0)) {
    return Status::Error("pause_probability must be in [0, 1]");
  }
  if (!non_negative(pause_duration_s) || !non_negative(bob_amplitude_m) ||
      !non_negative(step_frequency_hz)) {
    return Status::Error(
        "pause_duration_s, bob_amplitude_m and step_frequency_hz must be non-negative");
  }
  return Status::Ok();
}

Expected<Trajectory> GenerateHeadMotion(const HeadMotionOptions& o) {
  if (Status s = o.Check(); !s) return s.Prefixed("head motion options: ");
  Random random(o.seed);
  Expected<std::vector<Event>> events = Plan(o, random);
  if (!events) return Expected<Trajectory>(events.status());
  double phase[6];
  for (double& p : phase) p = random.Uniform(0.0, 2.0 * kPi);

  const double f = o.look_frequency_hz;
  const auto samples = static_cast<int64_t>(std::floor(o.duration_s * o.rate_hz + 1e-9)) + 1;
  std::vector<TimedPose> poses;
  poses.reserve(static_cast<size_t>(samples));
  size_t e = 0;
  for (int64_t k = 0; k < samples; ++k) {
    const double t = static_cast<double>(k) / o.rate_hz;
    while (e + 1 < events->size() && t >= (*events)[e + 1].t0) ++e;
    const Event& event = (*events)[e];
    const double tau = std::clamp((t - event.t0) / event.duration, 0.0, 1.0);
    const Eigen::Vector2d ground = event.from + (event.to - event.from) * MinJerk(tau);
    const double speed_fraction =
        MinJerkRate(tau) / kMinJerkPeak * ((event.to - event.from).norm() > 0.0 ? 1.0 : 0.0);
    const double turn_time = std::clamp(std::abs(event.yaw - event.yaw_before) / kTurnRate,
                                        std::min(kMinTurn_s, event.duration), event.duration);
    const double turn = MinJerk(std::clamp((t - event.t0) / turn_time, 0.0, 1.0));
    const double base_yaw = event.yaw_before + (event.yaw - event.yaw_before) * turn;
    // Looking around more while standing than while walking.
    const double gaze = 1.0 + 0.4 * (1.0 - speed_fraction);
    const double w = 2.0 * kPi * f;
    const double yaw = base_yaw + gaze * o.yaw_amplitude_deg * kDegToRad *
                                      (0.65 * std::sin(w * t + phase[0]) +
                                       0.35 * std::sin(2.3 * w * t + phase[1]));
    const double pitch =
        o.pitch_bias_deg * kDegToRad +
        o.pitch_amplitude_deg * kDegToRad *
            (0.7 * std::sin(0.7 * w * t + phase[2]) + 0.3 * std::sin(1.9 * w * t + phase[3]));
    const double roll = o.roll_amplitude_deg * kDegToRad * std::sin(0.5 * w * t + phase[4]);
    const double bob = o.bob_amplitude_m * speed_fraction *
                       std::sin(2.0 * kPi * o.step_frequency_hz * t + phase[5]);
    const Eigen::Vector3d eye(ground.x(), ground.y(), o.eye_height_m + bob);
    poses.push_back({t, HeadPose(eye, yaw, pitch, roll)});
  }
  return Trajectory::FromPoses(std::move(poses));
}

HeadMotionOptions DefaultHeadMotionOptions() {
  const RoomLayout layout = DefaultRoomLayout();
  HeadMotionOptions options;
  options.room = Eigen::AlignedBox2d(layout.room.min().head<2>(), layout.room.max().head<2>());
  options.obstacles = layout.obstacles;
  options.seed = 7;
  return options;
}

Trajectory DefaultTrajectory() {
  Expected<Trajectory> trajectory = GenerateHeadMotion(DefaultHeadMotionOptions());
  M2S_CHECK(trajectory.ok()) << "default trajectory: " << trajectory.error();
  return std::move(trajectory).value();
}

Expected<Trajectory> LoadTrajectoryOrDefault(const std::string& path) {
  if (path.empty()) return DefaultTrajectory();
  return ReadTum(path);
}

}  // namespace m2s
