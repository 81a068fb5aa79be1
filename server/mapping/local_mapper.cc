#include "mapping/local_mapper.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "mapping/keyframe_culling.h"
#include "mapping/point_uncertainty.h"
#include "optimization/problems.h"

namespace m2s::slam {
namespace {

// Points created from two views must gain an observation within this many keyframes.
constexpr int kRecentPointKeyframes = 3;

}  // namespace

LocalMapper::LocalMapper(const MeasurementModel& model, const MapperOptions& options,
                         const DriftOptions& drift, Map* map)
    : model_(model),
      options_(options),
      drift_options_(drift),
      map_(map),
      checks_(PointChecks(model)),
      drift_(model, drift, map) {}

MappingStats LocalMapper::stats() const {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  return stats_;
}

void LocalMapper::InsertInitialMap(const InitialMap& initial, KeyframeId first, KeyframeId second) {
  map_->Write([&](MapData& m) {
    for (const auto& [frame, id] :
         {std::pair{&initial.first, first}, std::pair{&initial.second, second}}) {
      Keyframe kf;
      kf.id = id;
      kf.seq = frame->seq;
      kf.timestamp = frame->timestamp;
      kf.world_from_camera = frame->world_from_camera;
      kf.ids = frame->features.ids;
      kf.uvs = frame->features.uvs;
      m.AddKeyframe(std::move(kf));
    }
    for (size_t i = 0; i < initial.point_ids.size(); ++i) {
      m.AddPoint(initial.point_ids[i], initial.points[i], first);
      m.AddObservation(initial.point_ids[i], first);
      m.AddObservation(initial.point_ids[i], second);
    }
    UpdateUncertainty(initial.point_ids, &m);
  });
  FlushUncertainty();
  std::lock_guard<std::mutex> lock(stats_mutex_);
  stats_.points_created += static_cast<int64_t>(initial.point_ids.size());
}

bool LocalMapper::InsertKeyframe(const KeyframeCandidate& c) {
  // A drift correction published after the tracker made this candidate moved the world: carry
  // the pose over (as the tracker does for its own pose), or drop the candidate when more than
  // one correction happened in between (only the latest is known).
  Pose3 world_from_camera = c.world_from_camera;
  const WorldCorrection correction = map_->correction();
  if (correction.epoch != c.correction_epoch) {
    if (correction.epoch != c.correction_epoch + 1) {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++stats_.keyframes_dropped_stale;
      return false;
    }
    world_from_camera = correction.new_from_old.TransformPose(world_from_camera);
  }
  map_->Write([&](MapData& m) {
    Keyframe kf;
    kf.id = c.id;
    kf.seq = c.seq;
    kf.timestamp = c.timestamp;
    kf.world_from_camera = world_from_camera;
    kf.ids = c.features.ids;
    kf.uvs = c.features.uvs;
    m.AddKeyframe(std::move(kf));
    for (const VertexId id : c.tracked_points) m.AddObservation(id, c.id);
    UpdateUncertainty(c.tracked_points, &m);
  });
  return true;
}

bool LocalMapper::CheckDrift(const KeyframeCandidate& c) {
  if (c.dormant_points.empty()) return false;
  // Too few dormant points to check (or no drift correction): they are taken as they are.
  DriftOutcome outcome = DriftOutcome::kAgree;
  if (drift_options_.enabled &&
      static_cast<int>(c.dormant_points.size()) >= drift_options_.min_points) {
    outcome = drift_.Check(c.id, c.dormant_points);
  }
  // Old points are re-observed: from now on they are ordinary observations, unless the check
  // was deferred (it needs recent keyframes that measured them). An inconclusive check (too
  // few points re-triangulate) merges too: keeping them dormant re-runs the check on every
  // later keyframe and, measured with bench_slam_accuracy (noisy, 30 fps, 60 s), leaves
  // room-s2 at 1.82 mm ATE against 1.30 mm when they merge (default: 1.48 against 1.56 mm).
  if (outcome != DriftOutcome::kDeferred) {
    // When the map agrees with the keyframe (or was corrected to), an old point that reprojects
    // far from where the keyframe sees its vertex is not drift: the vertex moved. (Far: a few
    // times the triangulation bound, so that old points' own errors and noise do not count.)
    constexpr double kMovedDormantFactor = 4.0;
    const bool consistent = outcome == DriftOutcome::kAgree || outcome == DriftOutcome::kCorrected;
    map_->Write([&](MapData& m) {
      const Keyframe* kf = m.keyframe(c.id);
      const Pose3 camera_from_world = kf != nullptr ? kf->world_from_camera.Inverse() : Pose3();
      for (const VertexId id : c.dormant_points) {
        const MapPoint* p = m.point(id);
        const Eigen::Vector2d* uv = kf != nullptr ? kf->Find(id) : nullptr;
        if (consistent && p != nullptr && uv != nullptr) {
          const Eigen::Vector3d q = camera_from_world * p->position;
          if (!(q.z() > 0.0) || (model_.camera.Project(q) - *uv).norm() >
                                    kMovedDormantFactor * checks_.max_reprojection_px) {
            m.ForgetMovedVertex(id, c.id);
            continue;
          }
        }
        m.AddObservation(id, c.id);
      }
      UpdateUncertainty(c.dormant_points, &m);
    });
  } else {
    M2S_LOG(kDebug) << "drift check at keyframe " << c.id << ": " << ToString(outcome) << "; "
                    << c.dormant_points.size() << " re-observed points stay dormant";
  }
  return outcome == DriftOutcome::kCorrected;
}

void LocalMapper::Process(const KeyframeCandidate& c, bool backlog) {
  if (!InsertKeyframe(c)) return;
  const bool corrected = CheckDrift(c);
  if (!c.moved_points.empty()) {
    map_->Write([&](MapData& m) {
      for (const VertexId id : c.moved_points) m.ForgetMovedVertex(id, c.id);
    });
  }
  ExtendPoints(c);
  TriangulateNewPoints(c.id);
  const bool young = map_->Read([](const MapData& m) { return IsYoungMap(m); });
  if (corrected) {
    GlobalBundleAdjust(/*max_iterations=*/15, /*max_points=*/0);
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.loop_corrections;
  } else if (young) {
    // A young map is refined as a whole: the low-parallax initial structure must not be
    // frozen into the keyframes that later windows hold fixed.
    GlobalBundleAdjust(/*max_iterations=*/10, options_.local_ba_max_points);
  } else if (!backlog) {
    LocalBundleAdjust(c.id);
  } else {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.local_ba_deferred;
  }
  CullRecentPoints();
  CullKeyframes(c.id);
  FlushUncertainty();
  std::lock_guard<std::mutex> lock(stats_mutex_);
  ++stats_.keyframes_processed;
}

void LocalMapper::TriangulateNewPoints(KeyframeId kf_id) {
  struct Candidate {
    VertexId id;
    std::vector<KeyframeId> kfs;  // the new keyframe first
    std::vector<Eigen::Vector2d> uvs;
  };
  std::vector<Candidate> candidates;
  std::unordered_map<KeyframeId, Pose3> camera_from_world;
  map_->Read([&](const MapData& m) {
    const Keyframe* kf = m.keyframe(kf_id);
    if (kf == nullptr) return;
    camera_from_world[kf_id] = kf->world_from_camera.Inverse();
    for (size_t i = 0; i < kf->ids.size(); ++i) {
      const VertexId id = kf->ids[i];
      if (m.point(id) != nullptr) continue;
      const std::vector<KeyframeId>* seen = m.KeyframesWithFeature(id);
      if (seen == nullptr || seen->size() < 2) continue;
      Candidate c{id, {kf_id}, {kf->uvs[i]}};
      for (const KeyframeId other : *seen) {
        if (other == kf_id) continue;
        const Keyframe* o = m.keyframe(other);
        c.kfs.push_back(other);
        c.uvs.push_back(*o->Find(id));
        if (!camera_from_world.count(other))
          camera_from_world[other] = o->world_from_camera.Inverse();
      }
      candidates.push_back(std::move(c));
    }
  });
  struct NewPoint {
    VertexId id;
    Eigen::Vector3d position;
    std::vector<KeyframeId> observers;
  };
  std::vector<NewPoint> created;
  const double max_err_sq = checks_.max_reprojection_px * checks_.max_reprojection_px;
  for (const Candidate& c : candidates) {
    // Pair the new keyframe with the view of widest baseline, then collect agreeing views.
    const Pose3& cfw0 = camera_from_world[kf_id];
    const Eigen::Vector3d c0 = cfw0.Inverse().translation();
    size_t best = 0;
    double best_baseline = -1.0;
    for (size_t k = 1; k < c.kfs.size(); ++k) {
      const double b = (camera_from_world[c.kfs[k]].Inverse().translation() - c0).norm();
      if (b > best_baseline) best_baseline = b, best = k;
    }
    if (best == 0) continue;
    const auto p = TriangulateChecked(
        model_.camera, checks_, {cfw0, camera_from_world[c.kfs[best]]}, {c.uvs[0], c.uvs[best]});
    if (!p) continue;
    NewPoint np{c.id, *p, {}};
    for (size_t k = 0; k < c.kfs.size(); ++k) {
      if (ReprojectionErrorSq(model_.camera, camera_from_world[c.kfs[k]], *p, c.uvs[k]) <=
          max_err_sq) {
        np.observers.push_back(c.kfs[k]);
      }
    }
    if (np.observers.size() >= 2) created.push_back(std::move(np));
  }
  map_->Write([&](MapData& m) {
    std::vector<VertexId> ids;
    ids.reserve(created.size());
    for (const NewPoint& np : created) {
      m.AddPoint(np.id, np.position, kf_id);
      for (const KeyframeId o : np.observers) m.AddObservation(np.id, o);
      ids.push_back(np.id);
    }
    UpdateUncertainty(ids, &m);
  });
  RecentPoints recent{kf_id, {}};
  for (const NewPoint& np : created) {
    if (np.observers.size() <= 2) recent.ids.push_back(np.id);
  }
  recent_points_.push_back(std::move(recent));
  std::lock_guard<std::mutex> lock(stats_mutex_);
  stats_.points_created += static_cast<int64_t>(created.size());
}

void LocalMapper::LocalBundleAdjust(KeyframeId kf_id) {
  BaWindow window;
  BaProblem problem;
  map_->Read([&](const MapData& m) {
    window = SelectLocalBaWindow(m, kf_id, options_);
    problem = MakeBaProblem(m, window);
  });
  if (problem.keyframes.size() < 2 || problem.observations.empty()) return;
  const double solve_ms = SolveAndApply(&problem, window.rest, /*max_iterations=*/10);
  std::lock_guard<std::mutex> lock(stats_mutex_);
  stats_.last_local_ba_ms = solve_ms;
  stats_.total_local_ba_ms += solve_ms;
}

double LocalMapper::SolveAndApply(BaProblem* problem, const std::vector<VertexId>& rest,
                                  int max_iterations) {
  BundleAdjustmentOptions ba;
  ba.pixel_sigma = model_.pixel_sigma;
  ba.huber_delta_px = std::sqrt(kChi2TwoDof95) * model_.pixel_sigma;
  ba.max_iterations = max_iterations;
  ba.num_threads = options_.num_ba_threads;
  const BundleAdjustmentResult result = BundleAdjust(model_.camera, ba, problem);
  if (result.success) ApplyBundleAdjustment(*problem, result);
  RetriangulatePoints(rest);
  return result.solve_ms;
}

void LocalMapper::ExtendPoints(const KeyframeCandidate& c) {
  std::vector<VertexId> ids;
  map_->Read([&](const MapData& m) {
    const Keyframe* kf = m.keyframe(c.id);
    if (kf == nullptr) return;
    for (const VertexId id : kf->ids) {
      const MapPoint* p = m.point(id);
      if (p == nullptr || std::binary_search(p->observers.begin(), p->observers.end(), c.id))
        continue;
      ids.push_back(id);
    }
  });
  std::vector<VertexId> dormant = c.dormant_points;
  std::sort(dormant.begin(), dormant.end());
  std::erase_if(
      ids, [&](VertexId id) { return std::binary_search(dormant.begin(), dormant.end(), id); });
  RetriangulatePoints(ids, c.id);
}

void LocalMapper::RetriangulatePoints(const std::vector<VertexId>& ids,
                                      std::optional<KeyframeId> new_view) {
  if (ids.empty()) return;
  // Copy the observations under the map lock and triangulate outside it: tracking reads the
  // map on every frame and must not wait for thousands of triangulations.
  struct Job {
    VertexId id;
    size_t begin;  // range in the flat observation arrays
    size_t end;
  };
  std::vector<Job> jobs;
  std::vector<Pose3> poses;
  std::vector<Eigen::Vector2d> uvs;
  jobs.reserve(ids.size());
  map_->Read([&](const MapData& m) {
    std::unordered_map<KeyframeId, Pose3> camera_from_world;
    const Keyframe* view = new_view ? m.keyframe(*new_view) : nullptr;
    if (new_view && view == nullptr) return;
    const Pose3 view_from_world = view != nullptr ? view->world_from_camera.Inverse() : Pose3();
    for (const VertexId id : ids) {
      const MapPoint* p = m.point(id);
      if (p == nullptr || p->observers.size() < 2) continue;
      const size_t begin = poses.size();
      if (view != nullptr) {
        const Eigen::Vector2d* uv = view->Find(id);
        if (uv == nullptr) continue;
        poses.push_back(view_from_world);
        uvs.push_back(*uv);
      }
      for (const KeyframeId o : p->observers) {
        const Keyframe* kf = m.keyframe(o);
        auto it = camera_from_world.find(o);
        if (it == camera_from_world.end())
          it = camera_from_world.emplace(o, kf->world_from_camera.Inverse()).first;
        poses.push_back(it->second);
        uvs.push_back(*kf->Find(id));
      }
      jobs.push_back({id, begin, poses.size()});
    }
  });
  std::vector<std::pair<VertexId, Eigen::Vector3d>> updated;
  updated.reserve(jobs.size());
  std::vector<Pose3> job_poses;
  std::vector<Eigen::Vector2d> job_uvs;
  for (const Job& job : jobs) {
    job_poses.assign(poses.begin() + job.begin, poses.begin() + job.end);
    job_uvs.assign(uvs.begin() + job.begin, uvs.begin() + job.end);
    // Every check a new point passes (a DLT over near-parallel rays fits anywhere along them).
    const auto q = TriangulateChecked(model_.camera, checks_, job_poses, job_uvs);
    if (q) updated.emplace_back(job.id, *q);
  }
  map_->Write([&](MapData& m) {
    std::vector<VertexId> changed;
    changed.reserve(updated.size());
    for (const auto& [id, q] : updated) {
      if (m.point(id) == nullptr) continue;  // culled meanwhile
      m.SetPointPosition(id, q);
      if (new_view && m.keyframe(*new_view) != nullptr) m.AddObservation(id, *new_view);
      changed.push_back(id);
    }
    UpdateUncertainty(changed, &m);
  });
  if (new_view) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.points_extended += static_cast<int64_t>(updated.size());
  }
}

