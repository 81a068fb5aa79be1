#include "mapping/triangulation.h"

#include <random>

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

namespace m2s::slam {
namespace {

TEST(Triangulation, HasParallaxAgreesWithTheExhaustivePairwiseMaximum) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int decided_by_bound = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const Eigen::Vector3d point(u(rng), u(rng), 3.0 + u(rng));
    std::vector<Eigen::Vector3d> centers;
    const int n = 2 + trial % 30;
    const double spread = 0.002 * (1 + trial % 50);  // from far under to far over 1 degree
    for (int i = 0; i < n; ++i) centers.emplace_back(spread * u(rng), spread * u(rng), 0.0);
    const double reference = MaxParallaxDeg(point, centers);
    EXPECT_EQ(HasParallax(point, centers, 1.0), reference >= 1.0) << "trial " << trial;
    decided_by_bound += reference >= 0.5 && reference < 2.0 ? 0 : 1;
  }
  EXPECT_GT(decided_by_bound, 100);  // both quick exits were exercised
  EXPECT_FALSE(HasParallax(Eigen::Vector3d(0, 0, 1), {Eigen::Vector3d::Zero()}, 1.0));
}

}  // namespace
}  // namespace m2s::slam
