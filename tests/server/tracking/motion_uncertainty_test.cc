// The motion and pose uncertainties the initialiser and the tracker gate on
// (server/tracking/motion_uncertainty.h) against independent computations: the Jacobian of
// every residual by central differences and the blocks of (J^T J)^-1. PoseCentreCovariance with
// uncertain points against the joint problem of the pose and every point, each point held to
// its map position by a prior of its deviation.
#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Dense>

#include "tracking/motion_uncertainty.h"

namespace m2s::slam {
namespace {

// Uniform numbers in [lo, hi) from a seeded generator.
class Uniform {
 public:
  explicit Uniform(unsigned seed) : rng_(seed) {}
  double operator()(double lo, double hi) {
    return std::uniform_real_distribution<double>(lo, hi)(rng_);
  }

 private:
  std::mt19937 rng_;
};

// (J^T J)^-1 of `residuals` (in units of the noise) at zero, the Jacobian by central differences.
Eigen::MatrixXd NumericalCovariance(
    const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& residuals, int num_params) {
  const Eigen::VectorXd at_zero = residuals(Eigen::VectorXd::Zero(num_params));
  Eigen::MatrixXd jacobian(at_zero.size(), num_params);
  const double h = 1e-6;
  for (int k = 0; k < num_params; ++k) {
    Eigen::VectorXd plus = Eigen::VectorXd::Zero(num_params), minus = plus;
    plus(k) = h;
    minus(k) = -h;
    jacobian.col(k) = (residuals(plus) - residuals(minus)) / (2.0 * h);
  }
  return (jacobian.transpose() * jacobian).inverse();
}

// The rotation by rotation vector `w`.
Eigen::Matrix3d Turn(const Eigen::Vector3d& w) {
  return w.norm() > 0 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()
                      : Eigen::Matrix3d::Identity();
}

// A pose turned by `angle` about `axis` (any length) and moved by `t`.
Pose3 Turned(double angle, const Eigen::Vector3d& axis, const Eigen::Vector3d& t) {
  return Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(angle, axis.normalized())), t);
}

// The square root of the largest eigenvalue of a covariance block.
double LargestSigma(const Eigen::MatrixXd& block) {
  return std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(block).eigenvalues().maxCoeff());
}

// The centre's largest standard deviation from the joint information of [rotation vector,
// centre, point offsets]: residuals are the reprojections over `pixel_sigma` and the points'
// offsets over their deviations `point_sigmas`.
double JointCentreSigma(const Camera& camera, double pixel_sigma, const Eigen::Matrix3d& rotation,
                        const Eigen::Vector3d& centre, const std::vector<Eigen::Vector3d>& points,
                        const std::vector<double>& point_sigmas) {
  const int n = static_cast<int>(points.size());
  const int dim = 6 + 3 * n;
  auto residuals = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd {
    const Eigen::Matrix3d r = Turn(x.head<3>()) * rotation;
    Eigen::VectorXd res(5 * n);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d offset = x.segment<3>(6 + 3 * i);
      res.segment<2>(2 * i) =
          camera.Project(r * (points[i] + offset - centre - x.segment<3>(3))) / pixel_sigma;
      res.segment<3>(2 * n + 3 * i) = offset / point_sigmas[i];
    }
    return res;
  };
  return LargestSigma(NumericalCovariance(residuals, dim).block(3, 3, 3, 3));
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

// `n` points 2-6 m ahead, spread over the view.
std::vector<Eigen::Vector3d> PointsAhead(int n, Uniform* u) {
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < n; ++i) {
    const double z = (*u)(2.0, 6.0);
    points.emplace_back(0.5 * (*u)(-1, 1) * z, 0.4 * (*u)(-1, 1) * z, z);
  }
  return points;
}

