// Initialiser internals shared by initializer.cc (two views) and more_views.cc (more views):
// the two views' bundle adjustment problem and its points, how far apart two motions are, and
// a view posed on known points.
#pragma once

#include <cstddef>
#include <optional>
#include <unordered_map>
#include <vector>

#include "m2s/slam/options.h"
#include "optimization/problems.h"
#include "tracking/frame_validation.h"

namespace m2s::slam::initializer_internal {

// Starts whose triangulation leaves more than this share of the points behind a view are
// skipped (a wrong sign, a wrong decomposition: StartLeavesTooMany), and so are starts this
// close (degrees of rotation and of translation direction) to one already adjusted (SameMotion).
inline constexpr double kMaxStartBehind = 0.2;
inline constexpr double kSameStartDeg = 0.5;
// Starts are compared on an even subset of at most this many of the shared features (an
// initialisation stalls tracking for the adjustments' time).
inline constexpr size_t kMaxStartPoints = 300;

// How far apart two motions are: degrees of rotation and of translation direction.
struct MotionDistance {
  double rotation_deg = 0.0;
  double direction_deg = 0.0;
};
MotionDistance DistanceBetween(const Pose3& a, const Pose3& b);
// Within kSameStartDeg of rotation and of translation direction.
bool SameMotion(const Pose3& a, const Pose3& b);

// The two-view bundle adjustment problem of an initialisation: view 0 fixed at the origin,
// view 1 at `camera1_from_camera0`, a point for each of `ids` (sorted, shared by the views) at
// `points` (camera 0; parallel to `ids`), or, with `points` empty, triangulated (DLT) with that
// motion and left out where it does not lie in front of both views.
BaProblem TwoViewProblem(const Camera& camera, const SortedFeatures& view0,
                         const SortedFeatures& view1, const Pose3& camera1_from_camera0,
                         const std::vector<VertexId>& ids,
                         const std::vector<Eigen::Vector3d>& points);

// Whether a start's triangulation of `num_ids` points (TwoViewProblem without points) left
// more than kMaxStartBehind of them out.
bool StartLeavesTooMany(const BaProblem& problem, size_t num_ids);

// The ids two views share, sorted: an even subset of at most `max_count` of them.
std::vector<VertexId> SharedIds(const SortedFeatures& a, const SortedFeatures& b, size_t max_count);

// The points of an adjusted two-view problem a map takes: none of their observations an
// outlier, finite, in front of both views.
void AdjustedPoints(const BaProblem& problem, const BundleAdjustmentResult& result,
                    std::vector<VertexId>* ids, std::vector<Eigen::Vector3d>* points);

// The bundle adjustment options of an initialisation.
BundleAdjustmentOptions TwoViewBaOptions(const MeasurementModel& model, int num_threads);

// A view posed on known points: the pose-only solve and, parallel to its observations
// (PoseOnlyResult::inlier), which feature of the view is which point.
struct PosedView {
  Pose3 camera_from_world;
  PoseOnlyResult result;
  std::vector<size_t> features;  // indices into the view
  std::vector<size_t> points;    // indices into the points
};
// Poses `view` on the points `positions` (world; `point_index` maps their ids to indices) it
// sees, from `start` (camera_from_world). nullopt when it sees fewer than `min_points` of them
// (a view of a few points at its edge fits a wrong pose under noise) or the solve fails.
std::optional<PosedView> PoseOnPoints(const MeasurementModel& model, const SortedFeatures& view,
                                      const std::unordered_map<VertexId, size_t>& point_index,
                                      const std::vector<Eigen::Vector3d>& positions,
                                      const Pose3& start, int min_points);

}  // namespace m2s::slam::initializer_internal
