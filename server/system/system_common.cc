#include "system/system_common.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <unordered_map>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "m2s/common/numeric.h"
#include "tracking/motion_uncertainty.h"
#include "tracking/rotation_only.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {

MapAlignmentOptions MergeAlignmentOptions(const Options& options) {
  MapAlignmentOptions align;
  align.min_shared_points = options.multi_map.merge_min_shared_points;
  align.min_inlier_fraction = options.multi_map.merge_min_inlier_fraction;
  align.camera = options.camera;
  align.max_image_error_px = kMergeImageErrorSigmas * options.pixel_sigma;
  align.min_image_agreement = kMergeMinImageAgreement;
  return align;
}

bool TakeFrame(const Frame& frame, bool shut_down, int feature_budget, const FeatureGrid& grid,
               FrameValidator* validator, SortedFeatures* features, TrackResult* result,
               SystemStats* stats) {
  result->seq = frame.seq;
  result->timestamp = frame.timestamp;
  result->num_features = static_cast<int>(frame.features.size());
  if (shut_down) {
    result->state = TrackingState::kRejected;
    result->reject_reason = "shut_down";
    return false;
  }
  ++stats->frames_processed;
  if (const Status valid = validator->Validate(frame, features); !valid) {
    const char* reason = ToString(*valid.reason());
    result->state = TrackingState::kRejected;
    result->reject_reason = reason;
    ++stats->frames_rejected;
    ++stats->rejected_by_reason[reason];
    return false;
  }
  stats->features_over_budget +=
      static_cast<int64_t>(ApplyFeatureBudget(feature_budget, grid, features));
  return true;
}

void MoveRecord(const Sim3& new_from_old, int new_map_id, TrajectoryRecord* record) {
  record->world_from_camera = new_from_old.TransformPose(record->world_from_camera);
  // A relative pose keeps its rotation; its translation takes the scale.
  record->reference_from_camera =
      Pose3(record->reference_from_camera.rotation(),
            new_from_old.scale() * record->reference_from_camera.translation());
  record->map_id = new_map_id;
}

InitialFramesMarked MarkInitialFrames(const InitialMap& initial, KeyframeId first,
                                      KeyframeId second, int map_id, int kept,
                                      std::vector<TrajectoryRecord>* records) {
  std::unordered_map<int64_t, const InitialInbetween*> inbetween;
  for (const InitialInbetween& f : initial.inbetween) inbetween.emplace(f.seq, &f);
  InitialFramesMarked marked;
  for (TrajectoryRecord& r : *records) {
    const bool is_first = r.seq == initial.first.seq;
    const bool is_second = r.seq == initial.second.seq;
    const auto it = is_first || is_second ? inbetween.end() : inbetween.find(r.seq);
    if (!is_first && !is_second && it == inbetween.end()) continue;
    if (!is_first && HasPose(r.state)) continue;  // a pose in another map already
    ++marked.marked;
    marked.was_lost += r.state == TrackingState::kLost ? 1 : 0;
    r.state = TrackingState::kOk;
    r.reference = is_second ? second : first;
    r.map_id = map_id;
    if (is_first || is_second) {
      r.reference_from_camera = Pose3::Identity();
      r.world_from_camera =
          is_first ? initial.first.world_from_camera : initial.second.world_from_camera;
      r.is_keyframe = true;
      continue;
    }
    // The first keyframe is the initial map's world.
    const InitialInbetween& f = *it->second;
    r.world_from_camera = f.world_from_camera;
    r.reference_from_camera = f.world_from_camera;
    if (kept <= 0) continue;
    const std::vector<size_t> keep =
        EvenlySpacedIndices(f.observed_ids.size(), static_cast<size_t>(kept));
    r.observed_ids.clear();
    r.observed_uvs.clear();
    for (const size_t i : keep) {
      r.observed_ids.push_back(f.observed_ids[i]);
      r.observed_uvs.push_back(f.observed_uvs[i].cast<float>());
    }
  }
  return marked;
}

void StartTracking(const InitialMap& initial, KeyframeId second, double timestamp,
                   Tracker* tracker) {
  tracker->Start(second, initial.second.world_from_camera, static_cast<int>(initial.points.size()),
                 timestamp,
                 MedianDepth(initial.second.world_from_camera.Inverse(), initial.points));
}

TrajectoryEntry ToEntry(const TrajectoryRecord& record, const MapData* map) {
  TrajectoryEntry e;
  e.seq = record.seq;
  e.timestamp = record.timestamp;
  e.state = record.state;
  e.world_from_camera = record.world_from_camera;
  if (record.reference && map != nullptr) {
    if (auto ref = map->ResolveKeyframePose(*record.reference))
      e.world_from_camera = *ref * record.reference_from_camera;
  }
  e.is_keyframe = record.is_keyframe;
  e.ground_truth_world_from_camera = record.ground_truth;
  e.map_id = record.map_id;
  return e;
}