// The motion's standard deviations from the residuals (in units of the noise) of parameters
// whose first three are its rotation and next two its translation direction: the Jacobian by
// central differences, the blocks of (J^T J)^-1; `analytic` must match them to 0.1 %.
void ExpectNumericalSigmas(const MotionUncertainty& analytic,
                           const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& residuals,
                           int num_params) {
  const Eigen::MatrixXd covariance = NumericalCovariance(residuals, num_params);
  const double rotation_sigma = LargestSigma(covariance.block(0, 0, 3, 3));
  const double direction_sigma = LargestSigma(covariance.block(3, 3, 2, 2));
  EXPECT_NEAR(analytic.rotation_rad, rotation_sigma, 1e-3 * rotation_sigma);
  EXPECT_NEAR(analytic.direction_rad, direction_sigma, 1e-3 * direction_sigma);
}

// The motion's standard deviations against an independent computation: the full Jacobian of
// every reprojection residual by central differences, the 5 x 5 block of (J^T J)^-1.
TEST(TwoViewMotionUncertainty, MatchesNumericalInformation) {
  const Camera camera;
  Uniform u(3);
  const std::vector<Eigen::Vector3d> points = PointsAhead(25, &u);
  const Pose3 motion = Turned(0.04, Eigen::Vector3d(0.3, 1, 0.1),
                              Eigen::Vector3d(0.2, 0.03, 0.05));  // camera1_from_camera0
  const double sigma = 0.7;
  const auto analytic = TwoViewMotionUncertainty(camera, sigma, motion, points);
  ASSERT_TRUE(analytic.has_value());

  // Parameters: rotation (left perturbation), translation direction (two angles), points.
  const Eigen::Vector3d t = motion.translation();
  const Eigen::Vector3d d = t.normalized();
  const Eigen::Vector3d e1 = d.unitOrthogonal(), e2 = d.cross(e1);
  const int n = static_cast<int>(points.size());
  const int num_params = 5 + 3 * n;
  auto residuals = [&](const Eigen::VectorXd& x) {
    const Eigen::Matrix3d r = Turn(x.head<3>()) * motion.RotationMatrix();
    // The direction turned by the two angles, the length kept (the scale is not observable).
    const Eigen::Vector3d dir = (d + std::tan(x(3)) * e1 + std::tan(x(4)) * e2).normalized();
    Eigen::VectorXd res(4 * n);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d p = points[i] + x.segment<3>(5 + 3 * i);
      res.segment<2>(4 * i) = camera.Project(p) / sigma;
      res.segment<2>(4 * i + 2) = camera.Project(r * p + t.norm() * dir) / sigma;
    }
    return res;
  };
  ExpectNumericalSigmas(*analytic, residuals, num_params);
}

