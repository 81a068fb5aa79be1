// The Ceres cost functors: values against hand-computed residuals, Jacobians against numeric
// differentiation on their manifolds (ceres::GradientChecker).
#include "optimization/cost_functions.h"

#include <array>
#include <memory>
#include <vector>

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include "synthetic_scene.h"

namespace m2s::slam {
namespace {

constexpr double kInvSigma = 0.5;

Pose3 SomeCameraFromWorld() {
  return Pose3(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, -1.0, 0.4).normalized())),
      Eigen::Vector3d(0.1, -0.2, 0.3));
}

// The reprojection residual written out by hand from camera.h's equations.
Eigen::Vector2d HandResidual(const Camera& camera, const Pose3& camera_from_world,
                             const Eigen::Vector3d& point, const Eigen::Vector2d& uv) {
  const Eigen::Vector3d p =
      camera_from_world.RotationMatrix() * point + camera_from_world.translation();
  const double u = camera.fx * p.x() / p.z() + camera.cx;
  const double v = camera.fy * p.y() / p.z() + camera.cy;
  return {(u - uv.x()) * kInvSigma, (v - uv.y()) * kInvSigma};
}

void ExpectGradientsMatch(const ceres::CostFunction& cost,
                          const std::vector<const ceres::Manifold*>& manifolds,
                          const std::vector<const double*>& parameters) {
  ceres::NumericDiffOptions numeric;
  ceres::GradientChecker checker(&cost, &manifolds, numeric);
  ceres::GradientChecker::ProbeResults results;
  EXPECT_TRUE(checker.Probe(parameters.data(), 1e-7, &results)) << results.error_log;
  EXPECT_TRUE(results.return_value);
}

TEST(ReprojectionErrorTest, MatchesHandComputedResidual) {
  const Camera camera = testing::TestCamera();
  const Pose3 pose = SomeCameraFromWorld();
  const Eigen::Vector3d point(0.5, 0.2, 4.0);
  const Eigen::Vector2d uv(330.0, 250.0);
  std::unique_ptr<ceres::CostFunction> cost(ReprojectionError::Create(camera, uv, kInvSigma));
  const auto pose_parameters = PoseToParameters(pose);
  const double* parameters[] = {pose_parameters.data(), point.data()};
  double residuals[2];
  ASSERT_TRUE(cost->Evaluate(parameters, residuals, nullptr));
  const Eigen::Vector2d expected = HandResidual(camera, pose, point, uv);
  EXPECT_NEAR(residuals[0], expected.x(), 1e-9);
  EXPECT_NEAR(residuals[1], expected.y(), 1e-9);
}

TEST(ReprojectionErrorTest, ZeroAtTheTrueProjectionAndFailsBehindTheCamera) {
  const Camera camera = testing::TestCamera();
  const Pose3 pose = SomeCameraFromWorld();
  const Eigen::Vector3d point(0.5, 0.2, 4.0);
  const Eigen::Vector2d uv = camera.Project(pose * point);
  const ReprojectionError error(camera, uv, kInvSigma);
  const auto p = PoseToParameters(pose);
  double residuals[2];
  ASSERT_TRUE(error(p.data(), point.data(), residuals));
  EXPECT_NEAR(residuals[0], 0.0, 1e-9);
  EXPECT_NEAR(residuals[1], 0.0, 1e-9);
  const Eigen::Vector3d behind(0.5, 0.2, -4.0);
  EXPECT_FALSE(error(p.data(), behind.data(), residuals));
}

TEST(ReprojectionErrorTest, GradientCheckerOnPoseManifold) {
  const Camera camera = testing::TestCamera();
  const PoseManifold pose_manifold;
  std::unique_ptr<ceres::CostFunction> cost(
      ReprojectionError::Create(camera, Eigen::Vector2d(300.0, 200.0), kInvSigma));
  const auto pose = PoseToParameters(SomeCameraFromWorld());
  const Eigen::Vector3d point(0.5, 0.2, 4.0);
  ExpectGradientsMatch(*cost, {&pose_manifold, nullptr}, {pose.data(), point.data()});
}

TEST(AnalyticReprojectionErrorTest, MatchesTheAutodiffFunctorAndNumericGradients) {
  const Camera camera = testing::TestCamera();
  const Eigen::Vector2d uv(300.0, 200.0);
  std::unique_ptr<ceres::CostFunction> autodiff(ReprojectionError::Create(camera, uv, kInvSigma));
  const AnalyticReprojectionError analytic(camera, uv, kInvSigma);
  const auto pose = PoseToParameters(SomeCameraFromWorld());
  const Eigen::Vector3d point(0.5, 0.2, 4.0);
  const double* parameters[] = {pose.data(), point.data()};
  double r_auto[2], r_analytic[2], j_auto_pose[14], j_auto_point[6], j_pose[14], j_point[6];
  double* j_auto[] = {j_auto_pose, j_auto_point};
  double* j_analytic[] = {j_pose, j_point};
  ASSERT_TRUE(autodiff->Evaluate(parameters, r_auto, j_auto));
  ASSERT_TRUE(analytic.Evaluate(parameters, r_analytic, j_analytic));
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(r_analytic[i], r_auto[i], 1e-12);
  for (int i = 0; i < 14; ++i) EXPECT_NEAR(j_pose[i], j_auto_pose[i], 1e-9) << i;
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(j_point[i], j_auto_point[i], 1e-9) << i;
  const PoseManifold pose_manifold;
  ExpectGradientsMatch(analytic, {&pose_manifold, nullptr}, {pose.data(), point.data()});
  const Eigen::Vector3d behind(0.5, 0.2, -4.0);
  const double* behind_parameters[] = {pose.data(), behind.data()};
  EXPECT_FALSE(analytic.Evaluate(behind_parameters, r_analytic, nullptr));
}