void KeepObservations(const std::vector<VertexId>& ids, const std::vector<Eigen::Vector2d>& uvs,
                      int kept, TrajectoryRecord* record) {
  if (kept <= 0) return;  // EvenlySpacedIndices reads 0 as "every one"
  const std::vector<size_t> keep = EvenlySpacedIndices(ids.size(), static_cast<size_t>(kept));
  record->observed_ids.reserve(keep.size());
  record->observed_uvs.reserve(keep.size());
  for (const size_t i : keep) {
    record->observed_ids.push_back(ids[i]);
    record->observed_uvs.push_back(uvs[i].cast<float>());
  }
}

bool RefineFramePose(const MeasurementModel& model, const MapData& map, TrajectoryRecord* record) {
  if (!HasPose(record->state) || record->is_keyframe || !record->reference) return false;
  const std::optional<Pose3> reference = map.ResolveKeyframePose(*record->reference);
  if (!reference) return false;
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  for (size_t i = 0; i < record->observed_ids.size(); ++i) {
    const MapPoint* p = map.point(record->observed_ids[i]);
    if (p == nullptr || p->observers.empty()) continue;
    points.push_back(p->position);
    uvs.push_back(record->observed_uvs[i].cast<double>());
  }
  if (points.size() < static_cast<size_t>(tracker_internal::kMinTrackedInliers)) return false;
  Pose3 solved = (*reference * record->reference_from_camera).Inverse();
  const PoseOnlyResult r =
      OptimizePose(model.camera, tracker_internal::MakePoseOptions(model), points, uvs, &solved);
  // As tracking asks of a sparse view: most of the observations explained.
  if (!r.converged || !solved.AllFinite() ||
      r.num_inliers <
          tracker_internal::kSparseViewInlierFraction * static_cast<double>(points.size())) {
    return false;
  }
  record->reference_from_camera = reference->Inverse() * solved.Inverse();
  return true;
}

namespace {

// SolveUnposedFrames: a pose solved without a motion prior must have its centre determined to
// this fraction of the median depth, and the poses solved from either side must agree within
// it and this angle.
constexpr double kUnposedAgreement = 0.01;
constexpr double kUnposedAgreementRad = M_PI / 180.0;

// The record's observations that are points of `map`.
void MappedObservations(const MapData& map, const TrajectoryRecord& record,
                        std::vector<Eigen::Vector3d>* points, std::vector<Eigen::Vector2d>* uvs) {
  for (size_t i = 0; i < record.observed_ids.size(); ++i) {
    const MapPoint* p = map.point(record.observed_ids[i]);
    if (p == nullptr || p->observers.empty()) continue;
    points->push_back(p->position);
    uvs->push_back(record.observed_uvs[i].cast<double>());
  }
}

}  // namespace

