// Pinhole camera with a depth range, and its OpenGL projection matrix.
//
// Conventions (docs/ARCHITECTURE.md):
//  * Camera axes are OpenCV / TUM: x right, y down, z forward.
//  * u = fx X/Z + cx, v = fy Y/Z + cy; pixel (0,0) spans [0,1) x [0,1), so the image is
//    u in [0, width), v in [0, height) and the centre of pixel (i, j) is (i + 0.5, j + 0.5).
//  * A point is visible when near <= Z <= far and its (u, v) is inside the image.
//  * OpenGL (the paper's equations): clip = P V M p, ndc = clip.xy / clip.w,
//    u = (x_ndc / 2 + 1/2) width, v = (-y_ndc / 2 + 1/2) height, where
//    V = GlFromCv() * camera_from_world and GlFromCv() = diag(1, -1, -1, 1) turns our camera
//    axes into OpenGL's (y up, looking down -z). GlProjection() is chosen so both agree exactly.
#pragma once

#include <string>

#include <Eigen/Core>

#include "m2s/common/status.h"

namespace m2s {

struct Camera {
  int width = 640;
  int height = 480;
  double fx = 500.0;
  double fy = 500.0;
  double cx = 320.0;
  double cy = 240.0;
  double near = 0.05;  // metres
  double far = 50.0;   // metres

  // A camera with square pixels, the principal point at the image centre and the given
  // horizontal field of view in degrees.
  static Camera FromHorizontalFov(int width, int height, double hfov_deg, double near = 0.05,
                                  double far = 50.0);

  // False (with the reason) when any field is out of range or not finite.
  Status Check() const;

  Eigen::Vector2d Project(const Eigen::Vector3d& p_camera) const {
    return {fx * p_camera.x() / p_camera.z() + cx, fy * p_camera.y() / p_camera.z() + cy};
  }
  // The camera-frame point at depth z along the ray of pixel (u, v).
  Eigen::Vector3d Unproject(const Eigen::Vector2d& uv, double z) const {
    return {(uv.x() - cx) / fx * z, (uv.y() - cy) / fy * z, z};
  }
  bool InImage(double u, double v) const { return u >= 0 && v >= 0 && u < width && v < height; }
  Eigen::Matrix3d K() const;

  // OpenGL projection matrix P for this camera (see the header comment).
  Eigen::Matrix4d GlProjection() const;
  // Recovers the camera from P and the image size (inverse of GlProjection()).
  static Camera FromGlProjection(const Eigen::Matrix4d& projection, int width, int height);
  // diag(1, -1, -1, 1): OpenCV camera axes -> OpenGL eye axes.
  static Eigen::Matrix4d GlFromCv();
};

}  // namespace m2s
