// ApplyMotionPrior (trajectory_refinement.h): the map's frames smoothed jointly under a prior
// on the camera's acceleration (OptimizeTrajectory), the pixel noise estimated from their
// residuals (docs/design/map_refinement.md).
#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>
#include <utility>

#include "m2s/common/numeric.h"
#include "mapping/triangulation.h"
#include "optimization/problems.h"
#include "system/refinement_internal.h"
#include "system/trajectory_refinement.h"
#include "tracking/motion_uncertainty.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {

using refinement_internal::MappedObservations;
using refinement_internal::RecordPose;

namespace {

// The median of a chi-square variable with 2 degrees of freedom truncated at its 95 %
// quantile (the observations within tracking's bound): its 47.5 % quantile, -2 ln(0.525).
const double kGatedChi2TwoDofMedian = -2.0 * std::log(1.0 - 0.5 * 0.95);

// How many of `frame`'s observations `camera_from_world` explains within `max_err_sq`.
size_t Explained(const Camera& camera, const Pose3& camera_from_world, const TrajectoryFrame& frame,
                 double max_err_sq) {
  size_t n = 0;
  for (size_t k = 0; k < frame.points_world.size(); ++k) {
    if (ReprojectionErrorSq(camera, camera_from_world, frame.points_world[k],
                            frame.observations_uv[k]) <= max_err_sq) {
      ++n;
    }
  }
  return n;
}

}  // namespace

MotionPriorResult ApplyMotionPrior(const MeasurementModel& model, const MapData& map, int map_id,
                                   int max_points, double acceleration_sigma,
                                   std::vector<TrajectoryRecord>* records) {
  MotionPriorResult out;
  if (!(acceleration_sigma > 0.0) || !std::isfinite(acceleration_sigma)) return out;
  // Each frame with a pose in the map, on its observations within tracking's bound, or held.
  const double max_err_sq = kChi2TwoDof95 * model.pixel_sigma * model.pixel_sigma;
  std::vector<TrajectoryFrame> frames;
  std::vector<size_t> index;  // into the records, per frame
  std::vector<double> squared_errors;
  for (size_t i = 0; i < records->size(); ++i) {
    const TrajectoryRecord& r = (*records)[i];
    const std::optional<Pose3> pose = RecordPose(map, map_id, r);
    if (!pose || (!frames.empty() && !(r.timestamp > frames.back().t))) continue;
    TrajectoryFrame f;
    f.t = r.timestamp;
    f.camera_from_world = pose->Inverse();
    // A keyframe's record at its keyframe (RefineFramePose left it): the pose the bundle
    // adjustment gave it jointly with the map, held as an anchor of the prior.
    f.fixed = r.is_keyframe && r.reference_from_camera.translation().isZero(0.0) &&
              r.reference_from_camera.rotation().vec().isZero(0.0);
    if (!f.fixed) {
      std::vector<Eigen::Vector3d> points;
      std::vector<Eigen::Vector2d> uvs;
      MappedObservations(map, r, &points, &uvs);
      for (size_t k = 0; k < points.size(); ++k) {
        const double err_sq =
            ReprojectionErrorSq(model.camera, f.camera_from_world, points[k], uvs[k]);
        if (!(err_sq <= max_err_sq)) continue;
        f.points_world.push_back(points[k]);
        f.observations_uv.push_back(uvs[k]);
        squared_errors.push_back(err_sq);
      }
      if (f.points_world.size() < static_cast<size_t>(kMotionPriorMinPoints)) {
        squared_errors.resize(squared_errors.size() - f.points_world.size());
        continue;
      }
      // A loosely determined frame (SmoothLooseFrames' rule) stays as that step left it: its
      // points leave a valley the prior alone does not close (a stretch of such frames may
      // drift along it at constant velocity).
      std::vector<size_t> all(f.points_world.size());
      std::iota(all.begin(), all.end(), size_t{0});
      const std::optional<ViewCentreUncertainty> u = CentreUncertaintyOfView(
          model.camera, model.pixel_sigma, f.camera_from_world, f.points_world, all, max_points);
      if (!u || u->sigma > kLooseCentreSigmaFraction * u->median_depth) {
        squared_errors.resize(squared_errors.size() - f.points_world.size());
        continue;
      }
    }
    frames.push_back(std::move(f));
    index.push_back(i);
  }
  if (frames.size() < 3 || squared_errors.empty()) return out;
  // The pixel noise the observations show (robust: their median squared error).
  auto middle = squared_errors.begin() + static_cast<std::ptrdiff_t>(squared_errors.size() / 2);
  std::nth_element(squared_errors.begin(), middle, squared_errors.end());
  out.pixel_sigma = std::sqrt(*middle / kGatedChi2TwoDofMedian);
  // Exact data: the frames' own points fix them better than any prior on the motion.
  if (out.pixel_sigma * out.pixel_sigma <
      kExactDataVarianceFactor * model.pixel_sigma * model.pixel_sigma) {
    return out;
  }
  std::vector<Pose3> before;
  before.reserve(frames.size());
  for (const TrajectoryFrame& f : frames) before.push_back(f.camera_from_world);
  TrajectoryOptions options;
  options.pixel_sigma = out.pixel_sigma;
  options.acceleration_sigma = acceleration_sigma;
  options.max_gap_s = kSmoothingConsecutiveS;
  const TrajectoryResult result = OptimizeTrajectory(model.camera, options, &frames);
  if (!result.success) return out;
  for (size_t j = 0; j < frames.size(); ++j) {
    // A frame takes its smoothed pose while that still explains most of its observations
    // (tracking's sparse-view rule) within the bound.
    const TrajectoryFrame& f = frames[j];
    if (f.fixed) continue;
    if (static_cast<double>(Explained(model.camera, f.camera_from_world, f, max_err_sq)) <
        tracker_internal::kSparseViewInlierFraction *
            static_cast<double>(Explained(model.camera, before[j], f, max_err_sq))) {
      ++out.kept;
      continue;
    }
    TrajectoryRecord& record = (*records)[index[j]];
    const std::optional<Pose3> reference = map.ResolveKeyframePose(*record.reference);
    record.reference_from_camera = reference->Inverse() * f.camera_from_world.Inverse();
    ++out.smoothed;
  }
  return out;
}

}  // namespace m2s::slam
