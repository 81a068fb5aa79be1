// PoseCentreCovariance with uncertain points (server/tracking/motion_uncertainty.h) against an
// independent computation: the joint problem of the pose and every point, each point held to
// its map position by a prior of its deviation, differentiated numerically and inverted whole.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Dense>

#include "tracking/motion_uncertainty.h"

namespace m2s::slam {
namespace {

// The centre's largest standard deviation from the joint information of [rotation vector,
// centre, point offsets]: residuals are the reprojections over `pixel_sigma` and the points'
// offsets over their deviations `point_sigmas`.
double JointCentreSigma(const Camera& camera, double pixel_sigma, const Eigen::Matrix3d& rotation,
                        const Eigen::Vector3d& centre, const std::vector<Eigen::Vector3d>& points,
                        const std::vector<double>& point_sigmas) {
  const int n = static_cast<int>(points.size());
  const int dim = 6 + 3 * n;
  auto residuals = [&](const Eigen::VectorXd& x) {
    const Eigen::Vector3d w = x.head<3>();
    const Eigen::Matrix3d r =
        (w.norm() > 0 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()
                      : Eigen::Matrix3d::Identity()) *
        rotation;
    Eigen::VectorXd res(5 * n);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d offset = x.segment<3>(6 + 3 * i);
      res.segment<2>(2 * i) =
          camera.Project(r * (points[i] + offset - centre - x.segment<3>(3))) / pixel_sigma;
      res.segment<3>(2 * n + 3 * i) = offset / point_sigmas[i];
    }
    return res;
  };
  Eigen::MatrixXd jacobian(5 * n, dim);
  const double h = 1e-6;
  for (int k = 0; k < dim; ++k) {
    Eigen::VectorXd plus = Eigen::VectorXd::Zero(dim), minus = plus;
    plus(k) = h;
    minus(k) = -h;
    jacobian.col(k) = (residuals(plus) - residuals(minus)) / (2.0 * h);
  }
  const Eigen::MatrixXd covariance = (jacobian.transpose() * jacobian).inverse();
  return std::sqrt(
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(Eigen::Matrix3d(covariance.block<3, 3>(3, 3)))
          .eigenvalues()
          .maxCoeff());
}

TEST(PoseCentreCovariance, UncertainPointsMatchTheJointProblemWithPointPriors) {
  const Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<Eigen::Vector3d> points;
  std::vector<double> sigmas;
  for (int i = 0; i < 15; ++i) {
    const double z = 2.5 + 1.5 * unit(rng);
    points.emplace_back(0.6 * unit(rng) * z, 0.45 * unit(rng) * z, z);
    sigmas.push_back(z * (i % 3 == 0 ? 0.002 : 0.03 + 0.02 * unit(rng)));  // 0.2 %, 1-5 % of depth
  }
  const Eigen::Vector3d centre(0.1, -0.2, 0.3);
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(0.15, Eigen::Vector3d(0.2, 1.0, -0.1).normalized()).toRotationMatrix();
  const Pose3 camera_from_world(Eigen::Quaterniond(rotation), -(rotation * centre));
  const double pixel_sigma = 0.5;
  const double with_points =
      PoseCentreSigma(camera, pixel_sigma, camera_from_world, points, sigmas);
  const double reference = JointCentreSigma(camera, pixel_sigma, rotation, centre, points, sigmas);
  EXPECT_NEAR(with_points, reference, 1e-4 * reference);
  // Exact points fix the centre several times better than these (the pixels alone).
  const double exact_points = PoseCentreSigma(camera, pixel_sigma, camera_from_world, points);
  EXPECT_LT(exact_points, 0.5 * with_points);
  // Zero deviations are exact points.
  EXPECT_DOUBLE_EQ(PoseCentreSigma(camera, pixel_sigma, camera_from_world, points,
                                   std::vector<double>(points.size(), 0.0)),
                   exact_points);
}

}  // namespace
}  // namespace m2s::slam
