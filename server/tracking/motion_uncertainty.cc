#include "tracking/motion_uncertainty.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "m2s/common/check.h"
#include "m2s/common/numeric.h"

namespace m2s::slam {

std::string Describe(const MotionUncertainty& u) {
  std::ostringstream out;
  out << "rotation sigma " << RadToDeg(u.rotation_rad) << " deg, direction sigma "
      << RadToDeg(u.direction_rad) << " deg";
  return out.str();
}

namespace {

// d(pixel) / d(point in the camera frame) for the pinhole projection.
Eigen::Matrix<double, 2, 3> ProjectionJacobian(const Camera& camera, const Eigen::Vector3d& p) {
  Eigen::Matrix<double, 2, 3> j;
  const double iz = 1.0 / p.z();
  j << camera.fx * iz, 0.0, -camera.fx * p.x() * iz * iz, 0.0, camera.fy * iz,
      -camera.fy * p.y() * iz * iz;
  return j;
}

// Square root of the largest eigenvalue: the largest standard deviation.
double LargestSigma(const Eigen::Matrix3d& covariance) {
  return std::sqrt(std::max(
      0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance).eigenvalues().maxCoeff()));
}

}  // namespace

std::optional<MotionUncertainty> TwoViewMotionUncertainty(
    const Camera& camera, double pixel_sigma, const Pose3& camera1_from_camera0,
    const std::vector<Eigen::Vector3d>& points_camera0) {
  const Eigen::Matrix3d r = camera1_from_camera0.RotationMatrix();
  const Eigen::Vector3d t = camera1_from_camera0.translation();
  const double baseline = t.norm();
  if (!(baseline > 0.0) || points_camera0.size() < 3) return std::nullopt;
  // Two unit directions across the baseline: perturbations of the direction, in radians.
  Eigen::Vector3d e1 = t.unitOrthogonal();
  Eigen::Vector3d e2 = t.normalized().cross(e1);
  Eigen::Matrix<double, 5, 5> information = Eigen::Matrix<double, 5, 5>::Zero();
  for (const Eigen::Vector3d& x : points_camera0) {
    const Eigen::Vector3d rx = r * x;
    const Eigen::Vector3d p1 = rx + t;
    if (!(x.z() > 0.0) || !(p1.z() > 0.0)) continue;
    const Eigen::Matrix<double, 2, 3> j0 = ProjectionJacobian(camera, x);
    const Eigen::Matrix<double, 2, 3> j1 = ProjectionJacobian(camera, p1);
    Eigen::Matrix<double, 3, 5> dp_dmotion;
    dp_dmotion << -Hat(rx), baseline * e1, baseline * e2;
    const Eigen::Matrix<double, 2, 5> a = j1 * dp_dmotion;
    const Eigen::Matrix<double, 2, 3> b1 = j1 * r;
    const Eigen::Matrix3d h_ll = j0.transpose() * j0 + b1.transpose() * b1;
    const Eigen::Matrix<double, 5, 3> h_pl = a.transpose() * b1;
    Eigen::LDLT<Eigen::Matrix3d> h_ll_ldlt(h_ll);
    if (h_ll_ldlt.info() != Eigen::Success) continue;
    information += a.transpose() * a - h_pl * h_ll_ldlt.solve(h_pl.transpose());
  }
  information /= pixel_sigma * pixel_sigma;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 5, 5>> eig(information);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues().minCoeff() > 0.0)) {
    return MotionUncertainty{INFINITY, INFINITY};
  }
  const Eigen::Matrix<double, 5, 5> covariance = eig.eigenvectors() *
                                                 eig.eigenvalues().cwiseInverse().asDiagonal() *
                                                 eig.eigenvectors().transpose();
  MotionUncertainty out;
  out.rotation_rad =
      std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance.topLeftCorner<3, 3>())
                    .eigenvalues()
                    .maxCoeff());
  out.direction_rad =
      std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(covariance.bottomRightCorner<2, 2>())
                    .eigenvalues()
                    .maxCoeff());
  return out;
}

