// SmoothLooseFrames (trajectory_refinement.h): loosely determined frames fused with the centre
// interpolated between the well-determined frames around them, and frames without a pose whose
// points fix only their rotation given that centre (docs/design/map_refinement.md).
#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "m2s/common/numeric.h"
#include "mapping/triangulation.h"
#include "system/refinement_internal.h"
#include "system/trajectory_refinement.h"
#include "tracking/motion_uncertainty.h"
#include "tracking/rotation_only.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {

using refinement_internal::ExactData;
using refinement_internal::MappedObservations;
using refinement_internal::RecordPose;

namespace {

// SmoothLooseFrames: a frame of the map with a pose, or one without a pose whose map points
// may give it one (`unposed`: loose, its pose still to find); an anchor is a keyframe without
// observations or a frame whose points determine its centre; a loose frame carries what the
// fusion needs.
struct PosedFrame {
  size_t index = 0;  // into the records
  double t = 0.0;
  Pose3 world_from_camera;
  bool anchor = false;
  bool loose = false;
  bool unposed = false;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // of the points' centre
  std::vector<Eigen::Vector3d> points;                   // observations fitting the pose
  std::vector<Eigen::Vector2d> uvs;
};

Eigen::Vector3d Centre(const PosedFrame& f) { return f.world_from_camera.translation(); }

// The centre at time `t` on the line through the centres of `a` and `c` (linear in time).
Eigen::Vector3d CentreAt(const PosedFrame& a, const PosedFrame& c, double t) {
  return Centre(a) + (Centre(c) - Centre(a)) * ((t - a.t) / (c.t - a.t));
}

// The frames of map `map_id` with a pose, in the records' order, classified. Rotation-only
// frames (no observations, their centre not measured) are left out.
std::vector<PosedFrame> PosedFrames(const MeasurementModel& model, const MapData& map, int map_id,
                                    int max_points, const std::vector<TrajectoryRecord>& r) {
  std::vector<PosedFrame> frames;
  for (size_t i = 0; i < r.size(); ++i) {
    if (!HasPose(r[i].state) && !r[i].observed_ids.empty()) {
      PosedFrame f;
      f.index = i;
      f.t = r[i].timestamp;
      f.loose = f.unposed = true;
      MappedObservations(map, r[i], &f.points, &f.uvs);
      if (f.points.size() >= static_cast<size_t>(tracker_internal::kMinRotationOnlyInliers))
        frames.push_back(std::move(f));
      continue;
    }
    const std::optional<Pose3> pose = RecordPose(map, map_id, r[i]);
    if (!pose) continue;
    PosedFrame f;
    f.index = i;
    f.t = r[i].timestamp;
    f.world_from_camera = *pose;
    if (r[i].observed_ids.empty()) {
      if (r[i].is_keyframe) {  // the initial map's keyframes
        f.anchor = true;
        frames.push_back(std::move(f));
      }
      continue;
    }
    // The frame's observations that fit its pose (tracking's chi-square bound).
    const Pose3 camera_from_world = f.world_from_camera.Inverse();
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> uvs;
    MappedObservations(map, r[i], &points, &uvs);
    const double max_err_sq = kChi2TwoDof95 * model.pixel_sigma * model.pixel_sigma;
    double squared_error = 0.0;
    for (size_t k = 0; k < points.size(); ++k) {
      const Eigen::Vector3d pc = camera_from_world * points[k];
      if (!(pc.z() > 0.0)) continue;
      const double err_sq = (model.camera.Project(pc) - uvs[k]).squaredNorm();
      if (err_sq > max_err_sq) continue;
      f.points.push_back(points[k]);
      f.uvs.push_back(uvs[k]);
      squared_error += err_sq;
    }
    if (f.points.size() < static_cast<size_t>(tracker_internal::kMinTrackedInliers)) continue;
    std::vector<size_t> all(f.points.size());
    std::iota(all.begin(), all.end(), size_t{0});
    const std::optional<ViewCentreUncertainty> u = CentreUncertaintyOfView(
        model.camera, model.pixel_sigma, camera_from_world, f.points, all, max_points);
    if (!u) continue;
    // Exact data (the residuals far below the model's noise): the points' centre stands.
    f.loose = u->sigma > kLooseCentreSigmaFraction * u->median_depth &&
              !ExactData(model, squared_error, f.points.size());
    f.anchor = !f.loose;
    f.covariance = u->covariance;
    frames.push_back(std::move(f));
  }
  return frames;
}

// The centre of frames[k] from the anchors around it: interpolated between the nearest one on
// either side (each within kSmoothingMaxSpanS), or, at the end of a stretch, extrapolated
// from the two nearest on one side (consecutive). With it, how many times the deviation of an
// interpolation over consecutive frames its own deviation is: half the span in frames when
// interpolated, twice the distance in frames when extrapolated. nullopt without anchors.
std::optional<std::pair<Eigen::Vector3d, double>> CentreFromAnchors(
    const std::vector<PosedFrame>& frames, size_t k, double interval) {
  const PosedFrame& f = frames[k];
  size_t before = k, after = k;  // the stretch of frames without an anchor around k
  while (before > 0 && !frames[before - 1].anchor) --before;
  while (after + 1 < frames.size() && !frames[after + 1].anchor) ++after;
  const bool has_before = before >= 1 && f.t - frames[before - 1].t <= kSmoothingMaxSpanS;
  const bool has_after =
      after + 1 < frames.size() && frames[after + 1].t - f.t <= kSmoothingMaxSpanS;
  if (has_before && has_after) {
    const PosedFrame &a = frames[before - 1], &c = frames[after + 1];
    return std::pair{CentreAt(a, c, f.t), std::max(1.0, 0.5 * (c.t - a.t) / interval)};
  }
  // The nearest anchor before (after) frames[i], consecutive to it.
  auto previous_anchor = [&](size_t i) -> std::optional<size_t> {
    for (size_t j = i; j-- > 0 && frames[i].t - frames[j].t <= kSmoothingConsecutiveS;) {
      if (frames[j].anchor) return j;
    }
    return std::nullopt;
  };
  auto next_anchor = [&](size_t i) -> std::optional<size_t> {
    for (size_t j = i + 1; j < frames.size() && frames[j].t - frames[i].t <= kSmoothingConsecutiveS;
         ++j) {
      if (frames[j].anchor) return j;
    }
    return std::nullopt;
  };
  if (has_before) {
    const PosedFrame& b = frames[before - 1];
    const std::optional<size_t> a = previous_anchor(before - 1);
    if (!a) return std::nullopt;
    return std::pair{CentreAt(frames[*a], b, f.t), 2.0 * std::max(1.0, (f.t - b.t) / interval)};
  }
  if (has_after) {
    const PosedFrame& b = frames[after + 1];
    const std::optional<size_t> c = next_anchor(after + 1);
    if (!c) return std::nullopt;
    return std::pair{CentreAt(b, frames[*c], f.t), 2.0 * std::max(1.0, (b.t - f.t) / interval)};
  }
  return std::nullopt;
}

// How far the anchors within kSmoothingWindowS of time `t` lie from the interpolation
// between the anchors `span` apart around them (the nearest at least half of it before and
// after, at most 1.5 times it apart), RMS: the error of an interpolation over that span,
// the motion's curvature and the anchors' noise included. nullopt with fewer than
// kSmoothingMinSamples such anchors.
// `anchors`: the indices of the anchors in `frames`, in time order.
std::optional<double> InterpolationDeviation(const std::vector<PosedFrame>& frames,
                                             const std::vector<size_t>& anchors, double t,
                                             double span) {
  double sum = 0.0;
  int n = 0;
  const auto first = std::lower_bound(anchors.begin(), anchors.end(), t - kSmoothingWindowS,
                                      [&](size_t j, double time) { return frames[j].t < time; });
  for (size_t m = static_cast<size_t>(first - anchors.begin()); m < anchors.size(); ++m) {
    const PosedFrame& b = frames[anchors[m]];
    if (b.t - t > kSmoothingWindowS) break;
    std::optional<size_t> a, c;
    for (size_t j = m; j-- > 0;) {
      if (b.t - frames[anchors[j]].t >= 0.5 * span) {
        a = anchors[j];
        break;
      }
    }
    for (size_t j = m + 1; j < anchors.size(); ++j) {
      if (frames[anchors[j]].t - b.t >= 0.5 * span) {
        c = anchors[j];
        break;
      }
    }
    if (!a || !c || frames[*c].t - frames[*a].t > 1.5 * span) continue;
    sum += (Centre(b) - CentreAt(frames[*a], frames[*c], b.t)).squaredNorm();
    ++n;
  }
  if (n < kSmoothingMinSamples) return std::nullopt;
  return std::sqrt(sum / n);
}

// Gives the frame without a pose frames[k] the centre `centre` (the anchors', whose deviation
// is `sigma`) and the rotation its map points fit there, when the prior's deviation is within
// kUnposedPriorSigmaFraction of the points' median depth and the rotation explains most of
// them (tracking's sparse-view rule; each point's bound widened by the prior's deviation seen
// from its depth), and they are at least tracking's bound for a rotation-only pose
// (kMinRotationOnlyInliers: the centre given, three degrees of freedom). Its reference
// keyframe is the nearest posed frame's.
bool PoseAtPrior(const MeasurementModel& model, const MapData& map,
                 const std::vector<PosedFrame>& frames, size_t k, const Eigen::Vector3d& centre,
                 double sigma, std::vector<TrajectoryRecord>* records) {
  const PosedFrame& f = frames[k];
  std::optional<Pose3> pose = PoseAtCentre(model.camera, centre, f.points, f.uvs);
  if (!pose) return false;
  // Once more on the observations that fit the first fit (the wrong ids out).
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  for (size_t i = 0; i < f.points.size(); ++i) {
    const double depth = (*pose * f.points[i]).z();
    const double prior_px = model.camera.fx * sigma / std::max(depth, 1e-9);
    const double max_err_sq =
        kChi2TwoDof95 * (model.pixel_sigma * model.pixel_sigma + prior_px * prior_px);
    if (ReprojectionErrorSq(model.camera, *pose, f.points[i], f.uvs[i]) > max_err_sq) continue;
    points.push_back(f.points[i]);
    uvs.push_back(f.uvs[i]);
  }
  if (points.size() < static_cast<size_t>(tracker_internal::kMinRotationOnlyInliers) ||
      points.size() <
          tracker_internal::kSparseViewInlierFraction * static_cast<double>(f.points.size())) {
    return false;
  }
  pose = PoseAtCentre(model.camera, centre, points, uvs);
  if (!pose || !(sigma <= kUnposedPriorSigmaFraction * MedianDepth(*pose, points))) return false;
  // The nearest frame with a pose (before it first) lends its reference keyframe.
  const TrajectoryRecord* neighbour = nullptr;
  for (size_t step = 1; neighbour == nullptr && step < frames.size(); ++step) {
    for (const size_t j : {k - step, k + step}) {
      if (j < frames.size() && !frames[j].unposed) {
        neighbour = &(*records)[frames[j].index];
        break;
      }
    }
  }
  if (neighbour == nullptr) return false;
  const std::optional<Pose3> reference = map.ResolveKeyframePose(*neighbour->reference);
  if (!reference) return false;
  TrajectoryRecord& record = (*records)[f.index];
  record.state = TrackingState::kOk;
  record.map_id = neighbour->map_id;
  record.reference = neighbour->reference;
  record.world_from_camera = pose->Inverse();
  record.reference_from_camera = reference->Inverse() * pose->Inverse();
  return true;
}

}  // namespace

