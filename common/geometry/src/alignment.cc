#include "m2s/common/alignment.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace m2s {

std::optional<Sim3> AlignPoints(const std::vector<Eigen::Vector3d>& source,
                                const std::vector<Eigen::Vector3d>& target, bool with_scale) {
  const size_t n = source.size();
  if (n < 3 || target.size() != n) return std::nullopt;
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  for (size_t i = 0; i < n; ++i) {
    if (!source[i].allFinite() || !target[i].allFinite()) return std::nullopt;
    src.col(i) = source[i];
    dst.col(i) = target[i];
  }
  // Degenerate when the centred source spans fewer than two dimensions.
  const Eigen::Matrix3Xd centred = src.colwise() - src.rowwise().mean();
  const Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(centred);
  const Eigen::Vector3d sv = svd.singularValues();
  if (sv(0) <= 0.0 || sv(1) <= 1e-9 * sv(0)) return std::nullopt;

  const Eigen::Matrix4d m = Eigen::umeyama(src, dst, with_scale);
  if (!m.allFinite()) return std::nullopt;
  const Eigen::Matrix3d sr = m.topLeftCorner<3, 3>();
  const double scale = with_scale ? std::cbrt(sr.determinant()) : 1.0;
  if (!(scale > 0.0)) return std::nullopt;
  const Eigen::Matrix3d r = sr / scale;
  return Sim3(scale, Eigen::Quaterniond(r), m.topRightCorner<3, 1>());
}

}  // namespace m2s
