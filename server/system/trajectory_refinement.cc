// RefineFramePose and SolveUnposedFrames (trajectory_refinement.h), and the helpers the
// refinement shares (refinement_internal.h). SmoothLooseFrames is loose_frames.cc.
#include "system/trajectory_refinement.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "m2s/common/numeric.h"
#include "mapping/triangulation.h"
#include "optimization/problems.h"
#include "system/refinement_internal.h"
#include "tracking/motion_uncertainty.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {

namespace refinement_internal {

void MappedObservations(const MapData& map, const TrajectoryRecord& record,
                        std::vector<Eigen::Vector3d>* points, std::vector<Eigen::Vector2d>* uvs,
                        std::vector<double>* uncertainties) {
  for (size_t i = 0; i < record.observed_ids.size(); ++i) {
    const MapPoint* p = map.point(record.observed_ids[i]);
    if (p == nullptr || p->observers.empty()) continue;
    points->push_back(p->position);
    uvs->push_back(record.observed_uvs[i].cast<double>());
    if (uncertainties != nullptr) uncertainties->push_back(std::max(p->uncertainty, 0.0));
  }
}

bool ExactData(const MeasurementModel& model, double squared_error, size_t points) {
  return squared_error / (model.pixel_sigma * model.pixel_sigma *
                          std::max(1.0, 2.0 * static_cast<double>(points) - 6.0)) <
         kExactDataVarianceFactor;
}

std::optional<Pose3> RecordPose(const MapData& map, int map_id, const TrajectoryRecord& record) {
  if (!HasPose(record.state) || record.map_id != map_id || !record.reference) return std::nullopt;
  const std::optional<Pose3> reference = map.ResolveKeyframePose(*record.reference);
  if (!reference) return std::nullopt;
  return *reference * record.reference_from_camera;
}

}  // namespace refinement_internal

using refinement_internal::ExactData;
using refinement_internal::MappedObservations;
using refinement_internal::RecordPose;

bool RefineFramePose(const MeasurementModel& model, const MapData& map, TrajectoryRecord* record,
                     const Pose3* fallback_start) {
  if (!HasPose(record->state) || !record->reference) return false;
  const std::optional<Pose3> reference = map.ResolveKeyframePose(*record->reference);
  if (!reference) return false;
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  MappedObservations(map, *record, &points, &uvs);
  if (points.size() < static_cast<size_t>(tracker_internal::kMinTrackedInliers)) return false;
  // As tracking asks of a sparse view: most of the observations explained.
  const double min_inliers =
      tracker_internal::kSparseViewInlierFraction * static_cast<double>(points.size());
  const Pose3 current = (*reference * record->reference_from_camera).Inverse();
  if (record->is_keyframe) {
    const double max_err_sq = kChi2TwoDof95 * model.pixel_sigma * model.pixel_sigma;
    int explained = 0;
    for (size_t i = 0; i < points.size(); ++i) {
      explained += ReprojectionErrorSq(model.camera, current, points[i], uvs[i]) <= max_err_sq;
    }
    if (explained >= min_inliers) return false;
  }
  auto solve = [&](Pose3 start) -> std::optional<Pose3> {
    const PoseOnlyResult r =
        OptimizePose(model.camera, tracker_internal::MakePoseOptions(model), points, uvs, &start);
    if (!r.converged || !start.AllFinite() || r.num_inliers < min_inliers) return std::nullopt;
    return start;
  };
  std::optional<Pose3> solved = solve(current);
  if (!solved && fallback_start != nullptr) solved = solve(*fallback_start);
  if (!solved) return false;
  record->reference_from_camera = reference->Inverse() * solved->Inverse();
  return true;
}

