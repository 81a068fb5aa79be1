// Drone flight: random free waypoints joined by a uniform cubic B-spline (each new span is
// checked for clearance when its last control point is drawn), sampled densely, timed by a
// speed profile (cruise speed, lateral and longitudinal acceleration bounds, start from rest),
// then resampled at the output rate. The camera looks along the flight direction.
#include <algorithm>
#include <cmath>

#include "m2s/common/motion.h"
#include "motion_internal.h"

namespace m2s {
namespace {

using motion_internal::CameraPose;
using motion_internal::FreeSpace;
using motion_internal::kDegToRad;
using motion_internal::kPi;
using motion_internal::Random;
using motion_internal::WrapAngle;

constexpr int kMaxTries = 2000;
// Dead ends undone by dropping the last waypoint, per attempt: this many, plus this many per
// waypoint the path needs at its shortest segments.
constexpr int kMaxBacktracks = 200;
constexpr int kBacktracksPerWaypoint = 10;
constexpr int kMaxAttempts = 20;              // plans started afresh from a new start point
constexpr int kSamplesPerSpan = 64;           // dense samples of each B-spline span
constexpr double kGravity = 9.81;             // for the bank angle of a coordinated turn
constexpr double kCeilingMarginM = 0.3;       // altitude stays this far below the ceiling
constexpr double kAltitudeWavelengthM = 9.0;  // altitude changes over this much flown path
constexpr double kOpenRadiusM = 0.5;  // waypoints have free space this far around (room to turn)
constexpr double kPathLengthFactor = 2.5;  // path planned: cruise speed x duration x this

// Whether the disc of kOpenRadiusM around p is free (sampled on two circles).
bool IsOpen(const FreeSpace& space, const Eigen::Vector2d& p) {
  constexpr int kDirections = 12;
  for (int k = 0; k < kDirections; ++k) {
    const double a = 2.0 * kPi * k / kDirections;
    const Eigen::Vector2d d(std::cos(a), std::sin(a));
    if (!space.IsFree(p + 0.5 * kOpenRadiusM * d) || !space.IsFree(p + kOpenRadiusM * d)) {
      return false;
    }
  }
  return true;
}

// Uniform cubic B-spline span through control points p0..p3 at u in [0, 1].
Eigen::Vector2d Span(const Eigen::Vector2d& p0, const Eigen::Vector2d& p1,
                     const Eigen::Vector2d& p2, const Eigen::Vector2d& p3, double u) {
  const double u2 = u * u, u3 = u2 * u;
  return ((1 - u) * (1 - u) * (1 - u) * p0 + (3 * u3 - 6 * u2 + 4) * p1 +
          (-3 * u3 + 3 * u2 + 3 * u + 1) * p2 + u3 * p3) /
         6.0;
}

// Control points whose spline spans keep the clearance (checked densely, span by span). A dead
// end drops the last waypoints; an attempt that cannot leave its start begins elsewhere.
Expected<std::vector<Eigen::Vector2d>> PlanControlPoints(const DroneMotionOptions& o,
                                                         Random& random) {
  const Eigen::AlignedBox2d room(o.room.min().head<2>(), o.room.max().head<2>());
  const FreeSpace space(room, o.wall_clearance_m, o.obstacles, o.obstacle_clearance_m);
  using Points = std::vector<Eigen::Vector2d>;
  const double wanted = kPathLengthFactor * o.cruise_speed_mps * o.duration_s;
  const double max_turn = o.max_turn_deg * kDegToRad;
  const int max_backtracks =
      kMaxBacktracks + kBacktracksPerWaypoint * static_cast<int>(wanted / o.min_segment_m);
  for (int attempt = 0; attempt < kMaxAttempts; ++attempt) {
    Eigen::Vector2d start;
    int tries = 0;
    do {
      start = space.RandomPoint(random);
    } while (!(space.IsFree(start) && IsOpen(space, start)) && ++tries < kMaxTries);
    if (tries >= kMaxTries) {
      return Expected<Points>::Error("drone motion: no free space in the room");
    }
    // The start point three times: the spline starts exactly there, at rest.
    Points points = {start, start, start};
    double length = 0.0;
    int backtracks = 0;
    while (length < wanted) {
      const size_t n = points.size();
      const Eigen::Vector2d last = points[n - 1];
      const Eigen::Vector2d heading = last - points[n - 2];
      bool found = false;
      Eigen::Vector2d next;
      for (int i = 0; i < kMaxTries && !found; ++i) {
        next = space.RandomPoint(random);
        const Eigen::Vector2d step = next - last;
        if (step.norm() < (i < kMaxTries / 2 ? o.min_segment_m : 0.5 * o.min_segment_m)) continue;
        if (heading.norm() > 1e-9 &&
            std::abs(WrapAngle(std::atan2(step.y(), step.x()) -
                               std::atan2(heading.y(), heading.x()))) > max_turn) {
          continue;
        }
        if (!space.IsFree(next) || !IsOpen(space, next) || !space.SegmentFree(last, next)) {
          continue;
        }
        found = true;
        for (int k = 0; k <= kSamplesPerSpan && found; ++k) {
          const double u = static_cast<double>(k) / kSamplesPerSpan;
          found = space.IsFree(Span(points[n - 3], points[n - 2], points[n - 1], next, u));
        }
      }
      if (found) {
        length += (next - last).norm();
        points.push_back(next);
      } else if (n > 4 && ++backtracks <= max_backtracks) {
        length -= (points[n - 1] - points[n - 2]).norm();
        points.pop_back();
      } else {
        break;
      }
    }
    if (length >= wanted) return points;
  }
  return Expected<Points>::Error(
      "drone motion: no reachable waypoint (room too small or too cluttered)");
}

struct PathSample {
  Eigen::Vector2d position;
  double s = 0.0;          // arc length
  double heading = 0.0;    // unwrapped
  double curvature = 0.0;  // signed, 1/m
  double speed = 0.0;
  double t = 0.0;
};

}  // namespace

Status DroneMotionOptions::Check() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (Status s = motion_internal::CheckRoomAndClearances(duration_s, rate_hz, room,
                                                         wall_clearance_m, obstacle_clearance_m);
      !s) {
    return s;
  }
  if (!positive(min_altitude_m) || !(max_altitude_m >= min_altitude_m) ||
      min_altitude_m > room.sizes().z() - kCeilingMarginM) {
    return Status::Error("need 0 < min_altitude_m <= max_altitude_m, 0.3 m below the ceiling");
  }
  if (!positive(cruise_speed_mps) || !positive(max_acceleration_mps2) ||
      !positive(max_lateral_acceleration_mps2) || !positive(max_yaw_rate_deg_s) ||
      !positive(min_segment_m)) {
    return Status::Error("speed, accelerations, yaw rate and min_segment_m must be positive");
  }
  if (!(max_turn_deg > 0.0 && max_turn_deg <= 180.0)) {
    return Status::Error("max_turn_deg must be in (0, 180]");
  }
  if (!(std::abs(camera_tilt_deg) + look_amplitude_deg < 80.0) ||
      !non_negative(look_amplitude_deg) || !non_negative(bank_fraction)) {
    return Status::Error("|camera_tilt_deg| + look_amplitude_deg must stay below 80 deg");
  }
  return Status::Ok();
}

