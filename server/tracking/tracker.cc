#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "optimization/problems.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {

using tracker_internal::kMinOverrulingPoints;
using tracker_internal::kMinTrackedInliers;
using tracker_internal::kSparseViewInlierFraction;
using tracker_internal::MakePoseOptions;

namespace {

// Dormant points join tracking when the recent points' truncated cost at the joint pose exceeds
// their own optimum by at most chi2(6 dof, 99.9 %) plus this much per recent inlier (map noise
// in the recent points makes them fit their own pose a little better than the noise alone).
constexpr double kAgreementChi2 = kChi2SixDof999;
constexpr double kAgreementPerPoint = 0.5;
// SolvePoseFromPrior: a result under this fraction of the prior's inliers is retried, with
// this many classification rounds.
constexpr double kPriorInlierFraction = 0.97;
constexpr int kRetryRounds = 10;
// Below this fraction of the reference keyframe's points, a keyframe is made even when mapping
// is busy.
constexpr double kCriticalTrackedRatio = 0.5;
// Frames in a row a map point must outlie before its vertex counts as moved.
constexpr int kMovedPointFrames = 3;
// ... and reproject this many times the inlier bound away from its feature (a point triangulated
// over a short baseline outlies by a little, frame after frame; a moved vertex by far more).
constexpr double kMovedPointFactor = 4.0;
// Keyframes for unmapped features need some baseline (fraction of keyframe_baseline_ratio),
// or the same features would ask for a keyframe on every frame.
constexpr double kNewPointsBaselineFraction = 0.5;
// Camera speed for rotation-only tracking: measured over at least this long (s).
constexpr double kSpeedWindowS = 0.25;

}  // namespace

int SolvePoseFromPrior(const Camera& camera, const PoseOnlyOptions& options,
                       const std::vector<Eigen::Vector3d>& points_world,
                       const std::vector<Eigen::Vector2d>& uvs,
                       const Pose3& prior_camera_from_world, Pose3* camera_from_world) {
  const double max_err_sq = options.chi2_threshold * options.pixel_sigma * options.pixel_sigma;
  auto is_inlier = [&](const Pose3& pose, size_t i) {
    const Eigen::Vector3d pc = pose * points_world[i];
    return pc.z() > 0.0 && (camera.Project(pc) - uvs[i]).squaredNorm() <= max_err_sq;
  };
  auto inliers_at = [&](const Pose3& pose) {
    if (!pose.AllFinite()) return -1;
    int n = 0;
    for (size_t i = 0; i < points_world.size(); ++i) n += is_inlier(pose, i) ? 1 : 0;
    return n;
  };
  Pose3 best = prior_camera_from_world;
  // OptimizePose classifies every point at its final pose by the same chi-square bound.
  const PoseOnlyResult first = OptimizePose(camera, options, points_world, uvs, &best);
  int best_inliers = best.AllFinite() ? first.num_inliers : -1;
  const int prior_inliers = inliers_at(prior_camera_from_world);
  if (best_inliers >= kPriorInlierFraction * prior_inliers) {
    *camera_from_world = best;
    return best_inliers;
  }
  auto consider = [&](const Pose3& candidate) {
    const int n = inliers_at(candidate);
    if (n > best_inliers) {
      best = candidate;
      best_inliers = n;
    }
  };
  // More rounds let the classification bring the prior's inliers back.
  PoseOnlyOptions longer = options;
  longer.rounds = std::max(options.rounds, kRetryRounds);
  Pose3 retry = prior_camera_from_world;
  OptimizePose(camera, longer, points_world, uvs, &retry);
  consider(retry);
  // On the prior's inliers alone: the pose the consistent majority supports.
  if (best_inliers < kPriorInlierFraction * prior_inliers) {
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> observed;
    for (size_t i = 0; i < points_world.size(); ++i) {
      if (!is_inlier(prior_camera_from_world, i)) continue;
      points.push_back(points_world[i]);
      observed.push_back(uvs[i]);
    }
    Pose3 seeded = prior_camera_from_world;
    OptimizePose(camera, options, points, observed, &seeded);
    consider(seeded);
  }
  *camera_from_world = best;
  return best_inliers;
}

Tracker::Tracker(const MeasurementModel& model, const TrackerOptions& options,
                 const DriftOptions& drift, Map* map)
    : model_(model), options_(options), drift_(drift), map_(map) {}

