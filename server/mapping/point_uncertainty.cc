#include "mapping/point_uncertainty.h"

#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>

#include "mapping/triangulation.h"

namespace m2s::slam {

bool PointInformation(const Camera& camera, const std::vector<Pose3>& camera_from_world,
                      const Eigen::Vector3d& point_world, Eigen::Matrix3d* information,
                      double* mean_depth) {
  information->setZero();
  double depth_sum = 0.0;
  for (const Pose3& pose : camera_from_world) {
    const Eigen::Vector3d pc = pose * point_world;
    if (!(pc.z() > 0.0)) return false;
    const double inv_z = 1.0 / pc.z();
    // d(u, v) / d(camera-frame point), then through the rotation to world coordinates.
    Eigen::Matrix<double, 2, 3> projection;
    projection << camera.fx * inv_z, 0.0, -camera.fx * pc.x() * inv_z * inv_z,  //
        0.0, camera.fy * inv_z, -camera.fy * pc.y() * inv_z * inv_z;
    const Eigen::Matrix<double, 2, 3> jacobian = projection * pose.RotationMatrix();
    information->noalias() += jacobian.transpose() * jacobian;
    depth_sum += pc.z();
  }
  if (mean_depth != nullptr) {
    *mean_depth = camera_from_world.empty() ? 0.0 : depth_sum / camera_from_world.size();
  }
  return true;
}

double RelativePointUncertainty(const Camera& camera, double pixel_sigma,
                                const std::vector<Pose3>& camera_from_world,
                                const Eigen::Vector3d& point_world) {
  constexpr double kInfinity = std::numeric_limits<double>::infinity();
  if (camera_from_world.size() < 2) return kInfinity;
  Eigen::Matrix3d information;
  double mean_depth = 0.0;
  if (!PointInformation(camera, camera_from_world, point_world, &information, &mean_depth)) {
    return kInfinity;
  }
  // The iterative solver: the closed form loses the small eigenvalue of nearly parallel rays.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(information, Eigen::EigenvaluesOnly);
  const double smallest = eig.eigenvalues()[0];  // ascending
  if (!(smallest > 0.0) || !(mean_depth > 0.0)) return kInfinity;
  return pixel_sigma / std::sqrt(smallest) / mean_depth;
}

std::vector<PointQuality> EvaluatePointUncertainty(const Camera& camera, const PointGate& gate,
                                                   const std::vector<VertexId>& ids,
                                                   const MapData& map) {
  const double max_err_sq = gate.max_reprojection_px * gate.max_reprojection_px;
  std::vector<PointQuality> out;
  out.reserve(ids.size());
  std::vector<Pose3> poses;
  for (const VertexId id : ids) {
    const MapPoint* p = map.point(id);
    if (p == nullptr) continue;
    poses.clear();
    bool agree = true;
    for (const KeyframeId o : p->observers) {
      const Keyframe* kf = map.keyframe(o);
      if (kf == nullptr) continue;
      poses.push_back(kf->world_from_camera.Inverse());
      const Eigen::Vector2d* uv = kf->Find(id);
      agree = agree && uv != nullptr &&
              ReprojectionErrorSq(camera, poses.back(), p->position, *uv) <= max_err_sq;
    }
    const double u = RelativePointUncertainty(camera, gate.pixel_sigma, poses, p->position);
    out.push_back({id, u, agree && u <= gate.max_uncertainty});
  }
  return out;
}

void ApplyPointQuality(const std::vector<PointQuality>& quality, MapData* map) {
  for (const PointQuality& q : quality) {
    if (map->point(q.id) != nullptr) map->SetPointUncertainty(q.id, q.uncertainty, q.constrained);
  }
}

void UpdatePointUncertainty(const Camera& camera, const PointGate& gate,
                            const std::vector<VertexId>& ids, MapData* map) {
  ApplyPointQuality(EvaluatePointUncertainty(camera, gate, ids, *map), map);
}

}  // namespace m2s::slam
