#include "tracking/initializer_internal.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "m2s/common/numeric.h"
#include "mapping/triangulation.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam::initializer_internal {

MotionDistance DistanceBetween(const Pose3& a, const Pose3& b) {
  const double cos_direction = a.translation().normalized().dot(b.translation().normalized());
  return {RadToDeg(a.rotation().angularDistance(b.rotation())),
          RadToDeg(std::acos(std::clamp(cos_direction, -1.0, 1.0)))};
}

bool SameMotion(const Pose3& a, const Pose3& b) {
  const MotionDistance d = DistanceBetween(a, b);
  return d.rotation_deg < kSameStartDeg && d.direction_deg < kSameStartDeg;
}

BaProblem TwoViewProblem(const Camera& camera, const SortedFeatures& view0,
                         const SortedFeatures& view1, const Pose3& camera1_from_camera0,
                         const std::vector<VertexId>& ids,
                         const std::vector<Eigen::Vector3d>& points) {
  BaProblem problem;
  problem.keyframes = {{0, Pose3::Identity(), true}, {1, camera1_from_camera0, false}};
  for (size_t k = 0; k < ids.size(); ++k) {
    const auto uv = [&](const SortedFeatures& f) -> std::optional<Eigen::Vector2d> {
      const auto it = std::lower_bound(f.ids.begin(), f.ids.end(), ids[k]);
      if (it == f.ids.end() || *it != ids[k]) return std::nullopt;
      return f.uvs[static_cast<size_t>(it - f.ids.begin())];
    };
    const std::optional<Eigen::Vector2d> uv0 = uv(view0), uv1 = uv(view1);
    if (!uv0 || !uv1) continue;
    std::optional<Eigen::Vector3d> p;
    if (!points.empty()) {
      p = points[k];
    } else {
      p = TriangulateDlt(camera, {Pose3::Identity(), camera1_from_camera0}, {*uv0, *uv1});
      if (!p || !(p->z() > 0.0) || !((camera1_from_camera0 * *p).z() > 0.0)) continue;
    }
    problem.points.push_back({ids[k], *p, false});
    const int index = static_cast<int>(problem.points.size() - 1);
    problem.observations.push_back({0, index, *uv0});
    problem.observations.push_back({1, index, *uv1});
  }
  return problem;
}

bool StartLeavesTooMany(const BaProblem& problem, size_t num_ids) {
  return static_cast<double>(problem.points.size()) <
         (1.0 - kMaxStartBehind) * static_cast<double>(num_ids);
}

std::vector<VertexId> SharedIds(const SortedFeatures& a, const SortedFeatures& b,
                                size_t max_count) {
  const std::vector<std::pair<size_t, size_t>> shared = SharedIndices(a, b);
  std::vector<VertexId> out;
  for (const size_t k : EvenlySpacedIndices(shared.size(), max_count))
    out.push_back(a.ids[shared[k].first]);
  return out;
}

void AdjustedPoints(const BaProblem& problem, const BundleAdjustmentResult& result,
                    std::vector<VertexId>* ids, std::vector<Eigen::Vector3d>* points) {
  std::vector<bool> bad(problem.points.size(), false);
  for (size_t o = 0; o < problem.observations.size(); ++o) {
    if (o < result.outlier.size() && result.outlier[o])
      bad[static_cast<size_t>(problem.observations[o].point_index)] = true;
  }
  const Pose3& camera1_from_world = problem.keyframes[1].camera_from_world;
  std::vector<VertexId> out_ids;
  std::vector<Eigen::Vector3d> out_points;
  for (size_t i = 0; i < problem.points.size(); ++i) {
    const BaPoint& point = problem.points[i];
    const Eigen::Vector3d& p = point.position_world;
    if (bad[i] || !p.allFinite() || p.z() <= 0.0 || (camera1_from_world * p).z() <= 0.0) continue;
    out_ids.push_back(point.id);
    out_points.push_back(p);
  }
  *ids = std::move(out_ids);
  *points = std::move(out_points);
}

BundleAdjustmentOptions TwoViewBaOptions(const MeasurementModel& model, int num_threads) {
  BundleAdjustmentOptions ba;
  ba.pixel_sigma = model.pixel_sigma;
  ba.huber_delta_px = 2.0 * model.pixel_sigma;
  ba.max_iterations = 50;
  ba.num_threads = num_threads;
  return ba;
}

std::optional<PosedView> PoseOnPoints(const MeasurementModel& model, const SortedFeatures& view,
                                      const std::unordered_map<VertexId, size_t>& point_index,
                                      const std::vector<Eigen::Vector3d>& positions,
                                      const Pose3& start, int min_points) {
  PosedView posed;
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  for (size_t i = 0; i < view.size(); ++i) {
    const auto it = point_index.find(view.ids[i]);
    if (it == point_index.end()) continue;
    posed.features.push_back(i);
    posed.points.push_back(it->second);
    points.push_back(positions[it->second]);
    uvs.push_back(view.uvs[i]);
  }
  if (points.size() < static_cast<size_t>(min_points)) return std::nullopt;
  posed.camera_from_world = start;
  posed.result = OptimizePose(model.camera, tracker_internal::MakePoseOptions(model), points, uvs,
                              &posed.camera_from_world);
  if (!posed.result.converged || !posed.camera_from_world.AllFinite()) return std::nullopt;
  return posed;
}

}  // namespace m2s::slam::initializer_internal
