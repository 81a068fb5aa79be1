#include "tracking/initializer.h"

#include <algorithm>
#include <chrono>
#include <sstream>
#include <unordered_map>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "optimization/problems.h"
#include "tracking/initializer_internal.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {
namespace {

using namespace initializer_internal;
using RefusalKind = TwoViewRefusal::Kind;
// After a refused attempt, retry when the parallax extrapolated linearly in time since the
// reference reaches this fraction of the bound, and at least this often.
constexpr double kRetryParallaxFraction = 0.8;
constexpr double kMaxInitRetryDelayS = 0.1;
// ... and at least this much later: near the bound the parallax grows little from one frame to
// the next, and at 120 fps attempts of 5-9 ms in every frame kept the tracking thread busy for
// the whole period (frames dropped at the initialisation). Every frame below 55 fps.
constexpr double kMinInitRetryDelayS = 0.018;
// Second opinions (ReconstructTwoView) refuse at most this many attempts per map: more baseline
// usually narrows a valley of motions, but bunched dense objects keep one for seconds (the
// scanned-objects head motion: 15 s), and the views a few attempts later may be weaker still
// (a drone leaving its first view); after them, the motion RANSAC picks is taken.
constexpr int kMaxSecondOpinionRefusals = 3;
// Seed() takes as reference the earliest frame with this share of the most features.
constexpr double kSeedReferenceShare = 0.8;
// Residuals of the gated adjustment below this fraction of pixel_sigma (RMS) are exact data:
// the other starts are not adjusted (they would stall tracking for nothing; the real-time demo
// skipped frames at its initialisation).
constexpr double kExactRmseFraction = 0.1;
// AdjustFromEveryStart's result: the adjusted problem and how the adjustment went.
struct TwoViewAdjustment {
  BaProblem problem;
  BundleAdjustmentResult result;
  double cost = 0.0;
  bool from_start = false;  // the adjustment from `start`
  int adjustments = 0;      // starts adjusted in all
};

// The two views' bundle adjustment of the points `ids` (every shared feature), triangulated
// from `start` and from each of `candidates`. The adjustment from `start` is kept unless
// another's cost is lower by more than chi-square (5 dof, 99.9 %): within that margin the views
// do not tell the minima apart (a valley of motions, which the gates judged before). A start
// that leaves more than kMaxStartBehind of the points behind a view (a wrong sign, a wrong
// decomposition), or lies within kSameStartDeg of rotation and translation direction of a
// start already adjusted, is skipped. The cost: each observation's squared error capped at the
// chi-square bound (2 dof, 95 %), a point left out counting the cap twice. nullopt when no
// adjustment succeeds.
std::optional<TwoViewAdjustment> AdjustFromEveryStart(
    const MeasurementModel& model, const BundleAdjustmentOptions& ba, const SortedFeatures& view0,
    const SortedFeatures& view1, const Pose3& start, const std::vector<VertexId>& ids,
    const std::vector<Pose3>& candidates) {
  const double cap = kChi2TwoDof95 * model.pixel_sigma * model.pixel_sigma;
  std::optional<TwoViewAdjustment> best;
  std::vector<Pose3> tried;
  int adjustments = 0;
  auto same_as_tried = [&](const Pose3& motion) {
    return std::any_of(tried.begin(), tried.end(),
                       [&](const Pose3& other) { return SameMotion(motion, other); });
  };
  auto adjust = [&](const Pose3& motion) {
    if (!motion.AllFinite() || same_as_tried(motion)) return;
    tried.push_back(motion);
    TwoViewAdjustment a;
    a.from_start = tried.size() == 1;
    a.problem = TwoViewProblem(model.camera, view0, view1, motion, ids, {});
    if (StartLeavesTooMany(a.problem, ids.size())) return;
    a.result = BundleAdjust(model.camera, ba, &a.problem);
    ++adjustments;
    if (!a.result.success) return;
    a.cost = 2.0 * cap * static_cast<double>(ids.size() - a.problem.points.size());
    for (const BaObservation& o : a.problem.observations) {
      const Eigen::Vector3d p =
          a.problem.keyframes[static_cast<size_t>(o.keyframe_index)].camera_from_world *
          a.problem.points[static_cast<size_t>(o.point_index)].position_world;
      a.cost += p.z() > 0.0 ? std::min(cap, (model.camera.Project(p) - o.uv).squaredNorm()) : cap;
    }
    // The first adjustment is `start`'s; a later one must beat the best by the margin.
    const double margin = kChi2FiveDof999 * model.pixel_sigma * model.pixel_sigma;
    if (!best || a.cost < best->cost - margin) best = std::move(a);
  };
  adjust(start);
  for (const Pose3& candidate : candidates) adjust(candidate);
  if (best) best->adjustments = adjustments;
  return best;
}

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
  if (!two_view && !refused_since_) refused_since_ = timestamp;
  if (!two_view && !refusal.rivals.empty() && MoreViewsDue(timestamp)) {
    if (auto map = FromMoreViews(seq, timestamp, features, refusal.rivals, refusal.message))
      return map;
  }
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
        wait = std::clamp(elapsed * (needed / parallax - 1.0), kMinInitRetryDelayS,
                          kMaxInitRetryDelayS);
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

