#include "m2s/common/camera.h"

#include <filesystem>
#include <fstream>
#include <random>

#include <unistd.h>

#include <gtest/gtest.h>

#include "m2s/common/camera_io.h"
#include "m2s/common/geometry.h"

namespace m2s {
namespace {

// The paper's chain: clip = P V M p, ndc = clip.xy / clip.w, u = (x_ndc/2 + 1/2) w,
// v = (-y_ndc/2 + 1/2) h, with V = GlFromCv * camera_from_world.
Eigen::Vector3d PaperProjection(const Camera& cam, const Pose3& world_from_camera,
                                const Eigen::Vector3d& p_world) {
  const Eigen::Matrix4d view = Camera::GlFromCv() * world_from_camera.Inverse().Matrix();
  const Eigen::Vector4d clip = cam.GlProjection() * view * p_world.homogeneous();
  const double x_ndc = clip.x() / clip.w(), y_ndc = clip.y() / clip.w();
  return {(x_ndc / 2 + 0.5) * cam.width, (-y_ndc / 2 + 0.5) * cam.height, clip.z() / clip.w()};
}

TEST(CameraTest, GlProjectionAgreesWithPinhole) {
  Camera cam;
  cam.width = 1832;
  cam.height = 1920;
  cam.fx = 900;
  cam.fy = 910;
  cam.cx = 930.5;
  cam.cy = 950.25;
  cam.near = 0.1;
  cam.far = 20;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-2, 2);
  const Pose3 world_from_camera(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 1, 0).normalized())),
      Eigen::Vector3d(0.5, -0.2, 1.0));
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d p_cam(u(rng), u(rng), 0.2 + std::abs(u(rng)) * 4);
    const Eigen::Vector3d p_world = world_from_camera * p_cam;
    const Eigen::Vector2d pinhole = cam.Project(p_cam);
    const Eigen::Vector3d paper = PaperProjection(cam, world_from_camera, p_world);
    EXPECT_NEAR(paper.x(), pinhole.x(), 1e-9);
    EXPECT_NEAR(paper.y(), pinhole.y(), 1e-9);
  }
  // Depth range maps to NDC z = -1 at near and +1 at far.
  EXPECT_NEAR(PaperProjection(cam, Pose3(), {0, 0, cam.near}).z(), -1.0, 1e-12);
  EXPECT_NEAR(PaperProjection(cam, Pose3(), {0, 0, cam.far}).z(), 1.0, 1e-12);
}

TEST(CameraTest, PixelConventionCornersAndCentre) {
  const Camera cam = Camera::FromHorizontalFov(640, 480, 90.0);
  EXPECT_NEAR(cam.fx, 320.0, 1e-9);
  EXPECT_DOUBLE_EQ(cam.cx, 320.0);
  // A point on the optical axis lands at (cx, cy): the corner between the four centre pixels.
  EXPECT_TRUE(cam.Project({0, 0, 2}).isApprox(Eigen::Vector2d(320, 240)));
  // 45 degrees to the right lands on the right image edge, which is outside [0, width).
  const Eigen::Vector2d edge = cam.Project({1, 0, 1});
  EXPECT_NEAR(edge.x(), 640.0, 1e-9);
  EXPECT_FALSE(cam.InImage(edge.x(), edge.y()));
  EXPECT_TRUE(cam.InImage(0.0, 0.0));
  EXPECT_TRUE(cam.InImage(639.999, 479.999));
  EXPECT_TRUE(
      cam.Unproject(cam.Project({0.3, -0.4, 2.5}), 2.5).isApprox(Eigen::Vector3d(0.3, -0.4, 2.5)));
}

TEST(CameraTest, FromGlProjectionInvertsGlProjection) {
  Camera cam;
  cam.width = 800;
  cam.height = 600;
  cam.fx = 610;
  cam.fy = 605;
  cam.cx = 401.5;
  cam.cy = 297.0;
  cam.near = 0.05;
  cam.far = 30;
  const Camera back = Camera::FromGlProjection(cam.GlProjection(), cam.width, cam.height);
  EXPECT_NEAR(back.fx, cam.fx, 1e-9);
  EXPECT_NEAR(back.fy, cam.fy, 1e-9);
  EXPECT_NEAR(back.cx, cam.cx, 1e-9);
  EXPECT_NEAR(back.cy, cam.cy, 1e-9);
  EXPECT_NEAR(back.near, cam.near, 1e-9);
  EXPECT_NEAR(back.far, cam.far, 1e-6);
}

TEST(CameraTest, CheckRejectsBadCameras) {
  Status why;
  EXPECT_TRUE((why = Camera().Check()));
  Camera c;
  c.width = 0;
  EXPECT_FALSE((why = c.Check()));
  EXPECT_FALSE(why.message().empty());
  c = Camera();
  c.fx = NAN;
  EXPECT_FALSE((why = c.Check()));
  c = Camera();
  c.near = 2;
  c.far = 1;
  EXPECT_FALSE((why = c.Check()));
  c = Camera();
  c.near = 0;
  EXPECT_FALSE((why = c.Check()));
}

TEST(CameraIoTest, ReadsCameraJsonAndRejectsBadFiles) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("m2s_camera_io_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "ok.json")
      << R"({"width": 800, "height": 600, "fx": 500, "fy": 501, "cx": 400.5, "cy": 299.5,
             "near": 0.1, "far": 20})";
  const Expected<Camera> ok = ReadCameraJson((dir / "ok.json").string());
  ASSERT_TRUE(ok.ok()) << ok.error();
  EXPECT_EQ(ok->width, 800);
  EXPECT_DOUBLE_EQ(ok->fy, 501.0);
  EXPECT_DOUBLE_EQ(ok->cx, 400.5);
  EXPECT_DOUBLE_EQ(ok->far, 20.0);
  std::ofstream(dir / "missing_field.json") << R"({"width": 800, "height": 600})";
  std::ofstream(dir / "garbage.json") << "not json";
  std::ofstream(dir / "bad_range.json")
      << R"({"width": 800, "height": 600, "fx": 500, "fy": 500, "cx": 1, "cy": 1, "near": 5, "far": 1})";
  for (const char* name : {"missing_field.json", "garbage.json", "bad_range.json", "absent.json"}) {
    const Expected<Camera> bad = ReadCameraJson((dir / name).string());
    EXPECT_FALSE(bad.ok()) << name;
    EXPECT_NE(bad.error().find(name), std::string::npos) << bad.error();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace m2s