namespace {

// SolveUnposedFrames: a pose solved without a motion prior must have its centre determined to
// this fraction of the median depth, and the poses solved from either side must agree within
// it and this angle.
constexpr double kUnposedAgreement = 0.01;
constexpr double kUnposedAgreementRad = M_PI / 180.0;
// SolveUnposedFrames: PnP's RANSAC bound, in pixel sigmas (relocalisation's).
constexpr double kUnposedPnpThresholdSigmas = 4.0;

}  // namespace

int SolveUnposedFrames(const MeasurementModel& model, const MapData& map, int map_id,
                       int min_points, std::vector<TrajectoryRecord>* records) {
  std::vector<TrajectoryRecord>& r = *records;
  struct Solved {
    Pose3 world_from_camera;
    KeyframeId reference = 0;  // of the posed frame the sweep came from
    double depth = 0.0;        // the inliers' median depth
  };
  // Solves r[i] from `start`: a pose, none (the view refused), or none with `diverged` (the
  // solve found no inliers from its start, too far off after a fast turn: no opinion).
  struct Outcome {
    std::optional<Solved> pose;
    bool diverged = false;
  };
  // The frame's map points and pixels; false below min_points.
  auto observations = [&](size_t i, std::vector<Eigen::Vector3d>* points,
                          std::vector<Eigen::Vector2d>* uvs, std::vector<double>* uncertainties) {
    MappedObservations(map, r[i], points, uvs, uncertainties);
    return points->size() >= static_cast<size_t>(std::max(min_points, 1));
  };
  auto solve_on = [&](const std::vector<Eigen::Vector3d>& points,
                      const std::vector<Eigen::Vector2d>& uvs,
                      const std::vector<double>& uncertainties, const Solved& start) -> Outcome {
    Pose3 camera_from_world = start.world_from_camera.Inverse();
    const PoseOnlyResult result = OptimizePose(
        model.camera, tracker_internal::MakePoseOptions(model), points, uvs, &camera_from_world);
    if (!result.converged && result.num_inliers == 0) return {std::nullopt, true};
    if (!result.converged || !camera_from_world.AllFinite() ||
        result.num_inliers <
            tracker_internal::kSparseViewInlierFraction * static_cast<double>(points.size())) {
      return {};
    }
    std::vector<Eigen::Vector3d> inliers;
    // The inliers' deviations in world units: the relative uncertainty (over the depth they
    // were seen at) taken at their depth in this view.
    std::vector<double> sigmas;
    double squared_error = 0.0;
    for (size_t k = 0; k < points.size(); ++k) {
      if (!result.inlier[k]) continue;
      inliers.push_back(points[k]);
      sigmas.push_back(uncertainties[k] * std::abs((camera_from_world * points[k]).z()));
      squared_error += ReprojectionErrorSq(model.camera, camera_from_world, points[k], uvs[k]);
    }
    const double depth = MedianDepth(camera_from_world, inliers);
    // Exact data (the smoother's rule) fixes the centre however few the points. Otherwise the
    // centre's deviation counts the points' own: a view of points triangulated over small
    // baselines only (unconstrained) fits a pose well that is decimetres off.
    if (!ExactData(model, squared_error, inliers.size()) &&
        !(PoseCentreSigma(model.camera, model.pixel_sigma, camera_from_world, inliers, sigmas) <=
          kUnposedAgreement * depth)) {
      return {};
    }
    return {Solved{camera_from_world.Inverse(), start.reference, depth}};
  };
  auto solve = [&](size_t i, const Solved& start) -> Outcome {
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> uvs;
    std::vector<double> uncertainties;
    if (!observations(i, &points, &uvs, &uncertainties)) return {};
    return solve_on(points, uvs, uncertainties, start);
  };
  // The frames with a pose in the map, once.
  std::vector<std::optional<Solved>> posed_frames(r.size());
  for (size_t i = 0; i < r.size(); ++i) {
    if (const std::optional<Pose3> pose = RecordPose(map, map_id, r[i])) {
      posed_frames[i] = Solved{*pose, *r[i].reference, 0.0};
    }
  }
  auto posed = [&](size_t i) -> const std::optional<Solved>& { return posed_frames[i]; };
  auto unposed = [&](size_t i) { return !HasPose(r[i].state) && !r[i].observed_ids.empty(); };
  // One sweep in each direction, each solved frame starting the next.
  auto sweep = [&](bool forward) {
    std::vector<Outcome> out(r.size());
    std::optional<Solved> last;
    for (size_t k = 0; k < r.size(); ++k) {
      const size_t i = forward ? k : r.size() - 1 - k;
      if (const std::optional<Solved>& p = posed(i)) {
        last = p;
      } else if (last && unposed(i)) {
        out[i] = solve(i, *last);
        if (out[i].pose) last = out[i].pose;
      }
    }
    return out;
  };
  const std::vector<Outcome> from_before = sweep(true), from_after = sweep(false);
  // A frame with a pose on one side only (before the first pose, after the last): the second
  // opinion is a solve from PnP + RANSAC, which needs no start. Not on a young map (the rule
  // of IsYoungMap): its few keyframes' points hold where they were seen from, not further.
  const bool one_sided = map.keyframes().size() > static_cast<size_t>(kSmallMapKeyframes);
  bool seen_posed = false;
  std::vector<bool> before_any(r.size(), false), after_all(r.size(), false);
  for (size_t i = 0; i < r.size(); ++i) {
    seen_posed = seen_posed || posed(i).has_value();
    before_any[i] = !seen_posed;
  }
  seen_posed = false;
  for (size_t k = r.size(); k-- > 0;) {
    seen_posed = seen_posed || posed(k).has_value();
    after_all[k] = !seen_posed;
  }
  auto from_pnp = [&](size_t i) -> Outcome {
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> uvs;
    std::vector<double> uncertainties;
    if (!observations(i, &points, &uvs, &uncertainties)) return {};
    std::vector<int> ransac;
    const std::optional<Pose3> start = tracker_internal::PnpRansac(
        model.camera, kUnposedPnpThresholdSigmas * model.pixel_sigma, points, uvs, &ransac);
    if (!start) return {};
    return solve_on(points, uvs, uncertainties, Solved{start->Inverse(), 0, 0.0});
  };
  int solved = 0;
  for (size_t i = 0; i < r.size(); ++i) {
    Outcome a = from_before[i];
    Outcome b = from_after[i];
    if (one_sided && before_any[i] && b.pose && unposed(i)) {
      a = from_pnp(i);
      a.diverged = false;
    } else if (one_sided && after_all[i] && a.pose && unposed(i)) {
      b = from_pnp(i);
      b.diverged = false;
    }
    // Both sides must find the same pose: a view its points leave ambiguous (a few of them at
    // its edge) converges to wherever its start lies. A side that diverged has no say.
    // The sweep's pose (its reference keyframe is the posed frame it came from).
    const std::optional<Solved>& pose = before_any[i] ? b.pose : a.pose ? a.pose : b.pose;
    if (!pose || (!a.pose && !a.diverged) || (!b.pose && !b.diverged)) continue;
    if (a.pose && b.pose) {
      const double apart =
          (a.pose->world_from_camera.translation() - b.pose->world_from_camera.translation())
              .norm();
      const double turned = a.pose->world_from_camera.rotation().angularDistance(
          b.pose->world_from_camera.rotation());
      if (!(apart <= kUnposedAgreement * a.pose->depth) || !(turned <= kUnposedAgreementRad))
        continue;
    }
    const std::optional<Pose3> reference = map.ResolveKeyframePose(pose->reference);
    if (!reference) continue;
    TrajectoryRecord& record = r[i];
    record.state = TrackingState::kOk;
    record.map_id = map_id;
    record.reference = pose->reference;
    record.world_from_camera = pose->world_from_camera;
    record.reference_from_camera = reference->Inverse() * pose->world_from_camera;
    ++solved;
  }
  return solved;
}

}  // namespace m2s::slam
