#include "tracking/rotation_only.h"

#include <Eigen/SVD>

namespace m2s::slam {
namespace {

constexpr int kRansacIterations = 64;
constexpr int kRefits = 2;

// The rotation R minimising sum |R from_i - to_i|^2 over the given pairs (Kabsch).
Eigen::Matrix3d FitRotation(const std::vector<Eigen::Vector3d>& from,
                            const std::vector<Eigen::Vector3d>& to,
                            const std::vector<size_t>& use) {
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
  for (const size_t i : use) h += to[i] * from[i].transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

}  // namespace

std::optional<RotationOnlyPose> SolveRotationOnly(const Camera& camera, double max_error_px,
                                                  const Pose3& keyframe_world_from_camera,
                                                  const std::vector<VertexId>& keyframe_ids,
                                                  const std::vector<Eigen::Vector2d>& keyframe_uvs,
                                                  const SortedFeatures& features) {
  // Bearings of the shared ids (both lists are sorted by id).
  std::vector<Eigen::Vector3d> from, to;
  std::vector<Eigen::Vector2d> observed;
  for (size_t k = 0, f = 0; k < keyframe_ids.size() && f < features.size();) {
    if (keyframe_ids[k] < features.ids[f]) {
      ++k;
    } else if (features.ids[f] < keyframe_ids[k]) {
      ++f;
    } else {
      from.push_back(camera.Unproject(keyframe_uvs[k], 1.0).normalized());
      to.push_back(camera.Unproject(features.uvs[f], 1.0).normalized());
      observed.push_back(features.uvs[f]);
      ++k;
      ++f;
    }
  }
  const size_t n = from.size();
  if (n < 3) return std::nullopt;
  const double max_err_sq = max_error_px * max_error_px;
  auto inliers_of = [&](const Eigen::Matrix3d& r) {
    std::vector<size_t> in;
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d p = r * from[i];
      if (p.z() > 0.0 && (camera.Project(p) - observed[i]).squaredNorm() <= max_err_sq)
        in.push_back(i);
    }
    return in;
  };
  // Two bearings fix a rotation; the samples are spread deterministically over the pairs.
  std::vector<size_t> best;
  for (int it = 0; it < kRansacIterations; ++it) {
    const size_t a = (static_cast<size_t>(it) * 7919u) % n;
    const size_t b = (a + 1 + (static_cast<size_t>(it) * 104729u) % (n - 1)) % n;
    if (from[a].cross(from[b]).norm() < 1e-3) continue;
    std::vector<size_t> in = inliers_of(FitRotation(from, to, {a, b}));
    if (in.size() > best.size()) best = std::move(in);
    if (best.size() == n) break;
  }
  if (best.size() < 3) return std::nullopt;
  Eigen::Matrix3d r = FitRotation(from, to, best);
  for (int i = 0; i < kRefits; ++i) {
    std::vector<size_t> in = inliers_of(r);
    if (in.size() < 3) break;
    r = FitRotation(from, to, in);
    best = std::move(in);
  }
  best = inliers_of(r);
  // camera_from_keyframe is the pure rotation r: the frame's centre is the keyframe's.
  const Pose3 camera_from_keyframe(r, Eigen::Vector3d::Zero());
  return RotationOnlyPose{camera_from_keyframe * keyframe_world_from_camera.Inverse(),
                          static_cast<int>(n), static_cast<int>(best.size())};
}

std::optional<Pose3> PoseAtCentre(const Camera& camera, const Eigen::Vector3d& centre,
                                  const std::vector<Eigen::Vector3d>& points_world,
                                  const std::vector<Eigen::Vector2d>& uvs) {
  std::vector<Eigen::Vector3d> from, to;
  std::vector<size_t> use;
  for (size_t i = 0; i < points_world.size() && i < uvs.size(); ++i) {
    const Eigen::Vector3d d = points_world[i] - centre;
    if (!(d.norm() > 0.0)) continue;
    use.push_back(from.size());
    from.push_back(d.normalized());
    to.push_back(camera.Unproject(uvs[i], 1.0).normalized());
  }
  bool spread = false;
  for (size_t i = 1; i < from.size() && !spread; ++i) spread = from[0].cross(from[i]).norm() > 1e-9;
  if (!spread) return std::nullopt;
  const Eigen::Matrix3d r = FitRotation(from, to, use);
  return Pose3(r, -(r * centre));
}

}  // namespace m2s::slam
