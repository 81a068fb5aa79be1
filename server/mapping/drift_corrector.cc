#include "mapping/drift_corrector.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <unordered_set>

#include "m2s/common/alignment.h"
#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "mapping/triangulation.h"
#include "optimization/problems.h"

namespace m2s::slam {
namespace {

constexpr double kTrimFactor = 3.0;         // alignment outliers: residual > 3x median
constexpr int kGiveUpRecentViews = 4;       // that many recent views and still no triangulation
constexpr int kCovisibilityEdgesPerKf = 5;  // essential-graph edges per keyframe
constexpr int kMinEdgeCovisibility = 50;
constexpr double kLoopEdgeWeight = 1.0;
// A disagreement above this fraction of the median depth is not drift accumulated over a loop
// but a broken recent estimate (e.g. a keyframe posed in a world frame a correction has since
// moved): correcting the old map by it would destroy it, so the check is deferred.
constexpr double kMaxDriftError = 0.2;
// The old map agrees with the current keyframe when the old positions of the re-observed
// points reproject within this many pixel sigmas (median; sqrt of the 2-dof chi-square 95 %
// bound, rounded). 3-D disagreement alone is not evidence of drift: a point triangulated over a
// short baseline has a depth error of tens of percent, in the old map and in the recent views
// alike, while its reprojection from the views that measured it stays exact.
constexpr double kConsistentReprojectionSigmas = 2.45;
// A correction must bring the 3-D disagreement down to this fraction of what it was,
constexpr double kCorrectionErrorGain = 0.5;
// and the old points' median reprojection error in the current keyframe as well.
constexpr double kCorrectionReprojectionGain = 0.5;

// Median distance between the re-triangulated and the stored positions, as a fraction of the
// median depth.
double DisagreementError(const std::vector<Eigen::Vector3d>& new_positions,
                         const std::vector<Eigen::Vector3d>& old_positions, double median_depth) {
  std::vector<double> disagreement(new_positions.size());
  for (size_t i = 0; i < new_positions.size(); ++i) {
    disagreement[i] = (new_positions[i] - old_positions[i]).norm();
  }
  return Median(std::move(disagreement)) / median_depth;
}

// Old from new, fitted to the re-triangulated points, trimmed of outliers (wrong ids, poorly
// triangulated points) and re-fitted; with the median residual left (fraction of the median
// depth). nullopt when no alignment exists or too few points survive the trimming.
struct Alignment {
  Sim3 old_from_new;
  double residual_error = 0.0;
};
std::optional<Alignment> AlignToOldMap(const std::vector<Eigen::Vector3d>& new_positions,
                                       const std::vector<Eigen::Vector3d>& old_positions,
                                       double median_depth, int min_points) {
  auto s = AlignPoints(new_positions, old_positions, /*with_scale=*/true);
  if (!s) return std::nullopt;
  std::vector<double> residual(new_positions.size());
  for (size_t i = 0; i < new_positions.size(); ++i)
    residual[i] = ((*s) * new_positions[i] - old_positions[i]).norm();
  const double bound = kTrimFactor * Median(residual);
  std::vector<Eigen::Vector3d> src, dst;
  for (size_t i = 0; i < new_positions.size(); ++i) {
    if (residual[i] <= bound) src.push_back(new_positions[i]), dst.push_back(old_positions[i]);
  }
  if (static_cast<int>(src.size()) < min_points) return std::nullopt;
  s = AlignPoints(src, dst, /*with_scale=*/true);
  if (!s) return std::nullopt;
  std::vector<double> after;
  for (size_t i = 0; i < src.size(); ++i) after.push_back(((*s) * src[i] - dst[i]).norm());
  return Alignment{*s, Median(std::move(after)) / median_depth};
}

}  // namespace

const char* ToString(DriftOutcome outcome) {
  switch (outcome) {
    case DriftOutcome::kAgree:
      return "agree";
    case DriftOutcome::kInconclusive:
      return "inconclusive";
    case DriftOutcome::kCorrected:
      return "corrected";
    case DriftOutcome::kDeferred:
      return "deferred";
  }
  return "unknown";
}

DriftCorrector::OldPointsInView DriftCorrector::GatherOldPoints(
    KeyframeId keyframe, const std::vector<VertexId>& dormant) const {
  OldPointsInView view;
  map_->Read([&](const MapData& m) {
    const Keyframe* kf = m.keyframe(keyframe);
    if (kf == nullptr) return;
    view.world_from_camera = kf->world_from_camera;
    for (const VertexId id : dormant) {
      const MapPoint* p = m.point(id);
      const Eigen::Vector2d* uv = kf->Find(id);
      if (p == nullptr || uv == nullptr) continue;
      view.positions.push_back(p->position);
      view.uvs.push_back(*uv);
    }
  });
  return view;
}

double DriftCorrector::MedianReprojection(const OldPointsInView& view,
                                          const Pose3& world_from_camera) const {
  const Pose3 camera_from_world = world_from_camera.Inverse();
  std::vector<double> e(view.positions.size());
  for (size_t i = 0; i < view.positions.size(); ++i) {
    e[i] = std::sqrt(
        ReprojectionErrorSq(model_.camera, camera_from_world, view.positions[i], view.uvs[i]));
  }
  return Median(std::move(e));
}

DriftCorrector::Retriangulation DriftCorrector::Retriangulate(
    KeyframeId keyframe, const std::vector<VertexId>& dormant) const {
  Retriangulation r;
  const TriangulationChecks checks = PointChecks(model_);
  std::vector<double> depths;
  map_->Read([&](const MapData& m) {
    const Keyframe* kf = m.keyframe(keyframe);
    if (kf == nullptr) return;
    const Pose3 kf_from_world = kf->world_from_camera.Inverse();
    for (const VertexId id : dormant) {
      const MapPoint* p = m.point(id);
      const std::vector<KeyframeId>* seen = m.KeyframesWithFeature(id);
      if (p == nullptr || seen == nullptr) continue;
      const KeyframeId last = p->last_observer();
      std::vector<Pose3> poses;
      std::vector<Eigen::Vector2d> uvs;
      for (auto it = std::upper_bound(seen->begin(), seen->end(), last); it != seen->end(); ++it) {
        const Keyframe* o = m.keyframe(*it);
        poses.push_back(o->world_from_camera.Inverse());
        uvs.push_back(*o->Find(id));
      }
      r.max_recent_views = std::max(r.max_recent_views, poses.size());
      if (poses.size() < 2) continue;
      const auto q = TriangulateChecked(model_.camera, checks, poses, uvs);
      if (!q) continue;
      r.old_positions.push_back(p->position);
      r.new_positions.push_back(*q);
      depths.push_back((kf_from_world * *q).z());
      r.newest_old = std::max(r.newest_old, last);
    }
  });
  r.median_depth = std::max(Median(std::move(depths)), 1e-9);
  return r;
}

int DriftCorrector::CountOldPointsInAgreement(KeyframeId keyframe,
                                              const std::vector<VertexId>& dormant,
                                              KeyframeId newest_old) const {
  const std::unordered_set<VertexId> is_dormant(dormant.begin(), dormant.end());
  const double max_error = kConsistentReprojectionSigmas * model_.pixel_sigma;
  int count = 0;
  map_->Read([&](const MapData& m) {
    const Keyframe* kf = m.keyframe(keyframe);
    if (kf == nullptr) return;
    const Pose3 camera_from_world = kf->world_from_camera.Inverse();
    for (size_t i = 0; i < kf->ids.size(); ++i) {
      if (is_dormant.count(kf->ids[i])) continue;
      const MapPoint* p = m.point(kf->ids[i]);
      if (p == nullptr || p->observers.empty() || p->observers.front() > newest_old) continue;
      const double error_sq =
          ReprojectionErrorSq(model_.camera, camera_from_world, p->position, kf->uvs[i]);
      if (error_sq <= max_error * max_error) ++count;
    }
  });
  return count;
}

DriftOutcome DriftCorrector::Check(KeyframeId keyframe, const std::vector<VertexId>& dormant) {
  // 1. The image check first: when it settles the question, the re-triangulations (the costly
  // part) are not needed. Mapping is the map's only writer, so the reads below agree with it.
  const OldPointsInView view = GatherOldPoints(keyframe, dormant);
  const bool can_gate = static_cast<int>(view.positions.size()) >= options_.min_points;
  const double reprojection_before =
      can_gate ? MedianReprojection(view, view.world_from_camera) : 0.0;
  if (can_gate && reprojection_before <= kConsistentReprojectionSigmas * model_.pixel_sigma) {
    last_error_ = 0.0;
    return DriftOutcome::kAgree;
  }
  // 2. The points from their recent views.
  const Retriangulation r = Retriangulate(keyframe, dormant);
  if (static_cast<int>(r.new_positions.size()) < options_.min_points) {
    return r.max_recent_views >= static_cast<size_t>(kGiveUpRecentViews)
               ? DriftOutcome::kInconclusive
               : DriftOutcome::kDeferred;
  }
  // 3. Their 3-D disagreement.
  last_error_ = DisagreementError(r.new_positions, r.old_positions, r.median_depth);
  if (last_error_ < options_.min_error) return DriftOutcome::kAgree;
  const int agreeing = CountOldPointsInAgreement(keyframe, dormant, r.newest_old);
  if (agreeing >= std::max<int>(options_.min_points, static_cast<int>(r.new_positions.size()))) {
    M2S_LOG(kInfo) << "drift check at keyframe " << keyframe << ": " << r.new_positions.size()
                   << " re-observed points disagree by " << last_error_ << " of median depth, but "
                   << agreeing << " old points around them agree: moved, not drift";
    return DriftOutcome::kAgree;
  }
  // The keyframes right after a correction still settle (global BA); a second correction of
  // the same loop from them overshoots, so corrections are at least min_keyframe_gap apart.
  if (last_correction_ &&
      keyframe - *last_correction_ < static_cast<KeyframeId>(options_.min_keyframe_gap)) {
    return DriftOutcome::kDeferred;
  }
  if (last_error_ > kMaxDriftError) {
    M2S_LOG(kWarning) << "drift check at keyframe " << keyframe << ": error " << last_error_
                      << " of median depth is implausible for drift; deferred";
    return DriftOutcome::kDeferred;
  }
  // 4. The correction, which must explain the disagreement (otherwise it is noise, not drift)
  const std::optional<Alignment> alignment =
      AlignToOldMap(r.new_positions, r.old_positions, r.median_depth, options_.min_points);
  if (!alignment) return DriftOutcome::kInconclusive;
  if (alignment->residual_error > kCorrectionErrorGain * last_error_) return DriftOutcome::kAgree;
  // and what the current keyframe sees: the old points, reprojected into the keyframe moved by
  // the correction, must agree far better than before. A Sim3 fitted to depth noise does not.
  if (can_gate) {
    const double reprojection_after =
        MedianReprojection(view, alignment->old_from_new.TransformPose(view.world_from_camera));
    if (reprojection_after > kCorrectionReprojectionGain * reprojection_before) {
      M2S_LOG(kInfo) << "drift check at keyframe " << keyframe << ": a correction of "
                     << last_error_ << " of median depth would leave the old points at "
                     << reprojection_after << " px (from " << reprojection_before
                     << " px); not applied";
      return DriftOutcome::kAgree;
    }
  }
  // 5. The correction.
  Correct(keyframe, alignment->old_from_new, r.newest_old);
  last_correction_ = keyframe;
  return DriftOutcome::kCorrected;
}

void DriftCorrector::Correct(KeyframeId keyframe, const Sim3& old_from_new, KeyframeId newest_old) {
  std::vector<PoseGraphNode> nodes;
  std::vector<PoseGraphEdge> edges;
  std::unordered_map<KeyframeId, int> index;
  std::vector<Pose3> before;
  map_->Read([&](const MapData& m) {
    const Keyframe* current = m.keyframe(keyframe);
    // The current keyframe's neighbourhood in the drifted frame moves with the alignment.
    std::unordered_set<KeyframeId> moved = {keyframe};
    for (const auto& [other, shared] : m.Covisible(keyframe, 1)) {
      if (other > newest_old) moved.insert(other);
    }
    // Old keyframes observing re-observed points anchor the loop.
    std::unordered_set<KeyframeId> anchors;
    for (const VertexId vid : current->ids) {
      const MapPoint* p = m.point(vid);
      if (p == nullptr || p->last_observer() > newest_old) continue;
      for (const KeyframeId o : p->observers) anchors.insert(o);
    }
    for (const auto& [id, kf] : m.keyframes()) {
      index[id] = static_cast<int>(nodes.size());
      before.push_back(kf.world_from_camera);
      const Sim3 pose(kf.world_from_camera);
      const bool fixed = anchors.count(id) > 0 || id == m.keyframes().begin()->first;
      nodes.push_back({id, moved.count(id) ? old_from_new * pose : pose, fixed});
    }
    auto add_edge = [&](KeyframeId a, KeyframeId b, const Sim3& from_from_to, double w) {
      edges.push_back({index.at(a), index.at(b), from_from_to, w});
    };
    KeyframeId prev = 0;
    bool has_prev = false;
    for (const auto& [id, kf] : m.keyframes()) {
      if (has_prev) {
        add_edge(prev, id,
                 Sim3(m.keyframe(prev)->world_from_camera.Inverse() * kf.world_from_camera), 1.0);
      }
      int added = 0;
      for (const auto& [other, shared] : m.Covisible(id, kMinEdgeCovisibility)) {
        if (added >= kCovisibilityEdgesPerKf) break;
        if (other >= id) continue;
        if (has_prev && other == prev) continue;
        add_edge(other, id,
                 Sim3(m.keyframe(other)->world_from_camera.Inverse() * kf.world_from_camera), 1.0);
        ++added;
      }
      prev = id;
      has_prev = true;
    }
    for (const KeyframeId a : anchors) {
      for (const KeyframeId b : moved) {
        add_edge(a, b,
                 Sim3(m.keyframe(a)->world_from_camera.Inverse()) * old_from_new *
                     Sim3(m.keyframe(b)->world_from_camera),
                 kLoopEdgeWeight);
      }
    }
  });
  PoseGraphOptions pg;
  const PoseGraphResult result = OptimizePoseGraph(pg, &nodes, edges);
  if (!result.success) {
    M2S_LOG(kWarning) << "drift correction: pose graph failed; map left as it was";
    return;
  }
  Sim3 current_new_from_old;
  map_->Write([&](MapData& m) {
    std::unordered_map<KeyframeId, Sim3> new_from_old;
    for (size_t i = 0; i < nodes.size(); ++i) {
      new_from_old[nodes[i].id] = nodes[i].world_from_camera * Sim3(before[i].Inverse());
    }
    std::vector<VertexId> ids;
    for (const auto& [id, p] : m.points()) ids.push_back(id);
    for (const VertexId id : ids) {
      const MapPoint* p = m.point(id);
      KeyframeId ref = p->reference_keyframe;
      if (!new_from_old.count(ref)) {
        if (p->observers.empty()) continue;
        ref = p->observers.front();
      }
      m.SetPointPosition(id, new_from_old.at(ref) * p->position);
    }
    for (const PoseGraphNode& n : nodes) {
      m.SetKeyframePose(n.id,
                        Pose3(n.world_from_camera.rotation(), n.world_from_camera.translation()));
    }
    current_new_from_old = new_from_old.at(keyframe);
  });
  map_->PublishCorrection(current_new_from_old);
  M2S_LOG(kInfo) << "drift correction at keyframe " << keyframe << ": error " << last_error_
                 << " of median depth, scale " << old_from_new.scale();
}

}  // namespace m2s::slam
