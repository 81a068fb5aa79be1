#include "mapping/triangulation.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>

#include "m2s/common/numeric.h"

namespace m2s::slam {

TriangulationChecks PointChecks(const MeasurementModel& model) {
  TriangulationChecks checks;
  checks.min_parallax_deg = model.min_triangulation_parallax_deg;
  checks.max_reprojection_px = std::sqrt(kChi2TwoDof95) * model.pixel_sigma;
  return checks;
}

std::optional<Eigen::Vector3d> TriangulateDlt(const Camera& camera,
                                              const std::vector<Pose3>& camera_from_world,
                                              const std::vector<Eigen::Vector2d>& uv) {
  const size_t n = camera_from_world.size();
  if (n < 2 || uv.size() != n) return std::nullopt;
  // Each view adds two rows of the DLT system A h = 0; the null vector of A is the eigenvector
  // of the 4x4 normal matrix A^T A with the smallest eigenvalue. Accumulating A^T A keeps the
  // work fixed-size (no dynamic SVD per point); the rows are normalised so that every view
  // weighs the same.
  Eigen::Matrix4d normal = Eigen::Matrix4d::Zero();
  for (size_t i = 0; i < n; ++i) {
    Eigen::Matrix<double, 3, 4> p;
    p.leftCols<3>() = camera_from_world[i].RotationMatrix();
    p.col(3) = camera_from_world[i].translation();
    const double x = (uv[i].x() - camera.cx) / camera.fx;
    const double y = (uv[i].y() - camera.cy) / camera.fy;
    Eigen::Matrix<double, 2, 4> rows;
    rows.row(0) = x * p.row(2) - p.row(0);
    rows.row(1) = y * p.row(2) - p.row(1);
    for (int r = 0; r < 2; ++r) {
      const double norm = rows.row(r).norm();
      if (norm > 0.0) rows.row(r) /= norm;
    }
    normal.noalias() += rows.transpose() * rows;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eig(normal);
  if (eig.info() != Eigen::Success) return std::nullopt;
  const Eigen::Vector4d h = eig.eigenvectors().col(0);  // eigenvalues in increasing order
  if (std::abs(h[3]) < 1e-12) return std::nullopt;
  const Eigen::Vector3d point = h.head<3>() / h[3];
  if (!point.allFinite()) return std::nullopt;
  return point;
}

double ParallaxDeg(const Eigen::Vector3d& point, const Eigen::Vector3d& center_a,
                   const Eigen::Vector3d& center_b) {
  const Eigen::Vector3d ra = (point - center_a).normalized();
  const Eigen::Vector3d rb = (point - center_b).normalized();
  return std::atan2(ra.cross(rb).norm(), ra.dot(rb)) * 180.0 / M_PI;
}

double MaxParallaxDeg(const Eigen::Vector3d& point, const std::vector<Eigen::Vector3d>& centers) {
  double max_parallax = 0.0;
  for (size_t i = 0; i < centers.size(); ++i) {
    for (size_t j = i + 1; j < centers.size(); ++j)
      max_parallax = std::max(max_parallax, ParallaxDeg(point, centers[i], centers[j]));
  }
  return max_parallax;
}

bool HasParallax(const Eigen::Vector3d& point, const std::vector<Eigen::Vector3d>& centers,
                 double min_deg) {
  if (centers.size() < 2) return false;
  double from_first = 0.0;
  for (size_t i = 1; i < centers.size(); ++i)
    from_first = std::max(from_first, ParallaxDeg(point, centers[0], centers[i]));
  if (from_first >= min_deg) return true;
  if (2.0 * from_first < min_deg) return false;
  return MaxParallaxDeg(point, centers) >= min_deg;
}

double ReprojectionErrorSq(const Camera& camera, const Pose3& camera_from_world,
                           const Eigen::Vector3d& point_world, const Eigen::Vector2d& uv) {
  const Eigen::Vector3d pc = camera_from_world * point_world;
  if (!(pc.z() > 0.0)) return std::numeric_limits<double>::infinity();
  return (camera.Project(pc) - uv).squaredNorm();
}

std::optional<Eigen::Vector3d> TriangulateChecked(const Camera& camera,
                                                  const TriangulationChecks& checks,
                                                  const std::vector<Pose3>& camera_from_world,
                                                  const std::vector<Eigen::Vector2d>& uv) {
  const auto point = TriangulateDlt(camera, camera_from_world, uv);
  if (!point) return std::nullopt;
  const double max_err_sq = checks.max_reprojection_px * checks.max_reprojection_px;
  std::vector<Eigen::Vector3d> centers;
  centers.reserve(camera_from_world.size());
  for (size_t i = 0; i < camera_from_world.size(); ++i) {
    const Eigen::Vector3d pc = camera_from_world[i] * *point;
    if (!(pc.z() > checks.min_depth)) return std::nullopt;
    if ((camera.Project(pc) - uv[i]).squaredNorm() > max_err_sq) return std::nullopt;
    centers.push_back(camera_from_world[i].Inverse().translation());
  }
  if (!HasParallax(*point, centers, checks.min_parallax_deg)) return std::nullopt;
  return point;
}

}  // namespace m2s::slam
