// Synthetic scenes with exact ground truth for the optimisation tests: points in a box, cameras
// on a circle looking at its centre, noise-free projections.
#pragma once

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/numeric.h"

namespace m2s::slam::testing {

inline Camera TestCamera() {
  Camera camera;
  camera.width = 640;
  camera.height = 480;
  camera.fx = 500.0;
  camera.fy = 480.0;
  camera.cx = 320.5;
  camera.cy = 239.5;
  return camera;
}

// world_from_camera of a camera at `center` looking at `target` (world z up, camera y down).
using ::m2s::LookAt;

// Uniform points in the cube [-half, half]^3.
inline std::vector<Eigen::Vector3d> RandomPoints(int count, double half, std::mt19937* rng) {
  std::uniform_real_distribution<double> uniform(-half, half);
  std::vector<Eigen::Vector3d> points(count);
  for (Eigen::Vector3d& p : points) p = {uniform(*rng), uniform(*rng), uniform(*rng)};
  return points;
}

// Cameras (world_from_camera) on a horizontal circle around the origin, slightly above it.
inline std::vector<Pose3> CirclePoses(int count, double radius, double arc_rad) {
  std::vector<Pose3> poses;
  for (int i = 0; i < count; ++i) {
    const double angle = arc_rad * i / std::max(1, count - 1);
    poses.push_back(
        LookAt({radius * std::cos(angle), radius * std::sin(angle), 0.5}, Eigen::Vector3d::Zero()));
  }
  return poses;
}

// Rotation by a small random axis-angle of `angle_rad` and translation by `shift` (random dir).
inline Pose3 Perturb(const Pose3& pose, double angle_rad, double shift, std::mt19937* rng) {
  std::normal_distribution<double> normal;
  const Eigen::Vector3d axis =
      Eigen::Vector3d(normal(*rng), normal(*rng), normal(*rng)).normalized();
  const Eigen::Vector3d dir =
      Eigen::Vector3d(normal(*rng), normal(*rng), normal(*rng)).normalized();
  return Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, axis)) * pose.rotation(),
               pose.translation() + shift * dir);
}

// Pose distance: rotation angle (rad) plus translation norm.
inline double PoseError(const Pose3& a, const Pose3& b) {
  return RotationAngle(a.rotation().conjugate() * b.rotation()) +
         (a.translation() - b.translation()).norm();
}

}  // namespace m2s::slam::testing