TEST(PoseOnlyReprojectionErrorTest, MatchesHandComputedResidualAndGradients) {
  const Camera camera = testing::TestCamera();
  const Pose3 pose = SomeCameraFromWorld();
  const Eigen::Vector3d point(-0.7, 0.4, 3.0);
  const Eigen::Vector2d uv(200.0, 260.0);
  std::unique_ptr<ceres::CostFunction> cost(
      PoseOnlyReprojectionError::Create(camera, point, uv, kInvSigma));
  const auto pose_parameters = PoseToParameters(pose);
  const double* parameters[] = {pose_parameters.data()};
  double residuals[2];
  ASSERT_TRUE(cost->Evaluate(parameters, residuals, nullptr));
  const Eigen::Vector2d expected = HandResidual(camera, pose, point, uv);
  EXPECT_NEAR(residuals[0], expected.x(), 1e-9);
  EXPECT_NEAR(residuals[1], expected.y(), 1e-9);

  const PoseManifold pose_manifold;
  ExpectGradientsMatch(*cost, {&pose_manifold}, {pose_parameters.data()});
}

Sim3 SomeSim3(double angle, double scale, const Eigen::Vector3d& t) {
  return Sim3(scale,
              Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d(1, 2, 3).normalized())),
              t);
}

TEST(RelativeSim3ErrorTest, ZeroForAConsistentMeasurement) {
  const Sim3 a = SomeSim3(0.4, 1.3, {1, 2, 3});
  const Sim3 b = SomeSim3(-0.2, 0.8, {-1, 0.5, 2});
  const RelativeSim3Error error(a.Inverse() * b, 2.0);
  const auto pa = Sim3ToParameters(a);
  const auto pb = Sim3ToParameters(b);
  double residuals[7];
  ASSERT_TRUE(error(pa.data(), pb.data(), residuals));
  for (double r : residuals) EXPECT_NEAR(r, 0.0, 1e-12);
}

TEST(RelativeSim3ErrorTest, MatchesHandComputedResidual) {
  // from = identity, to = (scale 2, rotation 0.1 rad about z, t = (1, 0, 0)); measurement:
  // identity. The error is then `to` itself: 2 * vec(q) = (0, 0, 2 sin(0.05)), t, log 2.
  const Sim3 to(2.0, Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ())),
                Eigen::Vector3d(1, 0, 0));
  const double weight = 4.0;
  const RelativeSim3Error error(Sim3::Identity(), weight);
  const auto pa = Sim3ToParameters(Sim3::Identity());
  const auto pb = Sim3ToParameters(to);
  double r[7];
  ASSERT_TRUE(error(pa.data(), pb.data(), r));
  const double w = 2.0;  // sqrt(weight)
  EXPECT_NEAR(r[0], 0.0, 1e-12);
  EXPECT_NEAR(r[1], 0.0, 1e-12);
  EXPECT_NEAR(r[2], w * 2.0 * std::sin(0.05), 1e-12);
  EXPECT_NEAR(r[3], w * 1.0, 1e-12);
  EXPECT_NEAR(r[4], 0.0, 1e-12);
  EXPECT_NEAR(r[5], 0.0, 1e-12);
  EXPECT_NEAR(r[6], w * std::log(2.0), 1e-12);
}

TEST(RelativeSim3ErrorTest, GradientCheckerOnSim3Manifold) {
  const Sim3 a = SomeSim3(0.4, 1.3, {1, 2, 3});
  const Sim3 b = SomeSim3(-0.2, 0.8, {-1, 0.5, 2});
  const Sim3 measured = SomeSim3(0.1, 1.1, {0.3, -0.2, 0.1}) * (a.Inverse() * b);
  std::unique_ptr<ceres::CostFunction> cost(RelativeSim3Error::Create(measured, 1.5));
  const Sim3Manifold manifold;
  const auto pa = Sim3ToParameters(a);
  const auto pb = Sim3ToParameters(b);
  ExpectGradientsMatch(*cost, {&manifold, &manifold}, {pa.data(), pb.data()});
}

TEST(ParameterPackingTest, RoundTrips) {
  const Pose3 pose = SomeCameraFromWorld();
  const auto p = PoseToParameters(pose);
  EXPECT_LT(testing::PoseError(PoseFromParameters(p.data()), pose), 1e-15);
  const Sim3 s = SomeSim3(0.7, 3.0, {4, 5, 6});
  const Sim3 back = Sim3FromParameters(Sim3ToParameters(s).data());
  EXPECT_NEAR(back.scale(), 3.0, 1e-12);
  EXPECT_TRUE(back.Matrix().isApprox(s.Matrix(), 1e-12));
}

}  // namespace
}  // namespace m2s::slam