void LocalMapper::ApplyBundleAdjustment(const BaProblem& problem,
                                        const BundleAdjustmentResult& result) {
  map_->Write([&](MapData& m) {
    for (const BaKeyframe& kf : problem.keyframes) {
      if (!kf.fixed && kf.camera_from_world.AllFinite())
        m.SetKeyframePose(kf.id, kf.camera_from_world.Inverse());
    }
    for (const BaPoint& p : problem.points) {
      if (!p.fixed && p.position_world.allFinite()) m.SetPointPosition(p.id, p.position_world);
    }
    for (size_t o = 0; o < problem.observations.size() && o < result.outlier.size(); ++o) {
      if (!result.outlier[o]) continue;
      const BaObservation& obs = problem.observations[o];
      m.RemoveObservation(problem.points[obs.point_index].id,
                          problem.keyframes[obs.keyframe_index].id);
    }
    std::vector<Eigen::Vector3d> centers;
    for (const BaPoint& p : problem.points) {
      const MapPoint* mp = m.point(p.id);
      if (mp == nullptr) continue;
      if (mp->observers.size() < 2 || !p.position_world.allFinite()) {
        m.RemovePoint(p.id);
        continue;
      }
      // A point whose remaining rays are nearly parallel has no depth: BA can slide it
      // anywhere along them within the noise.
      centers.clear();
      for (const KeyframeId o : mp->observers)
        centers.push_back(m.keyframe(o)->world_from_camera.translation());
      if (!HasParallax(mp->position, centers, checks_.min_parallax_deg)) m.RemovePoint(p.id);
    }
    std::vector<VertexId> ids;
    ids.reserve(problem.points.size());
    for (const BaPoint& p : problem.points) ids.push_back(p.id);
    UpdateUncertainty(ids, &m);
  });
}