void Tracker::Start(KeyframeId keyframe, const Pose3& world_from_camera, int num_points,
                    double timestamp, double median_depth) {
  started_ = true;
  lost_ = false;
  last_camera_from_world_ = world_from_camera.Inverse();
  velocity_ = Pose3::Identity();
  correction_epoch_ = map_->correction().epoch;
  reference_kf_ = keyframe;
  reference_world_from_camera_ = world_from_camera;
  reference_points_ = num_points;
  last_keyframe_time_ = timestamp;
  last_keyframe_median_depth_ = median_depth;
  measured_.clear();
  measured_velocity_.setZero();
  RecordMeasuredCentre(timestamp, world_from_camera.translation());
}

void Tracker::RecordMeasuredCentre(double timestamp, const Eigen::Vector3d& centre) {
  measured_.push_back({timestamp, centre});
  while (measured_.size() > 2 && timestamp - measured_[1].timestamp >= kSpeedWindowS) {
    measured_.pop_front();
  }
  const MeasuredCentre& oldest = measured_.front();
  // The speed stays that of the last window until a new one spans enough time.
  if (timestamp - oldest.timestamp >= kSpeedWindowS)
    measured_velocity_ = (centre - oldest.centre) / (timestamp - oldest.timestamp);
}

void Tracker::StartLost() {
  Reset();
  started_ = true;
  lost_ = true;
  correction_epoch_ = map_->correction().epoch;
}

void Tracker::Reset() {
  started_ = false;
  lost_ = false;
  velocity_ = Pose3::Identity();
  reference_kf_.reset();
  reference_features_ = SortedFeatures();
  reference_points_ = 0;
  measured_.clear();
  measured_velocity_.setZero();
}

void Tracker::Associate(const SortedFeatures& features, Association* a) const {
  const KeyframeId newest = reference_kf_.value_or(0);
  const int gap = drift_.min_keyframe_gap;
  map_->Read([&](const MapData& m) {
    for (size_t i = 0; i < features.size(); ++i) {
      const MapPoint* p = m.point(features.ids[i]);
      if (p == nullptr) {
        if (m.KeyframesWithFeature(features.ids[i]) != nullptr) ++a->num_new_triangulable;
        continue;
      }
      if (p->observers.empty()) continue;
      const bool dormant =
          reference_kf_ &&
          static_cast<int64_t>(newest) - static_cast<int64_t>(p->last_observer()) > gap;
      a->ids.push_back(p->id);
      a->points.push_back(p->position);
      a->uvs.push_back(features.uvs[i]);
      a->dormant.push_back(dormant);
      a->num_dormant += dormant ? 1 : 0;
      a->constrained.push_back(p->constrained);
      a->uncertainty.push_back(p->uncertainty);
    }
    if (reference_kf_) {
      if (const Keyframe* kf = m.keyframe(*reference_kf_)) {
        a->reference_pose = kf->world_from_camera;
        a->reference_points = kf->num_points;
      } else if (auto resolved = m.ResolveKeyframePose(*reference_kf_)) {
        a->reference_pose = resolved;  // culled: through its links
      } else {
        // Still queued for mapping: the map will insert it at the pose it was made with (carried
        // through any drift correction, as reference_world_from_camera_ is). Recording the frame
        // against it lets the refined trajectory follow what mapping does to that keyframe; a
        // keyframe that mapping drops leaves the frame at its tracked pose.
        a->reference_pose = reference_world_from_camera_;
      }
    }
  });
}

std::vector<size_t> Tracker::PoseSolvingPoints(const Association& a, bool skip_dormant) const {
  std::vector<size_t> all, constrained;
  all.reserve(a.ids.size());
  for (size_t i = 0; i < a.ids.size(); ++i) {
    if (skip_dormant && a.dormant[i]) continue;
    all.push_back(i);
    if (a.constrained[i]) constrained.push_back(i);
  }
  const int enough = options_.min_constrained_points;
  if (enough > 0 && static_cast<int>(constrained.size()) >= enough) return constrained;
  return all;
}