std::optional<MotionUncertainty> MultiViewMotionUncertainty(
    const Camera& camera, double pixel_sigma, const std::vector<Pose3>& views_from_camera0,
    const std::vector<Eigen::Vector3d>& points_camera0,
    const std::vector<std::pair<int, int>>& observations) {
  M2S_CHECK(views_from_camera0.size() >= 2);
  const Eigen::Vector3d t = views_from_camera0[1].translation();
  const double baseline = t.norm();
  if (!(baseline > 0.0)) return std::nullopt;
  // Parameters: view 1's rotation (left perturbation) and translation direction (two angles
  // across it, its length the scale), then each further view's rotation and translation.
  const Eigen::Vector3d e1 = t.unitOrthogonal();
  const Eigen::Vector3d e2 = t.normalized().cross(e1);
  const int num_views = static_cast<int>(views_from_camera0.size());
  const int num_params = 5 + 6 * (num_views - 2);
  auto offset = [](int view) { return view == 1 ? 0 : 5 + 6 * (view - 2); };
  std::vector<std::vector<int>> seen_by(points_camera0.size());
  for (const auto& [view, point] : observations) {
    M2S_CHECK(view >= 0 && view < num_views && point >= 0 &&
              static_cast<size_t>(point) < points_camera0.size());
    seen_by[static_cast<size_t>(point)].push_back(view);
  }
  // The reduced camera system: the points eliminated one by one (Schur complement).
  Eigen::MatrixXd information = Eigen::MatrixXd::Zero(num_params, num_params);
  for (size_t i = 0; i < points_camera0.size(); ++i) {
    if (seen_by[i].size() < 2) continue;
    Eigen::Matrix3d h_ll = Eigen::Matrix3d::Zero();
    Eigen::MatrixXd h_cl = Eigen::MatrixXd::Zero(num_params, 3);
    Eigen::MatrixXd h_cc = Eigen::MatrixXd::Zero(num_params, num_params);
    for (const int view : seen_by[i]) {
      const Eigen::Matrix3d r = views_from_camera0[static_cast<size_t>(view)].RotationMatrix();
      const Eigen::Vector3d rx = r * points_camera0[i];
      const Eigen::Vector3d p = rx + views_from_camera0[static_cast<size_t>(view)].translation();
      if (!(p.z() > 0.0)) continue;
      const Eigen::Matrix<double, 2, 3> projection = ProjectionJacobian(camera, p);
      const Eigen::Matrix<double, 2, 3> b = projection * r;
      h_ll += b.transpose() * b;
      if (view == 0) continue;
      Eigen::MatrixXd dp_dview(3, view == 1 ? 5 : 6);
      if (view == 1) {
        dp_dview << -Hat(rx), baseline * e1, baseline * e2;
      } else {
        dp_dview << -Hat(rx), Eigen::Matrix3d::Identity();
      }
      const Eigen::MatrixXd a = projection * dp_dview;
      const int o = offset(view);
      const auto width = static_cast<Eigen::Index>(a.cols());
      h_cc.block(o, o, width, width) += a.transpose() * a;
      h_cl.block(o, 0, width, 3) += a.transpose() * b;
    }
    Eigen::LDLT<Eigen::Matrix3d> h_ll_ldlt(h_ll);
    if (h_ll_ldlt.info() != Eigen::Success || !(h_ll.determinant() > 0.0)) continue;
    information += h_cc - h_cl * h_ll_ldlt.solve(h_cl.transpose());
  }
  information /= pixel_sigma * pixel_sigma;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(information);
  if (eig.info() != Eigen::Success ||
      !(eig.eigenvalues().minCoeff() > 1e-12 * eig.eigenvalues().maxCoeff())) {
    return MotionUncertainty{INFINITY, INFINITY};
  }
  const Eigen::MatrixXd covariance = eig.eigenvectors() *
                                     eig.eigenvalues().cwiseInverse().asDiagonal() *
                                     eig.eigenvectors().transpose();
  MotionUncertainty out;
  out.rotation_rad = LargestSigma(covariance.topLeftCorner<3, 3>());
  out.direction_rad = std::sqrt(
      std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(covariance.block<2, 2>(3, 3))
                        .eigenvalues()
                        .maxCoeff()));
  return out;
}