void LocalMapper::GlobalBundleAdjust(int max_iterations, int max_points) {
  BaWindow window;
  BaProblem problem;
  map_->Read([&](const MapData& m) {
    window = SelectGlobalBaWindow(m, max_points);
    problem = MakeBaProblem(m, window);
  });
  if (problem.keyframes.size() < 2) return;
  SolveAndApply(&problem, window.rest, max_iterations);
  FlushUncertainty();
  std::lock_guard<std::mutex> lock(stats_mutex_);
  ++stats_.global_bundle_adjustments;
}

void LocalMapper::UpdateUncertainty(const std::vector<VertexId>& ids, MapData* /*m*/) {
  std::lock_guard<std::mutex> lock(pending_mutex_);
  pending_uncertainty_.insert(pending_uncertainty_.end(), ids.begin(), ids.end());
}

void LocalMapper::FlushUncertainty() {
  std::vector<VertexId> ids;
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    ids.swap(pending_uncertainty_);
  }
  if (ids.empty()) return;
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  const PointGate gate{model_.pixel_sigma, options_.max_point_uncertainty,
                       checks_.max_reprojection_px};
  // This stage is the map's only writer: nothing changes between the read and the write.
  const std::vector<PointQuality> quality = map_->Read(
      [&](const MapData& m) { return EvaluatePointUncertainty(model_.camera, gate, ids, m); });
  map_->Write([&](MapData& m) { ApplyPointQuality(quality, &m); });
}