  // Full bundle adjustment of the two views (the first one fixed) on the points of the
  // reconstruction, gated once more; then the same adjustment from the other estimators'
  // motions (below); then scale: median depth 1.
  BaProblem problem =
      TwoViewProblem(model_.camera, reference_->features, features, two_view->camera1_from_camera0,
                     two_view->ids, two_view->points);
  const BundleAdjustmentOptions ba = TwoViewBaOptions(model_, num_ba_threads_);
  const BundleAdjustmentResult result = BundleAdjust(model_.camera, ba, &problem);
  if (!result.success) {
    last_failure_ = "initial bundle adjustment failed";
    M2S_LOG(kDebug) << "initialisation with frames " << reference_->seq << " and " << seq
                    << ": the bundle adjustment failed";
    set_reference();
    return std::nullopt;
  }
  Pose3 camera1_from_world = problem.keyframes[1].camera_from_world;
  InitialMap map;
  AdjustedPoints(problem, result, &map.point_ids, &map.points);
  // The gate of ReconstructTwoView once more, on the refined motion and points: the adjustment
  // can leave a motion the two-view estimate only seemed to determine.
  const std::optional<MotionUncertainty> uncertainty =
      TwoViewMotionUncertainty(model_.camera, model_.pixel_sigma, camera1_from_world, map.points);
  if (!WellDetermined(uncertainty, options_)) {
    if (!refused_since_) refused_since_ = timestamp;
    if (MoreViewsDue(timestamp)) {
      if (auto more = FromMoreViews(seq, timestamp, features, {camera1_from_world},
                                    "the refined motion is undetermined")) {
        return more;
      }
    }
    last_failure_ = "the refined motion is undetermined";
    if (uncertainty) {
      M2S_LOG(kDebug) << "initialisation with frames " << reference_->seq << " and " << seq
                      << " refused after adjustment: " << Describe(*uncertainty);
    }
    next_attempt_time_ = timestamp + kMaxInitRetryDelayS;
    if (frames_since_reference_ > options_.max_reference_age) set_reference();
    keep_frame();
    return std::nullopt;
  }
  // A pair of views can hold several minima, and the one RANSAC's motion leads to need not be
  // the lowest: every shared feature (those RANSAC's bound left out too, whose absence biases
  // the cost towards RANSAC's own motion) is adjusted from the gated motion and from every
  // motion the estimators proposed. A minimum lower by more than the chi-square margin takes
  // the place of the gated one, its motion the start of the reconstruction's points' adjustment
  // (docs/design/two_view_initialisation.md, item 6).
  // Exact data (residuals far below the noise) has its minimum at the truth: no other start.
  const auto adjust_start = std::chrono::steady_clock::now();
  std::optional<TwoViewAdjustment> best;
  if (result.final_rmse_px > kExactRmseFraction * model_.pixel_sigma) {
    best = AdjustFromEveryStart(model_, ba, reference_->features, features, camera1_from_world,
                                SharedIds(reference_->features, features, kMaxStartPoints),
                                two_view->candidate_motions());
  }
  const double adjust_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - adjust_start)
          .count();
  if (best && !best->from_start) {
    BaProblem again =
        TwoViewProblem(model_.camera, reference_->features, features,
                       best->problem.keyframes[1].camera_from_world, map.point_ids, {});
    const BundleAdjustmentResult again_result = BundleAdjust(model_.camera, ba, &again);
    std::vector<VertexId> ids;
    std::vector<Eigen::Vector3d> points;
    if (again_result.success) AdjustedPoints(again, again_result, &ids, &points);
    if (static_cast<int>(points.size()) >= options_.min_points) {
      camera1_from_world = again.keyframes[1].camera_from_world;
      map.point_ids = std::move(ids);
      map.points = std::move(points);
    }
  }
  if (static_cast<int>(map.points.size()) < options_.min_points) {
    last_failure_ = "too few points after bundle adjustment";
    M2S_LOG(kDebug) << "initialisation with frames " << reference_->seq << " and " << seq << ": "
                    << map.points.size() << " points after the bundle adjustment";
    set_reference();
    return std::nullopt;
  }
  std::ostringstream how;
  how << (two_view->used_homography ? "homography" : "essential") << ", median parallax "
      << two_view->median_parallax_deg << " deg; " << (best ? best->adjustments : 0)
      << " starts adjusted in " << adjust_ms << " ms";
  return Complete(seq, timestamp, features, camera1_from_world, std::move(map.point_ids),
                  std::move(map.points), two_view->used_homography, how.str());
}

