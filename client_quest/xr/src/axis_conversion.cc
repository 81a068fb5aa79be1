#include "m2s/xr/axis_conversion.h"

#include <cmath>

namespace m2s::xr {

Pose3 CameraXrFromCameraCv() {
  // diag(1, -1, -1): quaternion (w, x, y, z) = (0, 1, 0, 0).
  return Pose3(Eigen::Quaterniond(0.0, 1.0, 0.0, 0.0), Eigen::Vector3d::Zero());
}

Pose3 WorldFromCameraFromXrView(const Pose3& world_from_view_xr) {
  return world_from_view_xr * CameraXrFromCameraCv();
}

Pose3 XrViewFromWorldFromCamera(const Pose3& world_from_camera) {
  return world_from_camera * CameraXrFromCameraCv().Inverse();
}

Pose3 PoseFromXr(const Eigen::Vector4d& orientation_xyzw, const Eigen::Vector3d& position) {
  return Pose3(Eigen::Quaterniond(orientation_xyzw.w(), orientation_xyzw.x(), orientation_xyzw.y(),
                                  orientation_xyzw.z()),
               position);
}

Camera CameraFromXrFov(const FieldOfView& fov, int width, int height, double near, double far) {
  const double tl = std::tan(fov.angle_left), tr = std::tan(fov.angle_right);
  const double tu = std::tan(fov.angle_up), td = std::tan(fov.angle_down);
  Camera camera;
  camera.width = width;
  camera.height = height;
  camera.fx = width / (tr - tl);
  camera.cx = -tl * camera.fx;
  camera.fy = height / (tu - td);
  camera.cy = tu * camera.fy;
  camera.near = near;
  camera.far = far;
  return camera;
}

Eigen::Matrix4d GlProjectionFromXrFov(const FieldOfView& fov, double near, double far) {
  const double tl = std::tan(fov.angle_left), tr = std::tan(fov.angle_right);
  const double tu = std::tan(fov.angle_up), td = std::tan(fov.angle_down);
  const double w = tr - tl, h = tu - td;
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();
  p(0, 0) = 2.0 / w;
  p(0, 2) = (tr + tl) / w;
  p(1, 1) = 2.0 / h;
  p(1, 2) = (tu + td) / h;
  p(2, 2) = -(far + near) / (far - near);
  p(2, 3) = -2.0 * far * near / (far - near);
  p(3, 2) = -1.0;
  return p;
}

Eigen::Matrix4d GlViewFromXrPose(const Pose3& world_from_eye_xr) {
  return world_from_eye_xr.Inverse().Matrix();
}

}  // namespace m2s::xr