SmoothedFrames SmoothLooseFrames(const MeasurementModel& model, const MapData& map, int map_id,
                                 int max_points, std::vector<TrajectoryRecord>* records) {
  const std::vector<PosedFrame> frames = PosedFrames(model, map, map_id, max_points, *records);
  // How far an anchor lies from the interpolation of the anchors on either side of it, over
  // consecutive frames: the motion's smoothness at the map's scale, pose noise included.
  std::vector<std::pair<double, double>> deviation;  // (time, squared deviation)
  std::vector<size_t> posed, anchors;                // indices into `frames`
  for (size_t k = 0; k < frames.size(); ++k) {
    if (!frames[k].unposed) posed.push_back(k);
    if (frames[k].anchor) anchors.push_back(k);
  }
  for (size_t k = 1; k + 1 < posed.size(); ++k) {
    const PosedFrame &a = frames[posed[k - 1]], &b = frames[posed[k]], &c = frames[posed[k + 1]];
    if (!a.anchor || !b.anchor || !c.anchor || !(c.t > a.t)) continue;
    if (c.t - a.t > kSmoothingConsecutiveS) continue;
    deviation.emplace_back(b.t, (Centre(b) - CentreAt(a, c, b.t)).squaredNorm());
  }
  // The frame interval: the median time between consecutive frames with a pose.
  std::vector<double> intervals;
  for (size_t k = 1; k < posed.size(); ++k) {
    const double dt = frames[posed[k]].t - frames[posed[k - 1]].t;
    if (dt > 0.0) intervals.push_back(dt);
  }
  if (intervals.empty()) return {};
  std::nth_element(intervals.begin(), intervals.begin() + intervals.size() / 2, intervals.end());
  const double interval = intervals[intervals.size() / 2];
  SmoothedFrames out;
  for (size_t k = 0; k < frames.size(); ++k) {
    const PosedFrame& f = frames[k];
    if (!f.loose || f.unposed) continue;
    const auto prior = CentreFromAnchors(frames, k, interval);
    if (!prior) continue;
    double sum = 0.0;
    int n = 0;
    for (const auto& [t, d2] : deviation) {
      if (std::abs(t - f.t) <= kSmoothingWindowS) {
        sum += d2;
        ++n;
      }
    }
    if (n < kSmoothingMinSamples) continue;
    const double sigma = std::sqrt(sum / n) * prior->second;
    // The two centres fused by their information.
    const Eigen::Matrix3d points_information = f.covariance.inverse();
    const Eigen::Matrix3d prior_information =
        Eigen::Matrix3d::Identity() / std::max(sigma * sigma, 1e-18);
    const Eigen::Vector3d fused =
        (points_information + prior_information)
            .ldlt()
            .solve(points_information * Centre(f) + prior_information * prior->first);
    if (!fused.allFinite()) continue;
    const std::optional<Pose3> pose = PoseAtCentre(model.camera, fused, f.points, f.uvs);
    if (!pose) continue;
    TrajectoryRecord& record = (*records)[f.index];
    const std::optional<Pose3> reference = map.ResolveKeyframePose(*record.reference);
    record.reference_from_camera = reference->Inverse() * pose->Inverse();
    ++out.smoothed;
  }
  // Frames without a pose: only between anchors, the prior's deviation measured at their span.
  for (size_t k = 0; k < frames.size(); ++k) {
    const PosedFrame& f = frames[k];
    if (!f.unposed) continue;
    std::optional<size_t> a, c;
    for (size_t j = k; j-- > 0 && f.t - frames[j].t <= kSmoothingMaxSpanS;) {
      if (frames[j].anchor) {
        a = j;
        break;
      }
    }
    for (size_t j = k + 1; j < frames.size() && frames[j].t - f.t <= kSmoothingMaxSpanS; ++j) {
      if (frames[j].anchor) {
        c = j;
        break;
      }
    }
    if (!a || !c) continue;
    const std::optional<double> sigma =
        InterpolationDeviation(frames, anchors, f.t, frames[*c].t - frames[*a].t);
    if (!sigma) continue;
    const Eigen::Vector3d centre = CentreAt(frames[*a], frames[*c], f.t);
    if (PoseAtPrior(model, map, frames, k, centre, *sigma, records)) ++out.posed;
  }
  return out;
}

}  // namespace m2s::slam