std::optional<Eigen::Matrix3d> PoseCentreCovariance(
    const Camera& camera, double pixel_sigma, const Pose3& camera_from_world,
    const std::vector<Eigen::Vector3d>& points_world, const std::vector<double>& point_sigmas) {
  M2S_CHECK(point_sigmas.empty() || point_sigmas.size() == points_world.size());
  if (!(pixel_sigma > 0.0)) return std::nullopt;
  // x_c = R (X - C): d x_c / d theta = -[x_c]x (rotation perturbed on the left), d x_c / d C = -R.
  const Eigen::Matrix3d r = camera_from_world.RotationMatrix();
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  const Eigen::Matrix2d pixel_covariance = pixel_sigma * pixel_sigma * Eigen::Matrix2d::Identity();
  int used = 0;
  for (size_t i = 0; i < points_world.size(); ++i) {
    const Eigen::Vector3d p = camera_from_world * points_world[i];
    if (!(p.z() > 0.0)) continue;
    Eigen::Matrix<double, 3, 6> dp_dpose;
    dp_dpose << -Hat(p), -r;
    const Eigen::Matrix<double, 2, 3> projection = ProjectionJacobian(camera, p);
    const Eigen::Matrix<double, 2, 6> j = projection * dp_dpose;
    // An isotropic point covariance s^2 I stays s^2 I in the camera frame.
    const double s = point_sigmas.empty() ? 0.0 : std::max(point_sigmas[i], 0.0);
    const Eigen::Matrix2d covariance =
        pixel_covariance + s * s * projection * projection.transpose();
    information += j.transpose() * covariance.inverse() * j;
    ++used;
  }
  if (used < 3) return std::nullopt;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(information);
  // Rank-deficient (within rounding): some direction of the pose is not observed.
  if (eig.info() != Eigen::Success ||
      !(eig.eigenvalues().minCoeff() > 1e-12 * eig.eigenvalues().maxCoeff())) {
    return std::nullopt;
  }
  const Eigen::Matrix<double, 6, 6> covariance = eig.eigenvectors() *
                                                 eig.eigenvalues().cwiseInverse().asDiagonal() *
                                                 eig.eigenvectors().transpose();
  return Eigen::Matrix3d(covariance.bottomRightCorner<3, 3>());
}

std::optional<ViewCentreUncertainty> CentreUncertaintyOfView(
    const Camera& camera, double pixel_sigma, const Pose3& camera_from_world,
    const std::vector<Eigen::Vector3d>& points_world, const std::vector<size_t>& use,
    int max_points) {
  if (use.empty()) return std::nullopt;
  const std::vector<size_t> subset =
      EvenlySpacedIndices(use.size(), static_cast<size_t>(std::max(max_points, 1)));
  std::vector<Eigen::Vector3d> points;
  points.reserve(subset.size());
  for (const size_t k : subset) points.push_back(points_world[use[k]]);
  const double noise =
      pixel_sigma * std::sqrt(static_cast<double>(subset.size()) / static_cast<double>(use.size()));
  const std::optional<Eigen::Matrix3d> covariance =
      PoseCentreCovariance(camera, noise, camera_from_world, points);
  if (!covariance) return std::nullopt;
  return ViewCentreUncertainty{*covariance, LargestSigma(*covariance),
                               MedianDepth(camera_from_world, points)};
}

double PoseCentreSigma(const Camera& camera, double pixel_sigma, const Pose3& camera_from_world,
                       const std::vector<Eigen::Vector3d>& points_world,
                       const std::vector<double>& point_sigmas) {
  const std::optional<Eigen::Matrix3d> covariance =
      PoseCentreCovariance(camera, pixel_sigma, camera_from_world, points_world, point_sigmas);
  return covariance ? LargestSigma(*covariance) : INFINITY;
}

}  // namespace m2s::slam