// The same for three views, the third seeing every other point, its pose unknown too: the
// full Jacobian by central differences (view 1's rotation and direction, view 2's rotation and
// translation, the points), the 5 x 5 block of (J^T J)^-1. With two views it must give
// TwoViewMotionUncertainty's figures.
TEST(MultiViewMotionUncertainty, MatchesNumericalInformation) {
  const Camera camera;
  Uniform u(4);
  const std::vector<Eigen::Vector3d> points = PointsAhead(30, &u);
  const Pose3 motion =
      Turned(0.03, Eigen::Vector3d(0.3, 1, 0.1), Eigen::Vector3d(0.15, 0.02, 0.04));
  const Pose3 third =
      Turned(0.05, Eigen::Vector3d(-0.2, 1, 0.3), Eigen::Vector3d(0.1, 0.12, -0.05));
  const double sigma = 0.7;
  const int n = static_cast<int>(points.size());
  std::vector<std::pair<int, int>> observations;
  for (int i = 0; i < n; ++i) observations.insert(observations.end(), {{0, i}, {1, i}});
  const auto two =
      MultiViewMotionUncertainty(camera, sigma, {Pose3::Identity(), motion}, points, observations);
  const auto two_reference = TwoViewMotionUncertainty(camera, sigma, motion, points);
  ASSERT_TRUE(two && two_reference);
  EXPECT_NEAR(two->rotation_rad, two_reference->rotation_rad, 1e-9);
  EXPECT_NEAR(two->direction_rad, two_reference->direction_rad, 1e-9);
  for (int i = 0; i < n; i += 2) observations.emplace_back(2, i);
  const auto analytic = MultiViewMotionUncertainty(
      camera, sigma, {Pose3::Identity(), motion, third}, points, observations);
  ASSERT_TRUE(analytic.has_value());

  const Eigen::Vector3d t = motion.translation();
  const Eigen::Vector3d d = t.normalized();
  const Eigen::Vector3d e1 = d.unitOrthogonal(), e2 = d.cross(e1);
  const int num_params = 11 + 3 * n;
  auto residuals = [&](const Eigen::VectorXd& x) {
    const Eigen::Matrix3d r1 = Turn(x.head<3>()) * motion.RotationMatrix();
    const Eigen::Vector3d dir = (d + std::tan(x(3)) * e1 + std::tan(x(4)) * e2).normalized();
    const Eigen::Matrix3d r2 = Turn(x.segment<3>(5)) * third.RotationMatrix();
    const Eigen::Vector3d t2 = third.translation() + x.segment<3>(8);
    Eigen::VectorXd res(2 * static_cast<int>(observations.size()));
    for (size_t k = 0; k < observations.size(); ++k) {
      const auto [view, i] = observations[k];
      const Eigen::Vector3d p = points[static_cast<size_t>(i)] + x.segment<3>(11 + 3 * i);
      Eigen::Vector3d pc = p;
      if (view == 1) pc = r1 * p + t.norm() * dir;
      if (view == 2) pc = r2 * p + t2;
      res.segment<2>(2 * static_cast<int>(k)) = camera.Project(pc) / sigma;
    }
    return res;
  };
  ExpectNumericalSigmas(*analytic, residuals, num_params);
  // The third view adds information.
  EXPECT_LT(analytic->rotation_rad, two->rotation_rad);
}

// A camera centre's standard deviation against an independent computation: the Jacobian of every
// reprojection residual with respect to a rotation vector and the centre, by central
// differences, and the centre's 3 x 3 block of (J^T J)^-1. Points on one ray leave it unknown.
TEST(PoseCentreSigma, MatchesNumericalInformation) {
  const Camera camera;
  Uniform u(11);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 12; ++i) {
    const double z = u(1.0, 4.0);
    points.emplace_back(0.2 * u(-1, 1) * z + 0.5, 0.15 * u(-1, 1) * z, z);
  }
  const Eigen::Vector3d centre(0.1, -0.2, 0.3);
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.1, 1.0, 0.3).normalized()).toRotationMatrix();
  const Pose3 camera_from_world(Eigen::Quaterniond(rotation), -(rotation * centre));
  const double sigma = 0.8;
  const double analytic = PoseCentreSigma(camera, sigma, camera_from_world, points);

  const int n = static_cast<int>(points.size());
  auto residuals = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd {
    const Eigen::Matrix3d r = Turn(x.head<3>()) * rotation;
    Eigen::VectorXd res(2 * n);
    for (int i = 0; i < n; ++i)
      res.segment<2>(2 * i) = camera.Project(r * (points[i] - centre - x.tail<3>())) / sigma;
    return res;
  };
  const double numerical = LargestSigma(NumericalCovariance(residuals, 6).block(3, 3, 3, 3));
  EXPECT_NEAR(analytic, numerical, 1e-4 * numerical);

  std::vector<Eigen::Vector3d> on_a_ray;
  for (int i = 1; i <= 5; ++i)
    on_a_ray.push_back(centre + 0.7 * i * Eigen::Vector3d(0.1, 0.2, 1.0));
  EXPECT_TRUE(std::isinf(PoseCentreSigma(camera, sigma, camera_from_world, on_a_ray)));
  EXPECT_TRUE(
      std::isinf(PoseCentreSigma(camera, sigma, camera_from_world, {points[0], points[1]})));
}

}  // namespace
}  // namespace m2s::slam