Expected<Trajectory> GenerateDroneMotion(const DroneMotionOptions& o) {
  if (Status s = o.Check(); !s) return s.Prefixed("drone motion options: ");
  Random random(o.seed);
  Expected<std::vector<Eigen::Vector2d>> control = PlanControlPoints(o, random);
  if (!control) return Expected<Trajectory>(control.status());

  // Dense samples along the spline: arc length, heading, curvature.
  std::vector<PathSample> path;
  for (size_t i = 0; i + 3 < control->size(); ++i) {
    for (int k = (i == 0 ? 0 : 1); k <= kSamplesPerSpan; ++k) {
      PathSample sample;
      sample.position = Span((*control)[i], (*control)[i + 1], (*control)[i + 2], (*control)[i + 3],
                             static_cast<double>(k) / kSamplesPerSpan);
      if (!path.empty() && (sample.position - path.back().position).norm() < 1e-6) continue;
      path.push_back(sample);
    }
  }
  if (path.size() < 3) return Status::Error("drone motion: degenerate path");
  for (size_t i = 1; i < path.size(); ++i) {
    const Eigen::Vector2d d = path[i].position - path[i - 1].position;
    path[i].s = path[i - 1].s + d.norm();
    const double heading = std::atan2(d.y(), d.x());
    path[i].heading =
        i == 1 ? heading : path[i - 1].heading + WrapAngle(heading - path[i - 1].heading);
  }
  path[0].heading = path[1].heading;
  for (size_t i = 1; i + 1 < path.size(); ++i) {
    const double ds = path[i + 1].s - path[i - 1].s;
    path[i].curvature = ds > 0.0 ? (path[i + 1].heading - path[i].heading) / (0.5 * ds) : 0.0;
  }
  // Speed: bounded by cruise and lateral acceleration; forward pass from rest, backward pass to
  // rest at the end of the planned path; then time by the trapezoid rule.
  const double max_yaw_rate = o.max_yaw_rate_deg_s * kDegToRad;
  for (PathSample& p : path) {
    const double curvature = std::max(std::abs(p.curvature), 1e-9);
    p.speed = std::min({o.cruise_speed_mps, std::sqrt(o.max_lateral_acceleration_mps2 / curvature),
                        max_yaw_rate / curvature});
  }
  path.front().speed = 0.0;
  path.back().speed = 0.0;
  for (size_t i = 1; i < path.size(); ++i) {
    const double ds = path[i].s - path[i - 1].s;
    path[i].speed = std::min(path[i].speed, std::sqrt(path[i - 1].speed * path[i - 1].speed +
                                                      2.0 * o.max_acceleration_mps2 * ds));
  }
  for (size_t i = path.size() - 1; i-- > 0;) {
    const double ds = path[i + 1].s - path[i].s;
    path[i].speed = std::min(path[i].speed, std::sqrt(path[i + 1].speed * path[i + 1].speed +
                                                      2.0 * o.max_acceleration_mps2 * ds));
  }
  for (size_t i = 1; i < path.size(); ++i) {
    const double mean = 0.5 * (path[i].speed + path[i - 1].speed);
    path[i].t = path[i - 1].t + (path[i].s - path[i - 1].s) / std::max(mean, 1e-6);
  }
  if (path.back().t < o.duration_s) {
    return Status::Error("drone motion: planned path too short for the duration");
  }

  double phase[4];
  for (double& p : phase) p = random.Uniform(0.0, 2.0 * kPi);
  const double floor = o.room.min().z();
  const double top = std::min(o.max_altitude_m, o.room.sizes().z() - kCeilingMarginM);
  const double mid = 0.5 * (o.min_altitude_m + top), amplitude = 0.5 * (top - o.min_altitude_m);
  const double look = o.look_amplitude_deg * kDegToRad;
  const auto samples = static_cast<int64_t>(std::floor(o.duration_s * o.rate_hz + 1e-9)) + 1;
  std::vector<TimedPose> poses;
  poses.reserve(static_cast<size_t>(samples));
  size_t j = 0;
  for (int64_t k = 0; k < samples; ++k) {
    const double t = static_cast<double>(k) / o.rate_hz;
    while (j + 2 < path.size() && path[j + 1].t <= t) ++j;
    const PathSample& a = path[j];
    const PathSample& b = path[j + 1];
    const double w = std::clamp((t - a.t) / std::max(b.t - a.t, 1e-12), 0.0, 1.0);
    const Eigen::Vector2d xy = a.position + w * (b.position - a.position);
    const double s = a.s + w * (b.s - a.s);
    const double heading = a.heading + w * (b.heading - a.heading);
    const double speed = a.speed + w * (b.speed - a.speed);
    const double curvature = a.curvature + w * (b.curvature - a.curvature);
    const double altitude =
        mid + amplitude * std::sin(2.0 * kPi * s / kAltitudeWavelengthM + phase[0]);
    const double bank = std::atan(speed * speed * curvature / kGravity);
    const double yaw = heading + look * std::sin(2.0 * kPi * 0.13 * t + phase[1]);
    const double pitch =
        o.camera_tilt_deg * kDegToRad + 0.5 * look * std::sin(2.0 * kPi * 0.09 * t + phase[2]);
    // Banking into a left turn (positive curvature) rolls the camera counter-clockwise as seen
    // from behind, i.e. a negative roll about its viewing axis.
    const double roll = -o.bank_fraction * bank;
    poses.push_back(
        {t, CameraPose(Eigen::Vector3d(xy.x(), xy.y(), floor + altitude), yaw, pitch, roll)});
  }
  return Trajectory::FromPoses(std::move(poses));
}

}  // namespace m2s
