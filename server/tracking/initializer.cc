#include "tracking/initializer.h"

#include <algorithm>
#include <chrono>
#include <iterator>
#include <sstream>
#include <unordered_map>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "mapping/triangulation.h"
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
// AdjustFromEveryStart: starts that leave more than this share of the points behind a view
// are skipped, and so are starts this close (degrees of rotation and of translation direction)
// to one already adjusted.
constexpr double kMaxStartBehind = 0.2;
constexpr double kSameStartDeg = 0.5;
// AdjustFromEveryStart compares the starts on an even subset of at most this many of the shared
// features (an initialisation stalls tracking for the adjustments' time).
constexpr size_t kMaxStartPoints = 300;
// Residuals of the gated adjustment below this fraction of pixel_sigma (RMS) are exact data:
// the other starts are not adjusted (they would stall tracking for nothing; the real-time demo
// skipped frames at its initialisation).
constexpr double kExactRmseFraction = 0.1;
// FromMoreViews: at most this many kept frames, each at least this fraction of the time
// between the two views away from both, are the third views.
constexpr size_t kMaxThirdViews = 3;
constexpr double kMinThirdViewSpan = 0.25;
// FromMoreViews: starts adjusted to minima further apart than this many times the largest
// standard deviations the motion may have (InitializerOptions::max_*_sigma_deg) are separate
// minima (a plane's twins: tens of degrees of translation direction apart).
constexpr double kFarRivalSigmas = 6.0;

// How far apart two motions are: degrees of rotation and of translation direction.
struct MotionDistance {
  double rotation_deg = 0.0;
  double direction_deg = 0.0;
};
MotionDistance DistanceBetween(const Pose3& a, const Pose3& b) {
  const double cos_direction = a.translation().normalized().dot(b.translation().normalized());
  return {RadToDeg(a.rotation().angularDistance(b.rotation())),
          RadToDeg(std::acos(std::clamp(cos_direction, -1.0, 1.0)))};
}
bool SameMotion(const Pose3& a, const Pose3& b) {
  const MotionDistance d = DistanceBetween(a, b);
  return d.rotation_deg < kSameStartDeg && d.direction_deg < kSameStartDeg;
}

// The two-view bundle adjustment problem of an initialisation: view 0 fixed at the origin,
// view 1 at `camera1_from_camera0`, a point for each of `ids` (sorted, shared by the views) at
// `points` (camera 0; parallel to `ids`), or, with `points` empty, triangulated (DLT) with that
// motion and left out where it does not lie in front of both views.
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

// The ids two views share, sorted: an even subset of at most `max_count` of them.
std::vector<VertexId> SharedIds(const SortedFeatures& a, const SortedFeatures& b,
                                size_t max_count) {
  const std::vector<std::pair<size_t, size_t>> shared = SharedIndices(a, b);
  std::vector<VertexId> out;
  for (const size_t k : EvenlySpacedIndices(shared.size(), max_count))
    out.push_back(a.ids[shared[k].first]);
  return out;
}

// The points of an adjusted two-view problem a map takes: none of their observations an
// outlier, finite, in front of both views.
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
    if (static_cast<double>(a.problem.points.size()) <
        (1.0 - kMaxStartBehind) * static_cast<double>(ids.size())) {
      return;
    }
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

// The bundle adjustment options of an initialisation.
BundleAdjustmentOptions TwoViewBaOptions(const MeasurementModel& model, int num_threads) {
  BundleAdjustmentOptions ba;
  ba.pixel_sigma = model.pixel_sigma;
  ba.huber_delta_px = 2.0 * model.pixel_sigma;
  ba.max_iterations = 50;
  ba.num_threads = num_threads;
  return ba;
}

