// OpenXR -> project conventions against hand-computed cases (see axis_conversion.h).
#include "m2s/xr/axis_conversion.h"

#include <cmath>

#include <gtest/gtest.h>

namespace m2s::xr {
namespace {

TEST(AxisConversion, IdentityViewLooksDownMinusZWithYDown) {
  const Pose3 camera = WorldFromCameraFromXrView(Pose3::Identity());
  Eigen::Matrix3d expected;
  expected << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  EXPECT_TRUE(camera.RotationMatrix().isApprox(expected, 1e-12));
  EXPECT_TRUE(camera.translation().isZero());
  // A world point 2 m in front of the headset (OpenXR: -z) is on the camera's optical axis.
  const Eigen::Vector3d p_camera = camera.Inverse() * Eigen::Vector3d(0, 0, -2);
  EXPECT_TRUE(p_camera.isApprox(Eigen::Vector3d(0, 0, 2), 1e-12));
  // A point above the headset (OpenXR +y) is above the image centre (our -y).
  EXPECT_LT((camera.Inverse() * Eigen::Vector3d(0, 1, -2)).y(), 0);
}

TEST(AxisConversion, HeadTurnedLeftNinetyDegrees) {
  // Yaw of +90 degrees about OpenXR's up axis: the headset now looks along world -x.
  const Pose3 view(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY())),
                   Eigen::Vector3d(1, 1.6, 2));
  const Pose3 camera = WorldFromCameraFromXrView(view);
  // Columns: camera right, down, forward in world coordinates (computed by hand).
  Eigen::Matrix3d expected;
  expected.col(0) = Eigen::Vector3d(0, 0, -1);
  expected.col(1) = Eigen::Vector3d(0, -1, 0);
  expected.col(2) = Eigen::Vector3d(-1, 0, 0);
  EXPECT_TRUE(camera.RotationMatrix().isApprox(expected, 1e-12));
  EXPECT_TRUE(camera.translation().isApprox(Eigen::Vector3d(1, 1.6, 2)));
}

TEST(AxisConversion, PitchUpAndRoundTrip) {
  // Pitch up by 30 degrees (about OpenXR x): forward tilts towards +y.
  const Pose3 view(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitX())),
                   Eigen::Vector3d(0.1, 0.2, 0.3));
  const Pose3 camera = WorldFromCameraFromXrView(view);
  const Eigen::Vector3d forward = camera.rotation() * Eigen::Vector3d::UnitZ();
  EXPECT_TRUE(forward.isApprox(Eigen::Vector3d(0, 0.5, -std::sqrt(3) / 2), 1e-12));
  const Pose3 back = XrViewFromWorldFromCamera(camera);
  EXPECT_NEAR(std::abs(back.rotation().dot(view.rotation())), 1.0, 1e-12);
  EXPECT_TRUE(back.translation().isApprox(view.translation()));
}

TEST(AxisConversion, PoseFromXrFields) {
  const double s = std::sqrt(0.5);
  const Pose3 pose = PoseFromXr(Eigen::Vector4d(0, s, 0, s), Eigen::Vector3d(1, 2, 3));
  EXPECT_TRUE((pose.rotation() * Eigen::Vector3d::UnitX()).isApprox(-Eigen::Vector3d::UnitZ()));
  EXPECT_TRUE(pose.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
}

TEST(AxisConversion, CameraFromSymmetricAndAsymmetricFov) {
  FieldOfView fov{-M_PI / 4, M_PI / 4, std::atan(0.75), -std::atan(0.75)};
  Camera c = CameraFromXrFov(fov, 640, 480, 0.1, 20.0);
  EXPECT_NEAR(c.fx, 320.0, 1e-9);
  EXPECT_NEAR(c.fy, 320.0, 1e-9);
  EXPECT_NEAR(c.cx, 320.0, 1e-9);
  EXPECT_NEAR(c.cy, 240.0, 1e-9);
  // Asymmetric: tan(left) = -1, tan(right) = 0.5, tan(up) = 0.25, tan(down) = -0.5.
  fov = {-M_PI / 4, std::atan(0.5), std::atan(0.25), -std::atan(0.5)};
  c = CameraFromXrFov(fov, 300, 150, 0.1, 20.0);
  EXPECT_NEAR(c.fx, 200.0, 1e-9);  // 300 / 1.5
  EXPECT_NEAR(c.cx, 200.0, 1e-9);  // 1 * 200
  EXPECT_NEAR(c.fy, 200.0, 1e-9);  // 150 / 0.75
  EXPECT_NEAR(c.cy, 50.0, 1e-9);   // 0.25 * 200
  // The ray through the top-left fov corner lands on pixel (0, 0).
  const Eigen::Vector3d corner_xr(std::tan(fov.angle_left), std::tan(fov.angle_up), -1);
  const Eigen::Vector3d corner_cv = CameraXrFromCameraCv().Inverse() * corner_xr;
  EXPECT_TRUE(c.Project(corner_cv).isZero(1e-9));
}

TEST(AxisConversion, GlProjectionAgreesWithTheCamera) {
  const FieldOfView fov{-0.9, 0.7, 0.6, -0.8};
  const Camera camera = CameraFromXrFov(fov, 400, 300, 0.1, 30.0);
  const Eigen::Matrix4d p = GlProjectionFromXrFov(fov, 0.1, 30.0);
  EXPECT_TRUE(p.isApprox(camera.GlProjection(), 1e-9)) << p << "\n\n" << camera.GlProjection();
  // World point -> GL clip -> pixel, against the pinhole projection of the camera.
  const Pose3 world_from_eye(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(0.5, -0.2, 1.0));
  const Eigen::Vector3d world_point = world_from_eye * Eigen::Vector3d(0.2, -0.1, -2.0);
  const Eigen::Vector4d clip = p * GlViewFromXrPose(world_from_eye) * world_point.homogeneous();
  const Eigen::Vector2d ndc = clip.head<2>() / clip.w();
  const Eigen::Vector2d pixel((ndc.x() / 2 + 0.5) * 400, (-ndc.y() / 2 + 0.5) * 300);
  const Pose3 world_from_camera = WorldFromCameraFromXrView(world_from_eye);
  const Eigen::Vector2d expected = camera.Project(world_from_camera.Inverse() * world_point);
  EXPECT_TRUE(pixel.isApprox(expected, 1e-9))
      << pixel.transpose() << " vs " << expected.transpose();
}

}  // namespace
}  // namespace m2s::xr
