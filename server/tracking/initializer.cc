#include "tracking/initializer.h"

#include <algorithm>
#include <chrono>
#include <unordered_map>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "optimization/problems.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {
namespace {

using RefusalKind = TwoViewRefusal::Kind;
// After a refused attempt, retry when the parallax extrapolated linearly in time since the
// reference reaches this fraction of the bound, and at least this often.
constexpr double kRetryParallaxFraction = 0.8;
constexpr double kMaxInitRetryDelayS = 0.1;
// Second opinions (ReconstructTwoView) refuse at most this many attempts per map: more baseline
// usually narrows a valley of motions, but bunched dense objects keep one for seconds (the
// scanned-objects head motion: 15 s), and the views a few attempts later may be weaker still
// (a drone leaving its first view); after them, the motion RANSAC picks is taken.
constexpr int kMaxSecondOpinionRefusals = 3;
// Seed() takes as reference the earliest frame with this share of the most features.
constexpr double kSeedReferenceShare = 0.8;

}  // namespace

std::optional<InitialMap> Initializer::Process(int64_t seq, double timestamp,
                                               const SortedFeatures& features) {
  auto set_reference = [&]() {
    reference_ = InitialFrame{seq, timestamp, features, Pose3::Identity()};
    frames_since_reference_ = 0;
    next_attempt_time_.reset();
    kept_frames_.clear();
  };
  // A frame that does not initialise is kept for SolveInbetween (unless it became the
  // reference).
  auto keep_frame = [&]() {
    if (reference_->seq != seq) KeepFrame(seq, timestamp, features);
  };
  if (!reference_ || features.size() < static_cast<size_t>(options_.min_points)) {
    if (features.size() >= static_cast<size_t>(options_.min_points)) set_reference();
    last_failure_ = "waiting for a reference frame";
    return std::nullopt;
  }
  ++frames_since_reference_;
  if (next_attempt_time_ && timestamp < *next_attempt_time_) {
    last_failure_ = "too little parallax (waiting)";
    if (frames_since_reference_ > options_.max_reference_age) set_reference();
    keep_frame();
    return std::nullopt;
  }
  TwoViewRefusal refusal;
  double parallax = 0.0;
  auto two_view =
      ReconstructTwoView(model_, options_, reference_->features, features, &refusal, &parallax,
                         second_opinion_refusals_ < kMaxSecondOpinionRefusals);
  if (!two_view) {
    last_failure_ = refusal.message;
    if (refusal.by_second_opinion) ++second_opinion_refusals_;
    const bool too_few_shared = refusal.kind == RefusalKind::kTooFewShared;
    // Refusals that ran the RANSACs mostly mean "not enough parallax yet": retry when it may be.
    if (!too_few_shared && refusal.kind != RefusalKind::kTooLittleMotion) {
      const double elapsed = timestamp - reference_->timestamp;
      double wait = kMaxInitRetryDelayS;
      // Weak geometry needs more baseline whatever the parallax: the longest wait.
      if (refusal.kind != RefusalKind::kWeakGeometry && parallax > 0.0 && elapsed > 0.0) {
        const double needed = kRetryParallaxFraction * options_.min_parallax_deg;
        wait = std::clamp(elapsed * (needed / parallax - 1.0), 0.0, kMaxInitRetryDelayS);
      }
      next_attempt_time_ = timestamp + wait;
    }
    M2S_LOG(kDebug) << "initialisation with frames " << reference_->seq << " and " << seq
                    << " refused: " << refusal.message;
    if (frames_since_reference_ > options_.max_reference_age || too_few_shared) {
      set_reference();
    }
    keep_frame();
    return std::nullopt;
  }

  // Full bundle adjustment of the two views (the first one fixed), then scale: median depth 1.
  BaProblem problem;
  problem.keyframes = {{0, Pose3::Identity(), true}, {1, two_view->camera1_from_camera0, false}};
  const SortedFeatures* views[2] = {&reference_->features, &features};
  for (size_t i = 0; i < two_view->ids.size(); ++i) {
    const VertexId id = two_view->ids[i];
    problem.points.push_back({id, two_view->points[i], false});
    for (int v = 0; v < 2; ++v) {
      const auto& f = *views[v];
      const auto it = std::lower_bound(f.ids.begin(), f.ids.end(), id);
      problem.observations.push_back({v, static_cast<int>(problem.points.size() - 1),
                                      f.uvs[static_cast<size_t>(it - f.ids.begin())]});
    }
  }
  BundleAdjustmentOptions ba;
  ba.pixel_sigma = model_.pixel_sigma;
  ba.huber_delta_px = 2.0 * model_.pixel_sigma;
  ba.max_iterations = 50;
  ba.num_threads = num_ba_threads_;
  const BundleAdjustmentResult result = BundleAdjust(model_.camera, ba, &problem);
  if (!result.success) {
    last_failure_ = "initial bundle adjustment failed";
    set_reference();
    return std::nullopt;
  }
  std::vector<bool> bad(problem.points.size(), false);
  for (size_t o = 0; o < problem.observations.size(); ++o) {
    if (o < result.outlier.size() && result.outlier[o])
      bad[problem.observations[o].point_index] = true;
  }
  const Pose3 camera1_from_world = problem.keyframes[1].camera_from_world;
  InitialMap map;
  for (size_t i = 0; i < problem.points.size(); ++i) {
    const Eigen::Vector3d& p = problem.points[i].position_world;
    if (bad[i] || !p.allFinite() || p.z() <= 0.0 || (camera1_from_world * p).z() <= 0.0) continue;
    map.point_ids.push_back(problem.points[i].id);
    map.points.push_back(p);
  }
  // The gate of ReconstructTwoView once more, on the refined motion and points: the adjustment
  // can leave a motion the two-view estimate only seemed to determine.
  const std::optional<MotionUncertainty> uncertainty =
      TwoViewMotionUncertainty(model_.camera, model_.pixel_sigma, camera1_from_world, map.points);
  if (!WellDetermined(uncertainty, options_)) {
    last_failure_ = "the refined motion is undetermined";
    next_attempt_time_ = timestamp + kMaxInitRetryDelayS;
    if (frames_since_reference_ > options_.max_reference_age) set_reference();
    keep_frame();
    return std::nullopt;
  }
  if (static_cast<int>(map.points.size()) < options_.min_points) {
    last_failure_ = "too few points after bundle adjustment";
    set_reference();
    return std::nullopt;
  }
  // The points are in the first camera's frame (the world).
  const double scale = 1.0 / MedianDepth(Pose3::Identity(), map.points);
  for (auto& p : map.points) p *= scale;
  const Pose3 world_from_camera1 =
      Pose3(camera1_from_world.rotation(), camera1_from_world.translation() * scale).Inverse();
  map.first = *reference_;
  map.first.world_from_camera = Pose3::Identity();
  map.second = InitialFrame{seq, timestamp, features, world_from_camera1};
  map.used_homography = two_view->used_homography;
  const auto t0 = std::chrono::steady_clock::now();
  SolveInbetween(&map);
  const double inbetween_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  M2S_LOG(kInfo) << "initialised from frames " << map.first.seq << " and " << seq << " with "
                 << map.points.size() << " points ("
                 << (map.used_homography ? "homography" : "essential") << ", median parallax "
                 << two_view->median_parallax_deg << " deg); " << map.inbetween.size() << " of "
                 << kept_frames_.size() << " frames between them solved in " << inbetween_ms
                 << " ms";
  reference_.reset();
  kept_frames_.clear();
  second_opinion_refusals_ = 0;
  return map;
}