// The cost of an adjusted problem over a fixed set of observations, so that adjustments from
// different starts compare: for each of `views` (keyframe ids 0, 1, ... of the problem, in
// order) and each of `ids` it sees, the squared reprojection error capped at the chi-square
// bound (2 dof, 95 %); the cap where the problem lacks the view or the point, or the point
// lies behind the view.
double CappedCost(const MeasurementModel& model, const BaProblem& problem,
                  const std::vector<const SortedFeatures*>& views,
                  const std::vector<VertexId>& ids) {
  const double cap = kChi2TwoDof95 * model.pixel_sigma * model.pixel_sigma;
  std::unordered_map<VertexId, size_t> point_index;
  for (size_t i = 0; i < problem.points.size(); ++i) point_index.emplace(problem.points[i].id, i);
  double cost = 0.0;
  for (size_t v = 0; v < views.size(); ++v) {
    const auto keyframe =
        std::find_if(problem.keyframes.begin(), problem.keyframes.end(),
                     [&](const BaKeyframe& k) { return k.id == static_cast<KeyframeId>(v); });
    for (const auto& [i, k] : SharedIndices(*views[v], SortedFeatures{ids, {}})) {
      (void)k;
      const auto point = point_index.find(views[v]->ids[i]);
      if (keyframe == problem.keyframes.end() || point == point_index.end()) {
        cost += cap;
        continue;
      }
      const Eigen::Vector3d p =
          keyframe->camera_from_world * problem.points[point->second].position_world;
      cost += p.z() > 0.0
                  ? std::min(cap, (model.camera.Project(p) - views[v]->uvs[i]).squaredNorm())
                  : cap;
    }
  }
  return cost;
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
                      << " refused after adjustment: rotation sigma "
                      << RadToDeg(uncertainty->rotation_rad) << " deg, direction sigma "
                      << RadToDeg(uncertainty->direction_rad) << " deg";
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
  const auto t0 = std::chrono::steady_clock::now();
  SolveInbetween(&map);
  const double inbetween_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  M2S_LOG(kInfo) << "initialised from frames " << map.first.seq << " and " << seq << " with "
                 << map.points.size() << " points (" << how << "); " << map.inbetween.size()
                 << " of " << kept_frames_.size() << " frames between them solved in "
                 << inbetween_ms << " ms";
  reference_.reset();
  kept_frames_.clear();
  second_opinion_refusals_ = 0;
  refused_since_.reset();
  return map;
}

