// Generated camera motion beyond head motion (trajectory.h): a hand-held camera that inspects
// objects and a drone flying through a room. Both are deterministic for a given seed, stay
// inside the room (with a clearance from walls, floor and ceiling) and keep a clearance from
// the (x, y) footprints of obstacles, which are treated as reaching the ceiling.
//
// Conventions as in trajectory.h: world_from_camera poses, OpenCV camera axes, world z up,
// floor at room.min().z().
//
//   HandheldMotionOptions o;
//   o.room = layout.room;  o.obstacles = layout.obstacles;  o.targets = object_centres;
//   Expected<Trajectory> handheld = GenerateHandheldMotion(o);
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "m2s/common/status.h"
#include "m2s/common/trajectory.h"

namespace m2s {

// A person walking slowly around objects with a phone or a hand-held camera: the camera moves
// between viewpoints around one target at a time (minimum-jerk segments, a few viewpoints per
// target), always looks at the current target (the gaze moves smoothly to the next target), is
// held lower and closer than a head, and shakes: a slow arm sway and a faster tremor in yaw,
// pitch and roll, plus a small translational jitter.
struct HandheldMotionOptions {
  double duration_s = 30.0;
  double rate_hz = 30.0;
  uint64_t seed = 1;
  Eigen::AlignedBox3d room =
      Eigen::AlignedBox3d(Eigen::Vector3d(-3.0, -2.5, 0.0), Eigen::Vector3d(3.0, 2.5, 2.7));
  double wall_clearance_m = 0.4;
  std::vector<Eigen::AlignedBox2d> obstacles;
  double obstacle_clearance_m = 0.25;
  // Points the camera looks at (object centres); empty: the room centre at 1 m height.
  std::vector<Eigen::Vector3d> targets;
  double min_distance_m = 0.6;  // horizontal distance from the camera to its target
  double max_distance_m = 1.5;
  double min_height_m = 0.9;  // camera height above the floor
  double max_height_m = 1.6;
  double speed_mps = 0.5;             // peak speed on a segment
  int viewpoints_per_target = 3;      // segments spent on one target before the next
  double max_orbit_deg = 70.0;        // bearing change around the target per segment
  double sway_amplitude_deg = 4.0;    // slow arm sway (about 0.3 Hz)
  double tremor_amplitude_deg = 0.8;  // hand tremor (2-7 Hz)
  double roll_amplitude_deg = 6.0;
  double jitter_m = 0.008;  // translational shake

  Status Check() const;
};
Expected<Trajectory> GenerateHandheldMotion(const HandheldMotionOptions& options);

// A small drone flying through a room: a smooth path (uniform cubic B-spline through random
// free waypoints, curvature-continuous) flown at a cruise speed that slows in turns (lateral
// acceleration bound) and starts from rest; altitude varies slowly; the camera looks along the
// flight direction (smooth yaw turns), tilted down, with a small look-around and a fraction of
// the bank angle of each turn as roll.
struct DroneMotionOptions {
  double duration_s = 30.0;
  double rate_hz = 30.0;
  uint64_t seed = 1;
  Eigen::AlignedBox3d room =
      Eigen::AlignedBox3d(Eigen::Vector3d(-3.0, -2.5, 0.0), Eigen::Vector3d(3.0, 2.5, 2.7));
  double wall_clearance_m = 0.6;
  std::vector<Eigen::AlignedBox2d> obstacles;
  double obstacle_clearance_m = 0.4;
  double min_altitude_m = 1.7;  // above the floor; clamped to the room height less 0.3 m
  double max_altitude_m = 2.3;
  double cruise_speed_mps = 1.5;
  double max_acceleration_mps2 = 1.5;
  double max_lateral_acceleration_mps2 = 1.5;
  double max_yaw_rate_deg_s = 60.0;  // turning rate of the flight direction
  double min_segment_m = 1.2;        // shortest distance between two waypoints
  double max_turn_deg = 100.0;       // largest heading change at a waypoint
  double camera_tilt_deg = -20.0;    // camera pitch (negative: looking down)
  double look_amplitude_deg = 8.0;   // slow yaw / pitch look-around
  double bank_fraction = 0.3;        // roll = this fraction of the coordinated-turn bank angle

  Status Check() const;
};
Expected<Trajectory> GenerateDroneMotion(const DroneMotionOptions& options);

}  // namespace m2s