bool Initializer::MoreViewsDue(double timestamp) const {
  // The two views' gated map stays the rule, more views the way out of views that keep refusing
  // (a drone flying along its optical axis: 382 frames, docs/design/two_view_initialisation.md).
  return options_.more_views_after_s >= 0.0 && refused_since_ &&
         timestamp - *refused_since_ >= options_.more_views_after_s;
}

InitialMap Initializer::Complete(int64_t seq, double timestamp, const SortedFeatures& features,
                                 const Pose3& camera1_from_world, std::vector<VertexId> ids,
                                 std::vector<Eigen::Vector3d> points, bool used_homography,
                                 const std::string& how) {
  InitialMap map;
  map.point_ids = std::move(ids);
  map.points = std::move(points);
  // The points are in the first camera's frame (the world).
  const double scale = 1.0 / MedianDepth(Pose3::Identity(), map.points);
  for (auto& p : map.points) p *= scale;
  const Pose3 world_from_camera1 =
      Pose3(camera1_from_world.rotation(), camera1_from_world.translation() * scale).Inverse();
  map.first = *reference_;
  map.first.world_from_camera = Pose3::Identity();
  map.second = InitialFrame{seq, timestamp, features, world_from_camera1};
  map.used_homography = used_homography;
  std::ostringstream frames_between;
  if (defer_inbetween_) {
    frames_between << kept_frames_.size() << " frames between them to solve";
    map.unsolved = std::move(kept_frames_);
  } else {
    const auto t0 = std::chrono::steady_clock::now();
    InbetweenSolver solver(model_, options_.min_points, map, std::move(kept_frames_));
    while (!solver.done()) {
      if (std::optional<InitialInbetween> f = solver.SolveNext())
        map.inbetween.push_back(std::move(*f));
    }
    frames_between
        << map.inbetween.size() << " of " << solver.size() << " frames between them solved in "
        << std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count()
        << " ms";
  }
  M2S_LOG(kInfo) << "initialised from frames " << map.first.seq << " and " << seq << " with "
                 << map.points.size() << " points (" << how << "); " << frames_between.str();
  reference_.reset();
  kept_frames_.clear();
  second_opinion_refusals_ = 0;
  refused_since_.reset();
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

InbetweenSolver::InbetweenSolver(const MeasurementModel& model, int min_points,
                                 const InitialMap& map, std::vector<InitialFrame> frames)
    : model_(model),
      min_points_(min_points),
      points_(map.points),
      first_time_(map.first.timestamp),
      span_(map.second.timestamp - map.first.timestamp),
      world_from_first_(map.first.world_from_camera),
      world_from_second_(map.second.world_from_camera),
      frames_(std::move(frames)) {
  for (size_t j = 0; j < map.point_ids.size(); ++j) point_index_.emplace(map.point_ids[j], j);
}

std::optional<InitialInbetween> InbetweenSolver::SolveNext() {
  if (done()) return std::nullopt;
  const InitialFrame& f = frames_[next_++];
  const double alpha =
      span_ > 0.0 ? std::clamp((f.timestamp - first_time_) / span_, 0.0, 1.0) : 0.5;
  const Pose3 start = Interpolate(world_from_first_, world_from_second_, alpha).Inverse();
  const std::optional<PosedView> posed =
      PoseOnPoints(model_, f.features, point_index_, points_, start, min_points_);
  if (!posed || posed->result.num_inliers < tracker_internal::kSparseViewInlierFraction *
                                                static_cast<double>(posed->features.size())) {
    return std::nullopt;
  }
  InitialInbetween solved{f.seq, posed->camera_from_world.Inverse(), {}, {}};
  for (size_t i = 0; i < posed->features.size(); ++i) {
    if (!posed->result.inlier[i]) continue;
    solved.observed_ids.push_back(f.features.ids[posed->features[i]]);
    solved.observed_uvs.push_back(f.features.uvs[posed->features[i]]);
  }
  return solved;
}

}  // namespace m2s::slam