bool Tracker::TrackWithModel(const Association& a, Pose3* camera_from_world,
                             std::vector<bool>* inlier) {
  const Pose3 prior = velocity_ * last_camera_from_world_;
  const int num_active = static_cast<int>(a.ids.size()) - a.num_dormant;
  const int required = RequiredInliers(static_cast<int>(a.ids.size()), kMinTrackedInliers);
  // Classified on the recent points alone, a pose needs the inliers of a view of those.
  const int required_active = RequiredInliers(num_active, kMinTrackedInliers);
  // Solves from the motion prior on the associated points (dormant ones too or not),
  // subsampled evenly beyond TrackerOptions::max_points.
  auto solve = [&](bool skip_dormant, Pose3* pose) {
    const int need = skip_dormant ? required_active : required;
    const std::vector<size_t> usable = PoseSolvingPoints(a, skip_dormant);
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> uvs;
    for (const size_t k :
         EvenlySpacedIndices(usable.size(), static_cast<size_t>(options_.max_points))) {
      points.push_back(a.points[usable[k]]);
      uvs.push_back(a.uvs[usable[k]]);
    }
    if (static_cast<int>(points.size()) < need) return false;
    const int inliers =
        SolvePoseFromPrior(model_.camera, MakePoseOptions(model_), points, uvs, prior, pose);
    return inliers >= need;
  };
  // Dormant points (mapped long ago) may carry drift not yet corrected. They are left out
  // only when they disagree with the recent ones: the recent points alone can be few and
  // freshly triangulated, and a pose solved on them alone is then worse than one on all.
  if (a.num_dormant > 0 && num_active >= 2 * options_.min_inliers) {
    Pose3 active_pose, joint_pose;
    const bool active_ok = solve(/*skip_dormant=*/true, &active_pose);
    const bool joint_ok = solve(/*skip_dormant=*/false, &joint_pose);
    // Agreement, a likelihood-ratio test on the recent points: moving from their own optimum
    // to the joint one raises their (chi-square truncated) cost by about chi2(6) when the old
    // points agree, by far more when the old ones have drifted.
    int active_inliers = 0;
    const double active_cost = active_ok ? RecentPointsCost(a, active_pose, &active_inliers) : 0.0;
    int unused = 0;
    const double joint_cost = joint_ok ? RecentPointsCost(a, joint_pose, &unused) : 0.0;
    const bool agree =
        joint_ok && (!active_ok || joint_cost - active_cost <=
                                       kAgreementChi2 + kAgreementPerPoint * active_inliers);
    if (agree) {
      *camera_from_world = joint_pose;
      return Classify(a, joint_pose, false, inlier) >= required;
    }
    if (!active_ok) return false;
    *camera_from_world = active_pose;
    return Classify(a, active_pose, true, inlier) >= required_active;
  }
  Pose3 pose;
  if (solve(/*skip_dormant=*/false, &pose) && Classify(a, pose, false, inlier) >= required) {
    *camera_from_world = pose;
    return true;
  }
  // Too few recent points to weigh them against the dormant ones, and together they do not
  // fit one pose: the dormant ones may have drifted (or never been well placed), so the
  // recent points alone decide, as they would in a view with many of them.
  if (a.num_dormant == 0 || num_active < kMinOverrulingPoints) return false;
  if (!solve(/*skip_dormant=*/true, &pose)) return false;
  *camera_from_world = pose;
  return Classify(a, pose, true, inlier) >= required_active;
}

int Tracker::Classify(const Association& a, const Pose3& camera_from_world, bool skip_dormant,
                      std::vector<bool>* inlier) const {
  const double max_err_sq = kChi2TwoDof95 * model_.pixel_sigma * model_.pixel_sigma;
  inlier->assign(a.ids.size(), false);
  int n = 0;
  for (size_t i = 0; i < a.ids.size(); ++i) {
    if (skip_dormant && a.dormant[i]) continue;
    const Eigen::Vector3d pc = camera_from_world * a.points[i];
    if (!(pc.z() > 0.0)) continue;
    if ((model_.camera.Project(pc) - a.uvs[i]).squaredNorm() <= max_err_sq) {
      (*inlier)[i] = true;
      ++n;
    }
  }
  return n;
}

double Tracker::RecentPointsCost(const Association& a, const Pose3& camera_from_world,
                                 int* num_inliers) const {
  const double inv_var = 1.0 / (model_.pixel_sigma * model_.pixel_sigma);
  double cost = 0.0;
  *num_inliers = 0;
  for (size_t i = 0; i < a.ids.size(); ++i) {
    if (a.dormant[i]) continue;
    const Eigen::Vector3d pc = camera_from_world * a.points[i];
    double s = kChi2TwoDof95;
    if (pc.z() > 0.0)
      s = std::min(s, (model_.camera.Project(pc) - a.uvs[i]).squaredNorm() * inv_var);
    if (s < kChi2TwoDof95) ++*num_inliers;
    cost += s;
  }
  return cost;
}