int SolveUnposedFrames(const MeasurementModel& model, const MapData& map, int map_id,
                       int min_points, std::vector<TrajectoryRecord>* records) {
  std::vector<TrajectoryRecord>& r = *records;
  struct Solved {
    Pose3 world_from_camera;
    KeyframeId reference = 0;  // of the posed frame the sweep came from
    double depth = 0.0;        // the inliers' median depth
  };
  // Solves r[i] from `start`.
  auto solve = [&](size_t i, const Solved& start) -> std::optional<Solved> {
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> uvs;
    MappedObservations(map, r[i], &points, &uvs);
    if (points.size() < static_cast<size_t>(std::max(min_points, 1))) return std::nullopt;
    Pose3 camera_from_world = start.world_from_camera.Inverse();
    const PoseOnlyResult result = OptimizePose(
        model.camera, tracker_internal::MakePoseOptions(model), points, uvs, &camera_from_world);
    if (!result.converged || !camera_from_world.AllFinite() ||
        result.num_inliers <
            tracker_internal::kSparseViewInlierFraction * static_cast<double>(points.size())) {
      return std::nullopt;
    }
    std::vector<Eigen::Vector3d> inliers;
    for (size_t k = 0; k < points.size(); ++k) {
      if (result.inlier[k]) inliers.push_back(points[k]);
    }
    const double depth = MedianDepth(camera_from_world, inliers);
    if (!(PoseCentreSigma(model.camera, model.pixel_sigma, camera_from_world, inliers) <=
          kUnposedAgreement * depth)) {
      return std::nullopt;
    }
    return Solved{camera_from_world.Inverse(), start.reference, depth};
  };
  auto posed = [&](size_t i) -> std::optional<Solved> {
    if (!HasPose(r[i].state) || r[i].map_id != map_id || !r[i].reference) return std::nullopt;
    const std::optional<Pose3> reference = map.ResolveKeyframePose(*r[i].reference);
    if (!reference) return std::nullopt;
    return Solved{*reference * r[i].reference_from_camera, *r[i].reference, 0.0};
  };
  auto unposed = [&](size_t i) { return !HasPose(r[i].state) && !r[i].observed_ids.empty(); };
  // One sweep in each direction, each solved frame starting the next.
  auto sweep = [&](bool forward) {
    std::vector<std::optional<Solved>> out(r.size());
    std::optional<Solved> last;
    for (size_t k = 0; k < r.size(); ++k) {
      const size_t i = forward ? k : r.size() - 1 - k;
      if (std::optional<Solved> p = posed(i)) {
        last = p;
      } else if (last && unposed(i)) {
        out[i] = solve(i, *last);
        if (out[i]) last = out[i];
      }
    }
    return out;
  };
  const std::vector<std::optional<Solved>> from_before = sweep(true), from_after = sweep(false);
  int solved = 0;
  for (size_t i = 0; i < r.size(); ++i) {
    const std::optional<Solved>& a = from_before[i];
    const std::optional<Solved>& b = from_after[i];
    // Both sides must find the same pose: a view its points leave ambiguous (a few of them at
    // its edge) converges to wherever its start lies.
    if (!a || !b) continue;
    const double apart =
        (a->world_from_camera.translation() - b->world_from_camera.translation()).norm();
    const double turned =
        a->world_from_camera.rotation().angularDistance(b->world_from_camera.rotation());
    if (!(apart <= kUnposedAgreement * a->depth) || !(turned <= kUnposedAgreementRad)) continue;
    const std::optional<Pose3> reference = map.ResolveKeyframePose(a->reference);
    if (!reference) continue;
    TrajectoryRecord& record = r[i];
    record.state = TrackingState::kOk;
    record.map_id = map_id;
    record.reference = a->reference;
    record.world_from_camera = a->world_from_camera;
    record.reference_from_camera = reference->Inverse() * a->world_from_camera;
    ++solved;
  }
  return solved;
}

namespace {

// SmoothLooseFrames: a frame of the map with a pose; an anchor is a keyframe without
// observations or a frame whose points determine its centre; a loose frame carries what the
// fusion needs.
struct PosedFrame {
  size_t index = 0;  // into the records
  double t = 0.0;
  Pose3 world_from_camera;
  bool anchor = false;
  bool loose = false;
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
    if (!HasPose(r[i].state) || r[i].map_id != map_id || !r[i].reference) continue;
    const std::optional<Pose3> reference = map.ResolveKeyframePose(*r[i].reference);
    if (!reference) continue;
    PosedFrame f;
    f.index = i;
    f.t = r[i].timestamp;
    f.world_from_camera = *reference * r[i].reference_from_camera;
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
    const double variance_factor =
        squared_error / (model.pixel_sigma * model.pixel_sigma *
                         std::max(1.0, 2.0 * static_cast<double>(f.points.size()) - 6.0));
    f.loose = u->sigma > kLooseCentreSigmaFraction * u->median_depth &&
              variance_factor >= kExactDataVarianceFactor;
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

}  // namespace

int SmoothLooseFrames(const MeasurementModel& model, const MapData& map, int map_id, int max_points,
                      std::vector<TrajectoryRecord>* records) {
  const std::vector<PosedFrame> frames = PosedFrames(model, map, map_id, max_points, *records);
  // How far an anchor lies from the interpolation of the anchors on either side of it, over
  // consecutive frames: the motion's smoothness at the map's scale, pose noise included.
  std::vector<std::pair<double, double>> deviation;  // (time, squared deviation)
  for (size_t k = 1; k + 1 < frames.size(); ++k) {
    const PosedFrame &a = frames[k - 1], &b = frames[k], &c = frames[k + 1];
    if (!a.anchor || !b.anchor || !c.anchor || !(c.t > a.t)) continue;
    if (c.t - a.t > kSmoothingConsecutiveS) continue;
    deviation.emplace_back(b.t, (Centre(b) - CentreAt(a, c, b.t)).squaredNorm());
  }
  // The frame interval: the median time between consecutive frames with a pose.
  std::vector<double> intervals;
  for (size_t k = 1; k < frames.size(); ++k) {
    if (frames[k].t > frames[k - 1].t) intervals.push_back(frames[k].t - frames[k - 1].t);
  }
  if (intervals.empty()) return 0;
  std::nth_element(intervals.begin(), intervals.begin() + intervals.size() / 2, intervals.end());
  const double interval = intervals[intervals.size() / 2];
  int smoothed = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    const PosedFrame& f = frames[k];
    if (!f.loose) continue;
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
    ++smoothed;
  }
  return smoothed;
}

}  // namespace m2s::slam
