// map.png: the scene mesh with the (aligned) map points and keyframes, seen from a high corner
// of the scene's bounding box. Rendered with MapRenderer on a headless EGL context; without
// EGL, drawn with OpenCV (mesh vertices as grey dots, points red, keyframe centres blue).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/scene.h"
#include "m2s/common/status.h"

namespace m2s::reporting {

struct MapImageInput {
  const Scene* scene = nullptr;
  Camera camera;                        // the frustum shape of the keyframes
  std::vector<Eigen::Vector3d> points;  // world frame (aligned)
  std::vector<Pose3> keyframes;         // world frame (aligned)
  std::optional<Pose3> ground_truth_last;
};

// The viewpoint used for map.png (looking at the scene's centre from a high corner).
Pose3 MapViewpoint(const Scene& scene);
Status WriteMapPng(const std::string& path, const MapImageInput& input);

}  // namespace m2s::reporting
