#include "m2s/gpu/camera_uniforms.h"

namespace m2s {

CameraUniforms MakeCameraUniforms(const Pose3& world_from_camera, const Camera& camera) {
  CameraUniforms u;
  const Eigen::Matrix3f rotation = world_from_camera.RotationMatrix().transpose().cast<float>();
  for (int c = 0; c < 3; ++c) {
    for (int r = 0; r < 3; ++r) u.rotation[3 * c + r] = rotation(r, c);
  }
  const Eigen::Vector3d& center = world_from_camera.translation();
  for (int i = 0; i < 3; ++i) {
    u.center_hi[i] = static_cast<float>(center[i]);
    u.center_lo[i] = static_cast<float>(center[i] - static_cast<double>(u.center_hi[i]));
  }
  u.intrinsics = {static_cast<float>(camera.fx), static_cast<float>(camera.fy),
                  static_cast<float>(camera.cx), static_cast<float>(camera.cy)};
  u.range = {static_cast<float>(camera.width), static_cast<float>(camera.height),
             static_cast<float>(camera.near), static_cast<float>(camera.far)};
  // Row 0 of the framebuffer is the image's top row (v = 0): flip GL's y axis.
  const Eigen::Matrix4d flip_y = Eigen::Vector4d(1.0, -1.0, 1.0, 1.0).asDiagonal();
  const Eigen::Matrix4f projection = (flip_y * camera.GlProjection()).cast<float>();
  for (int c = 0; c < 4; ++c) {
    for (int r = 0; r < 4; ++r) u.projection[4 * c + r] = projection(r, c);
  }
  return u;
}

CameraUniformLocations CameraUniformLocations::Find(GLuint program) {
  CameraUniformLocations where;
  where.rotation_ = glGetUniformLocation(program, "u_rotation");
  where.center_hi_ = glGetUniformLocation(program, "u_center_hi");
  where.center_lo_ = glGetUniformLocation(program, "u_center_lo");
  where.projection_ = glGetUniformLocation(program, "u_projection");
  return where;
}

void CameraUniformLocations::Set(const CameraUniforms& uniforms) const {
  glUniformMatrix3fv(rotation_, 1, GL_FALSE, uniforms.rotation.data());
  glUniform3fv(center_hi_, 1, uniforms.center_hi.data());
  glUniform3fv(center_lo_, 1, uniforms.center_lo.data());
  glUniformMatrix4fv(projection_, 1, GL_FALSE, uniforms.projection.data());
}

}  // namespace m2s