void Initializer::Seed(const std::vector<InitialFrame>& frames, SeedReference which) {
  Reset();
  size_t most = 0;
  for (const InitialFrame& f : frames) most = std::max(most, f.features.size());
  if (most < static_cast<size_t>(options_.min_points)) return;
  // kEarliestFull: the earliest frame with nearly the most features, the most parallax by the
  // next frames, but not a view with a few features at its edge (turning from a bare wall,
  // say), whose motion stays ambiguous. kLatest: the last frame with min_points features.
  const auto full = [&](const InitialFrame& f) {
    return static_cast<double>(f.features.size()) >=
           (which == SeedReference::kEarliestFull ? kSeedReferenceShare * static_cast<double>(most)
                                                  : static_cast<double>(options_.min_points));
  };
  const auto reference = which == SeedReference::kEarliestFull
                             ? std::find_if(frames.begin(), frames.end(), full)
                             : std::find_if(frames.rbegin(), frames.rend(), full).base() - 1;
  reference_ =
      InitialFrame{reference->seq, reference->timestamp, reference->features, Pose3::Identity()};
  frames_since_reference_ = static_cast<int>(frames.end() - reference) - 1;
  for (auto it = frames.begin(); it != frames.end(); ++it) {
    if (it != reference) KeepFrame(it->seq, it->timestamp, it->features);
  }
}

void Initializer::KeepFrame(int64_t seq, double timestamp, const SortedFeatures& features) {
  // The bound is the reference's age.
  if (kept_frames_.size() > static_cast<size_t>(options_.max_reference_age)) {
    kept_frames_.erase(kept_frames_.begin());
  }
  kept_frames_.push_back(InitialFrame{seq, timestamp, features, Pose3::Identity()});
}

void Initializer::SolveInbetween(InitialMap* map) const {
  const double span = map->second.timestamp - map->first.timestamp;
  const PoseOnlyOptions pose_options = tracker_internal::MakePoseOptions(model_);
  std::unordered_map<VertexId, size_t> point_index;
  for (size_t j = 0; j < map->point_ids.size(); ++j) point_index.emplace(map->point_ids[j], j);
  for (const InitialFrame& f : kept_frames_) {
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> uvs;
    std::vector<VertexId> ids;
    for (size_t i = 0; i < f.features.size(); ++i) {
      const auto it = point_index.find(f.features.ids[i]);
      if (it == point_index.end()) continue;
      ids.push_back(f.features.ids[i]);
      points.push_back(map->points[it->second]);
      uvs.push_back(f.features.uvs[i]);
    }
    // As many of the map's points as an initialisation needs: a view of a few points at its
    // edge (turning from a bare wall) fits a wrong pose under noise.
    if (points.size() < static_cast<size_t>(options_.min_points)) continue;
    const double alpha =
        span > 0.0 ? std::clamp((f.timestamp - map->first.timestamp) / span, 0.0, 1.0) : 0.5;
    Pose3 camera_from_world =
        Interpolate(map->first.world_from_camera, map->second.world_from_camera, alpha).Inverse();
    const PoseOnlyResult r =
        OptimizePose(model_.camera, pose_options, points, uvs, &camera_from_world);
    if (!r.converged || !camera_from_world.AllFinite() ||
        r.num_inliers <
            tracker_internal::kSparseViewInlierFraction * static_cast<double>(points.size())) {
      continue;
    }
    InitialInbetween solved{f.seq, camera_from_world.Inverse(), {}, {}};
    for (size_t i = 0; i < ids.size(); ++i) {
      if (!r.inlier[i]) continue;
      solved.observed_ids.push_back(ids[i]);
      solved.observed_uvs.push_back(uvs[i]);
    }
    map->inbetween.push_back(std::move(solved));
  }
}

}  // namespace m2s::slam