std::optional<InitialMap> Initializer::FromMoreViews(int64_t seq, double timestamp,
                                                     const SortedFeatures& features,
                                                     const std::vector<Pose3>& starts,
                                                     const std::string& refused) {
  const double span = timestamp - reference_->timestamp;
  if (!(span > 0.0)) return std::nullopt;
  std::vector<const InitialFrame*> between;
  for (const InitialFrame& f : kept_frames_) {
    const double alpha = (f.timestamp - reference_->timestamp) / span;
    if (alpha >= kMinThirdViewSpan && alpha <= 1.0 - kMinThirdViewSpan) between.push_back(&f);
  }
  if (between.empty()) return std::nullopt;
  const auto start_time = std::chrono::steady_clock::now();
  std::vector<const InitialFrame*> thirds;
  for (const size_t i : EvenlySpacedIndices(between.size(), kMaxThirdViews))
    thirds.push_back(between[i]);
  std::vector<const SortedFeatures*> views = {&reference_->features, &features};
  for (const InitialFrame* f : thirds) views.push_back(&f->features);

  const std::vector<VertexId> ids = SharedIds(reference_->features, features, kMaxStartPoints);
  const BundleAdjustmentOptions ba = TwoViewBaOptions(model_, num_ba_threads_);
  const PoseOnlyOptions pose_options = tracker_internal::MakePoseOptions(model_);
  struct Adjusted {
    BaProblem problem;
    BundleAdjustmentResult result;
    double cost = 0.0;
  };
  std::vector<Adjusted> adjusted;
  std::vector<Pose3> tried;
  for (const Pose3& start : starts) {
    if (!start.AllFinite() || !(start.translation().norm() > 0.0)) continue;
    const Pose3 motion(start.rotation(), start.translation().normalized());
    if (std::any_of(tried.begin(), tried.end(),
                    [&](const Pose3& other) { return SameMotion(motion, other); })) {
      continue;
    }
    tried.push_back(motion);
    Adjusted a;
    a.problem = TwoViewProblem(model_.camera, reference_->features, features, motion, ids, {});
    if (static_cast<double>(a.problem.points.size()) <
        (1.0 - kMaxStartBehind) * static_cast<double>(ids.size())) {
      continue;
    }
    // Each further view posed on the points triangulated with the start from the pose
    // interpolated in time, then every view adjusted together (a two-view adjustment first
    // would carry every start into the two views' own minimum, a plane's twin too).
    const Pose3 world_from_camera1 = a.problem.keyframes[1].camera_from_world.Inverse();
    std::unordered_map<VertexId, int> point_index;
    for (size_t i = 0; i < a.problem.points.size(); ++i)
      point_index.emplace(a.problem.points[i].id, static_cast<int>(i));
    for (size_t t = 0; t < thirds.size(); ++t) {
      const SortedFeatures& f = thirds[t]->features;
      std::vector<Eigen::Vector3d> points;
      std::vector<Eigen::Vector2d> uvs;
      std::vector<int> indices;
      for (size_t i = 0; i < f.size(); ++i) {
        const auto it = point_index.find(f.ids[i]);
        if (it == point_index.end()) continue;
        points.push_back(a.problem.points[static_cast<size_t>(it->second)].position_world);
        uvs.push_back(f.uvs[i]);
        indices.push_back(it->second);
      }
      if (points.size() < static_cast<size_t>(options_.min_points)) continue;
      const double alpha = (thirds[t]->timestamp - reference_->timestamp) / span;
      Pose3 camera_from_world = Interpolate(Pose3::Identity(), world_from_camera1, alpha).Inverse();
      const PoseOnlyResult r =
          OptimizePose(model_.camera, pose_options, points, uvs, &camera_from_world);
      if (!r.converged || !camera_from_world.AllFinite()) continue;
      a.problem.keyframes.push_back({static_cast<KeyframeId>(2 + t), camera_from_world, false});
      const int keyframe = static_cast<int>(a.problem.keyframes.size() - 1);
      for (size_t i = 0; i < uvs.size(); ++i)
        a.problem.observations.push_back({keyframe, indices[i], uvs[i]});
    }
    if (a.problem.keyframes.size() < 3) continue;
    a.result = BundleAdjust(model_.camera, ba, &a.problem);
    if (!a.result.success) continue;
    adjusted.push_back(std::move(a));
  }
  if (adjusted.empty()) return std::nullopt;
  // The starts compare on the points every adjustment kept (one start's triangulation leaves
  // out points near its epipole that another's keeps).
  std::vector<VertexId> common = ids;
  for (const Adjusted& a : adjusted) {
    std::vector<VertexId> kept;
    for (const BaPoint& p : a.problem.points) kept.push_back(p.id);
    std::sort(kept.begin(), kept.end());
    std::vector<VertexId> both;
    std::set_intersection(common.begin(), common.end(), kept.begin(), kept.end(),
                          std::back_inserter(both));
    common = std::move(both);
  }
  for (Adjusted& a : adjusted) a.cost = CappedCost(model_, a.problem, views, common);
  std::sort(adjusted.begin(), adjusted.end(),
            [](const Adjusted& x, const Adjusted& y) { return x.cost < y.cost; });
  // Every other start must end at the same minimum (within kSameStartDeg), or far from it
  // (kFarRivalSigmas) and higher by the margin of AdjustFromEveryStart: minima a few sigmas
  // apart lie in one valley of the cost.
  const double margin = kChi2FiveDof999 * model_.pixel_sigma * model_.pixel_sigma;
  const Pose3& winner = adjusted[0].problem.keyframes[1].camera_from_world;
  for (size_t i = 1; i < adjusted.size(); ++i) {
    const Pose3& other = adjusted[i].problem.keyframes[1].camera_from_world;
    if (SameMotion(winner, other)) continue;
    const MotionDistance d = DistanceBetween(winner, other);
    const bool far = d.rotation_deg > kFarRivalSigmas * options_.max_rotation_sigma_deg ||
                     d.direction_deg > kFarRivalSigmas * options_.max_direction_sigma_deg;
    if (!far || !(adjusted[0].cost < adjusted[i].cost - margin)) return std::nullopt;
  }
  const Adjusted& best = adjusted[0];
  // The gate of ReconstructTwoView on every view: the motion's deviations with the further
  // views' poses and the points unknown.
  std::vector<Pose3> poses;
  for (const BaKeyframe& k : best.problem.keyframes) poses.push_back(k.camera_from_world);
  std::vector<Eigen::Vector3d> positions;
  for (const BaPoint& p : best.problem.points) positions.push_back(p.position_world);
  std::vector<std::pair<int, int>> seen;
  for (size_t o = 0; o < best.problem.observations.size(); ++o) {
    if (o < best.result.outlier.size() && best.result.outlier[o]) continue;
    seen.emplace_back(best.problem.observations[o].keyframe_index,
                      best.problem.observations[o].point_index);
  }
  const std::optional<MotionUncertainty> uncertainty =
      MultiViewMotionUncertainty(model_.camera, model_.pixel_sigma, poses, positions, seen);
  if (!WellDetermined(uncertainty, options_)) return std::nullopt;
  std::vector<VertexId> out_ids;
  std::vector<Eigen::Vector3d> out_points;
  AdjustedPoints(best.problem, best.result, &out_ids, &out_points);
  const Eigen::Vector3d c1 = winner.Inverse().translation();
  std::vector<double> parallax;
  for (const Eigen::Vector3d& p : out_points)
    parallax.push_back(ParallaxDeg(p, Eigen::Vector3d::Zero(), c1));
  const double median_parallax = Median(parallax);
  if (static_cast<int>(out_ids.size()) < options_.min_points ||
      median_parallax < options_.min_parallax_deg) {
    return std::nullopt;
  }
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_time)
          .count();
  std::ostringstream how;
  how << refused << "; " << best.problem.keyframes.size() - 2
      << " frames between them decide among " << tried.size() << " motions in " << ms
      << " ms, rotation sigma " << RadToDeg(uncertainty->rotation_rad) << " deg, direction sigma "
      << RadToDeg(uncertainty->direction_rad) << " deg, median parallax " << median_parallax
      << " deg";
  return Complete(seq, timestamp, features, winner, std::move(out_ids), std::move(out_points),
                  false, how.str());
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
