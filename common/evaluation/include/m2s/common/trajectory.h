// Camera trajectories: timed poses, file formats (TUM, KITTI, EuRoC), interpolation,
// resampling at a frame rate, and a generator of first-person head motion.
//
// Conventions:
//  * Every pose is `world_from_camera` (x_world = world_from_camera * x_camera) with OpenCV / TUM
//    camera axes: x right, y down, z forward.
//  * The world frame of the generated motion and of MakeDefaultScene() is z up (gravity along
//    -z), floor at z = 0; see DefaultRoomLayout() in scene.h.
//  * Timestamps are seconds (double).
//
// A Trajectory is an immutable value, safe to share between threads once built.
//
//   Expected<Trajectory> gt = ReadTum("groundtruth.tum");
//   if (!gt) return Status::Error(gt.error());
//   Expected<Pose3> pose = gt->Interpolate(1.25);              // slerp + linear translation
//   Expected<Trajectory> at_30hz = gt->Resample(30.0);          // t0 + k / 30
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "m2s/common/geometry.h"
#include "m2s/common/status.h"

namespace m2s {

struct TimedPose {
  double timestamp = 0.0;  // seconds
  Pose3 world_from_camera;
};

// Poses sorted by strictly increasing timestamp.
class Trajectory {
 public:
  Trajectory() = default;
  // Sorts by timestamp (stable). Fails on non-finite values or two poses with the same time.
  static Expected<Trajectory> FromPoses(std::vector<TimedPose> poses);

  const std::vector<TimedPose>& poses() const { return poses_; }
  size_t size() const { return poses_.size(); }
  bool empty() const { return poses_.empty(); }
  const TimedPose& operator[](size_t i) const { return poses_[i]; }
  std::vector<TimedPose>::const_iterator begin() const { return poses_.begin(); }
  std::vector<TimedPose>::const_iterator end() const { return poses_.end(); }
  // Precondition for both: !empty().
  double start_time() const { return poses_.front().timestamp; }
  double end_time() const { return poses_.back().timestamp; }

  // The pose at time t: exactly the stored pose at a sample time, otherwise linear in
  // translation and slerp in rotation between the two neighbouring samples. Fails outside
  // [start_time(), end_time()] and on an empty trajectory.
  Expected<Pose3> Interpolate(double t) const;

  // Poses at t = start_time() + k / rate_hz for k = 0, 1, ... while t <= end_time()
  // (a final time within 1e-9 s past the end is clamped to the end). Fails on an empty
  // trajectory or a rate that is not positive and finite.
  Expected<Trajectory> Resample(double rate_hz) const;

  // Poses at the given times (each interpolated); fails if any time is outside the range.
  Expected<Trajectory> SampleAt(const std::vector<double>& timestamps) const;

 private:
  std::vector<TimedPose> poses_;
};

// TUM RGB-D format: one pose per line, `timestamp tx ty tz qx qy qz qw`; lines starting with
// '#' and blank lines are skipped; fields are separated by spaces, tabs or commas. Errors name
// the file and the line number.
Expected<Trajectory> ReadTum(const std::string& path);
// Writes with 17 significant digits, so ReadTum(WriteTum(x)) reproduces x exactly.
Status WriteTum(const std::string& path, const Trajectory& trajectory);

// KITTI odometry poses: 12 numbers per line, the row-major 3x4 matrix [R | t] that maps points
// of the left camera at frame i into the first camera frame, i.e. world_from_camera.
struct KittiReadOptions {
  // Optional KITTI `times.txt` (one timestamp in seconds per line, same count as poses).
  std::string times_path;
  // Without a times file, frame i gets timestamp start_time_s + i * frame_period_s.
  double frame_period_s = 0.1;
  double start_time_s = 0.0;
};
Expected<Trajectory> ReadKitti(const std::string& poses_path, const KittiReadOptions& options = {});

// EuRoC MAV ground truth (mav0/state_groundtruth_estimate0/data.csv): comma separated,
// `timestamp_ns, px, py, pz, qw, qx, qy, qz, ...` (further columns ignored), '#' header lines
// skipped. The file gives world_from_body (the IMU frame); the result is
// world_from_body * body_from_camera (identity by default: body poses).
struct EurocReadOptions {
  Pose3 body_from_camera = Pose3::Identity();
};
Expected<Trajectory> ReadEuroc(const std::string& path, const EurocReadOptions& options = {});

// First-person head motion inside a room: the head walks at eye height between random
// waypoints (minimum-jerk segments: position, velocity and acceleration are continuous),
// turns towards where it walks, looks around (smooth yaw / pitch oscillations), bobs slightly
// with each step, and sometimes pauses to look around. Deterministic for a given seed. The
// first segment starts at t = 0 with no pause, so there is translation (parallax) from the
// first second. World frame z up (see the header comment).
struct HeadMotionOptions {
  double duration_s = 60.0;
  double rate_hz = 30.0;
  uint64_t seed = 1;
  // Floor rectangle (x, y) of the room; the head keeps wall_clearance_m from its sides.
  Eigen::AlignedBox2d room =
      Eigen::AlignedBox2d(Eigen::Vector2d(-3.0, -2.5), Eigen::Vector2d(3.0, 2.5));
  double wall_clearance_m = 0.6;
  // Footprints (x, y) of furniture; the head's path keeps obstacle_clearance_m from them.
  std::vector<Eigen::AlignedBox2d> obstacles;
  double obstacle_clearance_m = 0.35;
  double eye_height_m = 1.6;
  double walking_speed_mps = 0.9;   // peak speed on a segment
  double min_segment_m = 1.0;       // shortest walk between two waypoints
  double yaw_amplitude_deg = 30.0;  // look-around amplitude around the walking direction
  double pitch_amplitude_deg = 12.0;
  double pitch_bias_deg = -8.0;  // looking slightly down on average
  double roll_amplitude_deg = 2.0;
  double look_frequency_hz = 0.15;  // main look-around frequency
  double pause_probability = 0.35;  // chance of a pause at each waypoint
  double pause_duration_s = 2.0;
  double bob_amplitude_m = 0.015;  // vertical head bob at full walking speed
  double step_frequency_hz = 1.8;

  Status Check() const;
};
Expected<Trajectory> GenerateHeadMotion(const HeadMotionOptions& options);

// The options of DefaultTrajectory(): the DefaultRoomLayout() room and furniture, 60 s at 30 Hz.
HeadMotionOptions DefaultHeadMotionOptions();
// About a minute of head motion at 30 Hz through MakeDefaultScene(), never closer than 0.6 m
// to a wall. Deterministic.
Trajectory DefaultTrajectory();

// The TUM file at `path`, or DefaultTrajectory() when `path` is empty (the command-line tools'
// "--trajectory FILE, else the default walk").
Expected<Trajectory> LoadTrajectoryOrDefault(const std::string& path);

}  // namespace m2s
