// Initialisation from more views than two (docs/design/two_view_initialisation.md, item 7):
// Initializer::FromMoreViews, for views that keep refusing for weak geometry.
#include <algorithm>
#include <chrono>
#include <iterator>
#include <sstream>
#include <unordered_map>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "mapping/triangulation.h"
#include "tracking/initializer.h"
#include "tracking/initializer_internal.h"
#include "tracking/motion_uncertainty.h"

namespace m2s::slam {
namespace {

using namespace initializer_internal;

// FromMoreViews: at most this many kept frames, each at least this fraction of the time
// between the two views away from both, are the third views.
constexpr size_t kMaxThirdViews = 3;
constexpr double kMinThirdViewSpan = 0.25;
// FromMoreViews: starts adjusted to minima further apart than this many times the largest
// standard deviations the motion may have (InitializerOptions::max_*_sigma_deg) are separate
// minima (a plane's twins: tens of degrees of translation direction apart).
constexpr double kFarRivalSigmas = 6.0;

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

std::optional<InitialMap> Initializer::FromMoreViews(int64_t seq, double timestamp,
                                                     const SortedFeatures& features,
                                                     const std::vector<Pose3>& starts,
                                                     const std::string& refused) {
  auto refuse = [&](const std::string& why) -> std::optional<InitialMap> {
    M2S_LOG(kDebug) << "more views with frames " << reference_->seq << " and " << seq
                    << " refused: " << why;
    return std::nullopt;
  };
  const double span = timestamp - reference_->timestamp;
  if (!(span > 0.0)) return std::nullopt;
  std::vector<const InitialFrame*> between;
  for (const InitialFrame& f : kept_frames_) {
    const double alpha = (f.timestamp - reference_->timestamp) / span;
    if (alpha >= kMinThirdViewSpan && alpha <= 1.0 - kMinThirdViewSpan) between.push_back(&f);
  }
  if (between.empty()) return refuse("no kept frame between the views");
  const auto start_time = std::chrono::steady_clock::now();
  std::vector<const InitialFrame*> thirds;
  for (const size_t i : EvenlySpacedIndices(between.size(), kMaxThirdViews))
    thirds.push_back(between[i]);
  std::vector<const SortedFeatures*> views = {&reference_->features, &features};
  for (const InitialFrame* f : thirds) views.push_back(&f->features);

  const std::vector<VertexId> ids = SharedIds(reference_->features, features, kMaxStartPoints);
  const BundleAdjustmentOptions ba = TwoViewBaOptions(model_, num_ba_threads_);
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
    if (StartLeavesTooMany(a.problem, ids.size())) continue;
    // Each further view posed on the points triangulated with the start from the pose
    // interpolated in time, then every view adjusted together (a two-view adjustment first
    // would carry every start into the two views' own minimum, a plane's twin too).
    const Pose3 world_from_camera1 = a.problem.keyframes[1].camera_from_world.Inverse();
    std::unordered_map<VertexId, size_t> point_index;
    std::vector<Eigen::Vector3d> positions;
    for (size_t i = 0; i < a.problem.points.size(); ++i) {
      point_index.emplace(a.problem.points[i].id, i);
      positions.push_back(a.problem.points[i].position_world);
    }
    for (size_t t = 0; t < thirds.size(); ++t) {
      const double alpha = (thirds[t]->timestamp - reference_->timestamp) / span;
      const Pose3 start = Interpolate(Pose3::Identity(), world_from_camera1, alpha).Inverse();
      const std::optional<PosedView> posed = PoseOnPoints(model_, thirds[t]->features, point_index,
                                                          positions, start, options_.min_points);
      if (!posed) continue;
      a.problem.keyframes.push_back(
          {static_cast<KeyframeId>(2 + t), posed->camera_from_world, false});
      const int keyframe = static_cast<int>(a.problem.keyframes.size() - 1);
      for (size_t i = 0; i < posed->features.size(); ++i) {
        a.problem.observations.push_back({keyframe, static_cast<int>(posed->points[i]),
                                          thirds[t]->features.uvs[posed->features[i]]});
      }
    }
    if (a.problem.keyframes.size() < 3) continue;
    a.result = BundleAdjust(model_.camera, ba, &a.problem);
    if (!a.result.success) continue;
    adjusted.push_back(std::move(a));
  }
  if (adjusted.empty()) return refuse("no start adjusted over three views or more");
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
    if (!far || !(adjusted[0].cost < adjusted[i].cost - margin)) {
      std::ostringstream why;
      why << "another minimum " << d.rotation_deg << " deg of rotation and " << d.direction_deg
          << " deg of direction away costs " << adjusted[i].cost - adjusted[0].cost << " more";
      return refuse(why.str());
    }
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
  if (!WellDetermined(uncertainty, options_)) {
    std::ostringstream why;
    why << "the motion is undetermined";
    if (uncertainty) {
      why << " (" << Describe(*uncertainty) << ")";
    }
    return refuse(why.str());
  }
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
    return refuse(std::to_string(out_ids.size()) + " points, median parallax " +
                  std::to_string(median_parallax) + " deg");
  }
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_time)
          .count();
  std::ostringstream how;
  how << refused << "; " << best.problem.keyframes.size() - 2
      << " frames between them decide among " << tried.size() << " motions in " << ms << " ms, "
      << Describe(*uncertainty) << ", median parallax " << median_parallax << " deg";
  return Complete(seq, timestamp, features, winner, std::move(out_ids), std::move(out_points),
                  false, how.str());
}

}  // namespace m2s::slam
