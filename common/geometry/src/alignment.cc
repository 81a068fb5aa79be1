#include "m2s/common/alignment.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace m2s {

// Umeyama's closed form (IEEE TPAMI 13(4), 1991), written on 3x3 sums: Eigen::umeyama on
// 3 x n matrices costs minutes of compile time per build and gives the same result.
std::optional<Sim3> AlignPoints(const std::vector<Eigen::Vector3d>& source,
                                const std::vector<Eigen::Vector3d>& target, bool with_scale) {
  const size_t n = source.size();
  if (n < 3 || target.size() != n) return std::nullopt;
  Eigen::Vector3d mean_src = Eigen::Vector3d::Zero(), mean_dst = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    if (!source[i].allFinite() || !target[i].allFinite()) return std::nullopt;
    mean_src += source[i];
    mean_dst += target[i];
  }
  const double inv_n = 1.0 / static_cast<double>(n);
  mean_src *= inv_n;
  mean_dst *= inv_n;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();     // sum of s s^T (centred source)
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // sum of d s^T
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d s = source[i] - mean_src;
    scatter.noalias() += s * s.transpose();
    covariance.noalias() += (target[i] - mean_dst) * s.transpose();
  }
  // Degenerate when the centred source spans fewer than two dimensions: its second singular
  // value under 1e-7 of the first (the scatter's eigenvalues are their squares, ascending).
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter, Eigen::EigenvaluesOnly);
  const Eigen::Vector3d lambda = eigen.eigenvalues();
  if (!(lambda(2) > 0.0) || lambda(1) <= 1e-14 * lambda(2)) return std::nullopt;

  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance * inv_n,
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d sign = Eigen::Vector3d::Ones();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) sign(2) = -1.0;
  const Eigen::Matrix3d r = svd.matrixU() * sign.asDiagonal() * svd.matrixV().transpose();
  const double variance = scatter.trace() * inv_n;
  const double scale = with_scale ? svd.singularValues().dot(sign) / variance : 1.0;
  if (!(scale > 0.0) || !std::isfinite(scale) || !r.allFinite()) return std::nullopt;
  return Sim3(scale, Eigen::Quaterniond(r), mean_dst - scale * r * mean_src);
}

}  // namespace m2s