bool Tracker::NeedKeyframe(const Association& a, int num_inliers, const Pose3& world_from_camera,
                           double timestamp, bool loop_candidate) const {
  const int reference_points = a.reference_points >= 0 ? a.reference_points : reference_points_;
  if (num_inliers < options_.keyframe_tracked_ratio * reference_points) return true;
  if (timestamp - last_keyframe_time_ > options_.keyframe_max_interval_s) return true;
  const double baseline =
      (world_from_camera.translation() - reference_world_from_camera_.translation()).norm() /
      std::max(last_keyframe_median_depth_, 1e-9);
  if (baseline > options_.keyframe_baseline_ratio) return true;
  // Re-observed old points: a keyframe (with some baseline, so they can be re-triangulated).
  if (loop_candidate && baseline > kNewPointsBaselineFraction * options_.keyframe_baseline_ratio) {
    return true;
  }
  return a.num_new_triangulable >= options_.keyframe_min_new_points &&
         baseline > kNewPointsBaselineFraction * options_.keyframe_baseline_ratio;
}

TrackerOutput Tracker::Track(int64_t seq, double timestamp, const SortedFeatures& features,
                             bool mapping_busy) {
  TrackerOutput out;
  // Drift correction moved the world: carry the last pose into the corrected world.
  const WorldCorrection correction = map_->correction();
  if (correction.epoch != correction_epoch_) {
    correction_epoch_ = correction.epoch;
    const Pose3 world_from_camera =
        correction.new_from_old.TransformPose(last_camera_from_world_.Inverse());
    last_camera_from_world_ = world_from_camera.Inverse();
    velocity_ =
        Pose3(velocity_.rotation(), velocity_.translation() * correction.new_from_old.scale());
    reference_world_from_camera_ =
        correction.new_from_old.TransformPose(reference_world_from_camera_);
    last_keyframe_median_depth_ *= correction.new_from_old.scale();
    for (MeasuredCentre& m : measured_) m.centre = correction.new_from_old * m.centre;
    measured_velocity_ =
        correction.new_from_old.scale() * (correction.new_from_old.rotation() * measured_velocity_);
  }

  Association a;
  Associate(features, &a);
  Pose3 camera_from_world;
  std::vector<bool> inlier;
  bool ok = false;
  if (!lost_) {
    ok = TrackWithModel(a, &camera_from_world, &inlier) &&
         PoseDetermined(a, inlier, camera_from_world);
  }
  bool relocalised = false;
  if (!ok) {
    ok = Relocalise(a, &camera_from_world, &inlier);
    // PnP's pose, refined on its own inliers, seeds tracking on every associated point (the
    // well-constrained ones when there are enough, dormant ones weighed): what the next frame
    // would do from it, done on this one.
    if (ok) {
      const Pose3 last = last_camera_from_world_, velocity = velocity_;
      last_camera_from_world_ = camera_from_world;
      velocity_ = Pose3::Identity();
      Pose3 tracked;
      std::vector<bool> tracked_inlier;
      if (TrackWithModel(a, &tracked, &tracked_inlier)) {
        camera_from_world = tracked;
        inlier = std::move(tracked_inlier);
      }
      ok = PoseDetermined(a, inlier, camera_from_world);
      if (!ok) {  // as if never tried
        last_camera_from_world_ = last;
        velocity_ = velocity;
      }
    }
    relocalised = ok && lost_;
  }
  bool rotation_only = false;
  bool rotation_keyframe = false;
  if (!ok && !lost_) {
    ok = rotation_only =
        TrackRotationOnly(timestamp, features, a, &camera_from_world, &inlier, &rotation_keyframe);
  }
  if (!ok) {
    M2S_LOG(kDebug) << "frame " << seq << " not tracked: " << features.size() << " features, "
                    << a.ids.size() << " of them map points (" << a.num_dormant << " dormant)";
    lost_ = true;
    out.state = TrackingState::kLost;
    velocity_ = Pose3::Identity();
    return out;
  }
  velocity_ = lost_ ? Pose3::Identity() : camera_from_world * last_camera_from_world_.Inverse();
  if (rotation_only) {
    measured_gap_ = true;
  } else {
    if (lost_ || measured_gap_) measured_.clear();
    measured_gap_ = false;
    RecordMeasuredCentre(timestamp, camera_from_world.Inverse().translation());
  }
  lost_ = false;
  last_camera_from_world_ = camera_from_world;
  out.state = relocalised ? TrackingState::kRelocalized : TrackingState::kOk;
  out.world_from_camera = camera_from_world.Inverse();
  int num_inliers = 0;
  int dormant_inliers = 0;
  for (size_t i = 0; i < inlier.size(); ++i) num_inliers += inlier[i] ? 1 : 0;
  for (size_t i = 0; i < a.ids.size(); ++i) dormant_inliers += a.dormant[i] ? 1 : 0;
  out.num_inliers = num_inliers;
  // A point far off in consecutive frames whose poses the rest supports has moved (a wrong id
  // or a noisy feature is one frame's). "Far" counts the point's own uncertainty as pixel
  // noise (its relative spread times the focal length bounds how far a point that is only
  // poorly triangulated can reproject): a short-baseline point in a sparse, noisy view is not
  // a moved vertex, and forgetting it would take the view's support away.
  const double sigma_sq = model_.pixel_sigma * model_.pixel_sigma;
  std::unordered_map<VertexId, int> streak;
  for (size_t i = 0; i < a.ids.size(); ++i) {
    if (a.dormant[i] || inlier[i]) continue;
    const double spread_px = std::max(0.0, a.uncertainty[i]) * model_.camera.fx;
    const double moved_err_sq =
        kMovedPointFactor * kMovedPointFactor * kChi2TwoDof95 * (sigma_sq + spread_px * spread_px);
    const Eigen::Vector3d pc = camera_from_world * a.points[i];
    if (pc.z() > 0.0 && (model_.camera.Project(pc) - a.uvs[i]).squaredNorm() <= moved_err_sq)
      continue;
    const auto it = outlier_streak_.find(a.ids[i]);
    streak[a.ids[i]] = it == outlier_streak_.end() ? 1 : it->second + 1;
  }
  outlier_streak_ = std::move(streak);
  if (report_observations_ && !rotation_only) {
    const std::vector<size_t> observed =
        EvenlySpacedIndices(a.ids.size(), static_cast<size_t>(options_.max_points));
    out.observed_ids.reserve(observed.size());
    out.observed_uvs.reserve(observed.size());
    for (const size_t i : observed) {
      out.observed_ids.push_back(a.ids[i]);
      out.observed_uvs.push_back(a.uvs[i]);
    }
  }
  if (reference_kf_ && a.reference_pose) {
    out.reference_keyframe = reference_kf_;
    out.reference_from_camera = a.reference_pose->Inverse() * out.world_from_camera;
  }

  const bool loop_candidate = drift_.enabled && dormant_inliers >= drift_.min_points;
  // A busy mapping stage gets a keyframe only when tracking is getting weak (the caller then
  // waits for room in the queue: back-pressure instead of a lost track).
  const int reference_points = a.reference_points >= 0 ? a.reference_points : reference_points_;
  const bool critical = num_inliers < kCriticalTrackedRatio * reference_points;
  // A rotation-only pose's centre is the reference keyframe's, not a measurement: its
  // keyframes come only from the view turning away (every keyframe at that centre, with the
  // baseline BA noise gives them, would triangulate its new features badly).
  const bool need_keyframe = rotation_only ? rotation_keyframe
                                           : NeedKeyframe(a, num_inliers, out.world_from_camera,
                                                          timestamp, loop_candidate);
  if (localization_only_ || (mapping_busy && !critical) || relocalised || !need_keyframe) {
    return out;
  }
  KeyframeCandidate kf;
  kf.id = map_->NextKeyframeId();
  kf.seq = seq;
  kf.timestamp = timestamp;
  kf.world_from_camera = out.world_from_camera;
  kf.correction_epoch = correction_epoch_;
  kf.features = features;
  std::vector<Eigen::Vector3d> tracked_positions;
  for (size_t i = 0; i < a.ids.size(); ++i) {
    if (a.dormant[i]) {
      kf.dormant_points.push_back(a.ids[i]);
    } else if (inlier[i]) {
      kf.tracked_points.push_back(a.ids[i]);
      tracked_positions.push_back(a.points[i]);
    }
  }
  for (const auto& [id, frames] : outlier_streak_) {
    if (frames >= kMovedPointFrames) kf.moved_points.push_back(id);
  }
  std::sort(kf.moved_points.begin(), kf.moved_points.end());
  if (!tracked_positions.empty()) {
    last_keyframe_median_depth_ = MedianDepth(camera_from_world, tracked_positions);
  }
  reference_kf_ = kf.id;
  reference_features_ = features;
  reference_world_from_camera_ = kf.world_from_camera;
  reference_points_ = static_cast<int>(kf.tracked_points.size());
  last_keyframe_time_ = timestamp;
  out.reference_keyframe = kf.id;
  out.reference_from_camera = Pose3::Identity();
  out.keyframe = std::move(kf);
  return out;
}

}  // namespace m2s::slam
