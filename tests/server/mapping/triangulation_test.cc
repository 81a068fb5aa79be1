#include "mapping/triangulation.h"

#include <gtest/gtest.h>

namespace m2s::slam {
namespace {

TEST(Triangulation, RecoversAPointAndAppliesTheChecks) {
  const Camera camera;
  const Eigen::Vector3d point(0.3, -0.2, 4.0);
  const Pose3 a = Pose3::Identity();
  const Pose3 b(Eigen::Quaterniond(Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitY())),
                Eigen::Vector3d(-0.4, 0.0, 0.0));  // camera_from_world
  const std::vector<Pose3> poses = {a, b};
  const std::vector<Eigen::Vector2d> uv = {camera.Project(a * point), camera.Project(b * point)};
  const auto p = TriangulateChecked(camera, TriangulationChecks(), poses, uv);
  ASSERT_TRUE(p.has_value());
  EXPECT_LT((*p - point).norm(), 1e-9);
  EXPECT_NEAR(ParallaxDeg(point, Eigen::Vector3d::Zero(), b.Inverse().translation()),
              ParallaxDeg(*p, Eigen::Vector3d::Zero(), b.Inverse().translation()), 1e-9);

  TriangulationChecks strict;
  strict.min_parallax_deg = 10.0;  // the views are ~5.7 degrees apart
  EXPECT_FALSE(TriangulateChecked(camera, strict, poses, uv).has_value());
  std::vector<Eigen::Vector2d> off = uv;
  off[1].y() += 5.0;  // off the epipolar line
  EXPECT_FALSE(TriangulateChecked(camera, TriangulationChecks(), poses, off).has_value());
  EXPECT_FALSE(TriangulateDlt(camera, {a}, {uv[0]}).has_value());
}

}  // namespace
}  // namespace m2s::slam
