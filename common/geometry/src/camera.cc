#include "m2s/common/camera.h"

#include <cmath>

namespace m2s {

Camera Camera::FromHorizontalFov(int width, int height, double hfov_deg, double near, double far) {
  Camera c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = 0.5 * width / std::tan(0.5 * hfov_deg * M_PI / 180.0);
  c.cx = 0.5 * width;
  c.cy = 0.5 * height;
  c.near = near;
  c.far = far;
  return c;
}

Status Camera::Check() const {
  if (width <= 0 || height <= 0) return Status::Error("camera width and height must be positive");
  if (width > 65536 || height > 65536)
    return Status::Error("camera width and height must be <= 65536");
  if (!std::isfinite(fx) || !std::isfinite(fy) || fx <= 0 || fy <= 0)
    return Status::Error("camera fx and fy must be finite and positive");
  if (!std::isfinite(cx) || !std::isfinite(cy))
    return Status::Error("camera cx and cy must be finite");
  if (!std::isfinite(near) || !std::isfinite(far) || near <= 0 || far <= near)
    return Status::Error("camera depth range must satisfy 0 < near < far");
  return Status::Ok();
}

Eigen::Matrix3d Camera::K() const {
  Eigen::Matrix3d k;
  k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return k;
}

Eigen::Matrix4d Camera::GlProjection() const {
  const double w = width, h = height;
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();
  p(0, 0) = 2.0 * fx / w;
  p(0, 2) = 1.0 - 2.0 * cx / w;
  p(1, 1) = 2.0 * fy / h;
  p(1, 2) = 2.0 * cy / h - 1.0;
  p(2, 2) = -(far + near) / (far - near);
  p(2, 3) = -2.0 * far * near / (far - near);
  p(3, 2) = -1.0;
  return p;
}

Camera Camera::FromGlProjection(const Eigen::Matrix4d& p, int width, int height) {
  Camera c;
  c.width = width;
  c.height = height;
  c.fx = p(0, 0) * width / 2.0;
  c.fy = p(1, 1) * height / 2.0;
  c.cx = (1.0 - p(0, 2)) * width / 2.0;
  c.cy = (p(1, 2) + 1.0) * height / 2.0;
  const double a = p(2, 2), b = p(2, 3);
  c.near = b / (a - 1.0);
  c.far = b / (a + 1.0);
  return c;
}

Eigen::Matrix4d Camera::GlFromCv() { return Eigen::Vector4d(1.0, -1.0, -1.0, 1.0).asDiagonal(); }

}  // namespace m2s
