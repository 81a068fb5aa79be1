// Host-side preparation of the per-frame camera uniforms shared by the compute shader and the
// occlusion depth pass (see gpu_projector.h, "Numerics").
#pragma once

#include <array>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"

namespace m2s::internal {

struct CameraUniforms {
  std::array<float, 9> rotation;   // camera_from_world rotation, column-major (mat3)
  std::array<float, 3> center_hi;  // camera centre in world = center_hi + center_lo
  std::array<float, 3> center_lo;
  std::array<float, 4> intrinsics;   // fx, fy, cx, cy
  std::array<float, 4> range;        // width, height, near, far
  std::array<float, 16> projection;  // diag(1,-1,1,1) * Camera::GlProjection(), column-major
};

CameraUniforms MakeCameraUniforms(const Pose3& world_from_camera, const Camera& camera);

}  // namespace m2s::internal