void LocalMapper::CullRecentPoints() {
  // A genuine point made from two views is re-observed by the next keyframes (ids are exact);
  // one that is not (a wrong id that happened to triangulate) goes.
  while (recent_points_.size() > static_cast<size_t>(kRecentPointKeyframes)) {
    const RecentPoints recent = std::move(recent_points_.front());
    recent_points_.pop_front();
    map_->Write([&](MapData& m) {
      for (const VertexId id : recent.ids) {
        const MapPoint* p = m.point(id);
        if (p != nullptr && p->reference_keyframe == recent.keyframe && p->observers.size() <= 2) {
          m.RemovePoint(id);
        }
      }
    });
  }
}

void LocalMapper::CullKeyframes(KeyframeId kf_id) {
  int culled = 0;
  map_->Write([&](MapData& m) {
    // A young map is still refined as a whole and its scale still settles: a keyframe culled
    // now would keep a rigid link measured before that (the frames tracked against it with it).
    if (IsYoungMap(m)) return;
    // One at a time: each removal changes what the next candidate's points are seen by.
    // The points of a culled keyframe lose an observer: their uncertainty grows.
    std::vector<VertexId> touched;
    auto cull = [&](KeyframeId id) {
      const Keyframe* kf = m.keyframe(id);
      if (kf != nullptr) touched.insert(touched.end(), kf->ids.begin(), kf->ids.end());
      CullKeyframe(&m, id);
      ++culled;
    };
    for (const KeyframeId id : CullingCandidates(m, kf_id, options_)) {
      if (IsRedundant(m, id, options_)) cull(id);
    }
    // Bounded map: beyond max_keyframes, the oldest keyframes (but the first) go.
    while (const std::optional<KeyframeId> oldest = OldestBeyondBound(m, kf_id, options_)) {
      cull(*oldest);
    }
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    UpdateUncertainty(touched, &m);
  });
  if (culled > 0) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.keyframes_culled += culled;
  }
}

}  // namespace m2s::slam
