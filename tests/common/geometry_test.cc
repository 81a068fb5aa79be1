#include "m2s/common/geometry.h"

#include <random>

#include <gtest/gtest.h>

#include "m2s/common/alignment.h"

namespace m2s {
namespace {

Pose3 RandomPose(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Matrix<double, 6, 1> xi;
  for (int i = 0; i < 6; ++i) xi(i) = n(rng);
  return Pose3::Exp(xi);
}

TEST(Pose3Test, InverseAndCompositionMatchMatrices) {
  std::mt19937 rng(1);
  for (int i = 0; i < 50; ++i) {
    const Pose3 a = RandomPose(rng), b = RandomPose(rng);
    EXPECT_TRUE((a * b).Matrix().isApprox(a.Matrix() * b.Matrix(), 1e-12));
    EXPECT_TRUE(a.Inverse().Matrix().isApprox(a.Matrix().inverse(), 1e-12));
    const Eigen::Vector3d p(0.3, -1.2, 2.0);
    const Eigen::Vector3d expected = (a.Matrix() * p.homogeneous()).head<3>();
    EXPECT_TRUE((a * p).isApprox(expected, 1e-12));
  }
}

TEST(Pose3Test, ExpLogRoundTrip) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  for (int i = 0; i < 100; ++i) {
    Eigen::Matrix<double, 6, 1> xi;
    for (int k = 0; k < 6; ++k) xi(k) = u(rng);
    const Eigen::Matrix<double, 6, 1> back = Pose3::Exp(xi).Log();
    EXPECT_LT((back - xi).norm(), 1e-9) << "xi=" << xi.transpose();
  }
  // Small angles and pure translation.
  Eigen::Matrix<double, 6, 1> tiny;
  tiny << 1, 2, 3, 1e-10, -2e-10, 0;
  EXPECT_LT((Pose3::Exp(tiny).Log() - tiny).norm(), 1e-9);
}

TEST(Pose3Test, ExpOfPureRotationMatchesAngleAxis) {
  Eigen::Matrix<double, 6, 1> xi;
  xi << 0, 0, 0, 0, 0, M_PI / 2;
  const Pose3 p = Pose3::Exp(xi);
  EXPECT_TRUE((p * Eigen::Vector3d(1, 0, 0)).isApprox(Eigen::Vector3d(0, 1, 0), 1e-12));
  EXPECT_NEAR(RotationAngle(p.rotation()), M_PI / 2, 1e-12);
}

TEST(Sim3Test, InverseCompositionAndPoseTransform) {
  const Sim3 s(2.5,
               Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())),
               Eigen::Vector3d(1, -2, 0.5));
  const Sim3 id = s * s.Inverse();
  EXPECT_NEAR(id.scale(), 1.0, 1e-12);
  EXPECT_TRUE(id.translation().isZero(1e-12));
  EXPECT_TRUE(s.Matrix().inverse().isApprox(s.Inverse().Matrix(), 1e-12));
  // A camera's position maps like a point; its orientation is only rotated.
  const Pose3 cam(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY())),
                  Eigen::Vector3d(0.2, 0.1, -1));
  const Pose3 moved = s.TransformPose(cam);
  EXPECT_TRUE(moved.translation().isApprox(s * cam.translation(), 1e-12));
  EXPECT_TRUE(moved.rotation().isApprox(s.rotation() * cam.rotation(), 1e-12));
}

TEST(InterpolateTest, EndpointsAndMidpoint) {
  const Pose3 a(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 0));
  const Pose3 b(Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitZ())),
                Eigen::Vector3d(2, 4, 6));
  EXPECT_TRUE(Interpolate(a, b, 0.0).Matrix().isApprox(a.Matrix(), 1e-12));
  EXPECT_TRUE(Interpolate(a, b, 1.0).Matrix().isApprox(b.Matrix(), 1e-12));
  const Pose3 mid = Interpolate(a, b, 0.5);
  EXPECT_TRUE(mid.translation().isApprox(Eigen::Vector3d(1, 2, 3), 1e-12));
  EXPECT_NEAR(RotationAngle(mid.rotation()), 0.5, 1e-12);
}

TEST(AlignPointsTest, RecoversKnownSimilarity) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-5, 5);
  const Sim3 truth(
      0.4, Eigen::Quaterniond(Eigen::AngleAxisd(-2.0, Eigen::Vector3d(0.2, 1, -0.3).normalized())),
      Eigen::Vector3d(3, -1, 7));
  std::vector<Eigen::Vector3d> src, dst;
  for (int i = 0; i < 40; ++i) {
    src.emplace_back(u(rng), u(rng), u(rng));
    dst.push_back(truth * src.back());
  }
  const auto est = AlignPoints(src, dst, /*with_scale=*/true);
  ASSERT_TRUE(est.has_value());
  EXPECT_NEAR(est->scale(), 0.4, 1e-9);
  EXPECT_TRUE(est->Matrix().isApprox(truth.Matrix(), 1e-9));
  const auto rigid = AlignPoints(src, dst, /*with_scale=*/false);
  ASSERT_TRUE(rigid.has_value());
  EXPECT_DOUBLE_EQ(rigid->scale(), 1.0);
  EXPECT_TRUE(rigid->rotation().isApprox(truth.rotation(), 1e-9));
}

TEST(AlignPointsTest, RejectsDegenerateInput) {
  std::vector<Eigen::Vector3d> line = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  EXPECT_FALSE(AlignPoints(line, line, true).has_value());
  std::vector<Eigen::Vector3d> two = {{0, 0, 0}, {1, 0, 0}};
  EXPECT_FALSE(AlignPoints(two, two, true).has_value());
  std::vector<Eigen::Vector3d> a = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  std::vector<Eigen::Vector3d> b = {{0, 0, 0}, {1, 0, 0}, {0, NAN, 0}};
  EXPECT_FALSE(AlignPoints(a, b, true).has_value());
  EXPECT_FALSE(AlignPoints(a, two, true).has_value());
}

}  // namespace
}  // namespace m2s
