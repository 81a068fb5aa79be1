// Test helpers for the mapping tests: exact views of a point scene from a circle of camera
// poses in the default room (world z up, cameras looking outwards, OpenCV axes).
#pragma once

#include <cmath>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/scene.h"
#include "tracking/frame_validation.h"

namespace m2s::slam::testing {

// A camera on the circle of radius 0.8 m at height 1.5 m, at angle theta, looking outwards.
inline Pose3 CirclePose(double theta) {
  const Eigen::Vector3d forward(std::cos(theta), std::sin(theta), 0.0), down(0, 0, -1);
  Eigen::Matrix3d r;
  r.col(0) = down.cross(forward);
  r.col(1) = down;
  r.col(2) = forward;
  return Pose3(r, Eigen::Vector3d(0.8 * std::cos(theta), 0.8 * std::sin(theta), 1.5));
}

// The scene's vertices in front of the camera (20 cm or more) and inside its image, by id.
inline SortedFeatures ObservePoints(const Scene& scene, const Camera& camera,
                                    const Pose3& world_from_camera) {
  SortedFeatures f;
  const Pose3 camera_from_world = world_from_camera.Inverse();
  for (size_t v = 0; v < scene.positions.size(); ++v) {
    const Eigen::Vector3d pc = camera_from_world * scene.positions[v].cast<double>();
    if (pc.z() < 0.2) continue;
    const Eigen::Vector2d uv = camera.Project(pc);
    if (!camera.InImage(uv.x(), uv.y())) continue;
    f.ids.push_back(static_cast<VertexId>(v));
    f.uvs.push_back(uv);
  }
  return f;
}

}  // namespace m2s::slam::testing
