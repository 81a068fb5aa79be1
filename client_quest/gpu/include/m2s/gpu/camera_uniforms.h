// The per-frame camera uniforms of the camera-centred shaders: the GpuProjector's compute
// shader, its occlusion depth pass and SceneRenderer. Positions stay in world coordinates on
// the GPU; the camera centre goes up as two floats (hi + lo) and each vertex is moved to the
// camera before rotating, so float precision is that of the camera-relative position (see
// gpu_projector.h, "Numerics").
//
// A shader declares the uniforms and helpers with kCameraGlsl; the host finds the
// locations once and uploads a frame's values:
//
//   const std::string vs = std::string("#version 310 es\n") + kCameraGlsl + body;
//   ... compile and link `program` ...
//   const CameraUniformLocations where = CameraUniformLocations::Find(program.id());
//   glUseProgram(program.id());
//   where.Set(MakeCameraUniforms(world_from_camera, camera));
//
// Find and Set need a current GLES context; Set needs the program in use. A uniform a program
// does not declare (the compute shader has no u_projection) has location -1, which GL ignores.
#pragma once

#include <GLES3/gl32.h>

#include <array>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"

namespace m2s {

struct CameraUniforms {
  std::array<float, 9> rotation;   // camera_from_world rotation, column-major (mat3)
  std::array<float, 3> center_hi;  // camera centre in world = center_hi + center_lo
  std::array<float, 3> center_lo;
  std::array<float, 4> intrinsics;   // fx, fy, cx, cy
  std::array<float, 4> range;        // width, height, near, far
  std::array<float, 16> projection;  // diag(1,-1,1,1) * Camera::GlProjection(), column-major
};

CameraUniforms MakeCameraUniforms(const Pose3& world_from_camera, const Camera& camera);

// GLSL (ES 3.10, any stage) declarations of u_rotation, u_center_hi, u_center_lo and u_projection,
// and
//   vec3 CameraFromWorld(vec3 p): p in camera coordinates (x right, y down, z forward);
//   vec4 ClipFromCamera(vec3 x): GL clip coordinates, row 0 of the target = image top.
inline constexpr char kCameraGlsl[] = R"(
uniform mat3 u_rotation;   // camera_from_world
uniform vec3 u_center_hi;  // camera centre in world, split in two floats
uniform vec3 u_center_lo;
uniform mat4 u_projection; // y-flipped Camera::GlProjection()
vec3 CameraFromWorld(vec3 p) { return u_rotation * ((p - u_center_hi) - u_center_lo); }
// The paper's chain clip = P V p with V = GlFromCv * camera_from_world, camera-centred.
vec4 ClipFromCamera(vec3 x) { return u_projection * vec4(x.x, -x.y, -x.z, 1.0); }
)";

// The locations of kCameraGlsl's uniforms in one linked program.
class CameraUniformLocations {
 public:
  static CameraUniformLocations Find(GLuint program);
  // Uploads rotation, centre and projection to the program in use.
  void Set(const CameraUniforms& uniforms) const;

 private:
  GLint rotation_ = -1, center_hi_ = -1, center_lo_ = -1, projection_ = -1;
};

}  // namespace m2s
