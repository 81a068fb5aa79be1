#include "mapping/local_mapper.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <unordered_set>

#include "m2s/common/logging.h"
#include "optimization/problems.h"

namespace m2s::slam {
namespace {

// Fixed keyframes in a local BA: at most this multiple of the window (most shared first).
constexpr int kFixedKeyframesPerWindow = 2;
// A point is well observed for keyframe redundancy when this many other keyframes see it.
constexpr int kRedundancyObservers = 3;
// Covisibility needed to count as a neighbour in the local window.
constexpr int kMinCovisiblePoints = 15;
// Points created from two views must gain an observation within this many keyframes.
constexpr int kRecentPointKeyframes = 3;
// Maps with at most this many keyframes get a global BA per keyframe instead of a local one.
constexpr int kGlobalBaKeyframes = 10;

BundleAdjustmentOptions MakeBaOptions(const Options& options, int max_iterations) {
  BundleAdjustmentOptions ba;
  ba.pixel_sigma = options.pixel_sigma;
  ba.huber_delta_px = std::sqrt(5.991) * options.pixel_sigma;
  ba.max_iterations = max_iterations;
  ba.num_threads = options.num_ba_threads;
  return ba;
}

}  // namespace

LocalMapper::LocalMapper(const Options& options, Map* map)
    : options_(options), map_(map), drift_(options, map) {
  checks_.min_parallax_deg = options.min_triangulation_parallax_deg;
  checks_.max_reprojection_px = std::sqrt(5.991) * options.pixel_sigma;
}

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
  });
  std::lock_guard<std::mutex> lock(stats_mutex_);
  stats_.points_created += static_cast<int64_t>(initial.point_ids.size());
}

void LocalMapper::Process(const KeyframeCandidate& c, bool backlog) {
  // A drift correction published after the tracker made this candidate moved the world: carry
  // the pose over (as the tracker does for its own pose), or drop the candidate when more than
  // one correction happened in between (only the latest is known).
  Pose3 world_from_camera = c.world_from_camera;
  const WorldCorrection correction = map_->correction();
  if (correction.epoch != c.correction_epoch) {
    if (correction.epoch != c.correction_epoch + 1) {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++stats_.keyframes_dropped_stale;
      return;
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
  });
  bool corrected = false;
  if (!c.dormant_points.empty()) {
    DriftDecision decision = DriftDecision::kConsistent;
    if (options_.drift_correction &&
        static_cast<int>(c.dormant_points.size()) >= options_.loop_min_points) {
      decision = drift_.Check(c.id, c.dormant_points);
    }
    if (decision != DriftDecision::kDeferred) {
      // Old points are re-observed: from now on they are ordinary observations.
      map_->Write([&](MapData& m) {
        for (const VertexId id : c.dormant_points) m.AddObservation(id, c.id);
      });
    }
    corrected = decision == DriftDecision::kCorrected;
  }
  ExtendPoints(c);
  TriangulateNewPoints(c.id);
  const size_t num_keyframes = map_->Read([](const MapData& m) { return m.keyframes().size(); });
  if (corrected) {
    GlobalBundleAdjust(/*max_iterations=*/15, /*max_points=*/0);
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.loop_corrections;
  } else if (num_keyframes <= static_cast<size_t>(kGlobalBaKeyframes)) {
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
        options_.camera, checks_, {cfw0, camera_from_world[c.kfs[best]]}, {c.uvs[0], c.uvs[best]});
    if (!p) continue;
    NewPoint np{c.id, *p, {}};
    for (size_t k = 0; k < c.kfs.size(); ++k) {
      if (ReprojectionErrorSq(options_.camera, camera_from_world[c.kfs[k]], *p, c.uvs[k]) <=
          max_err_sq) {
        np.observers.push_back(c.kfs[k]);
      }
    }
    if (np.observers.size() >= 2) created.push_back(std::move(np));
  }
  map_->Write([&](MapData& m) {
    for (const NewPoint& np : created) {
      m.AddPoint(np.id, np.position, kf_id);
      for (const KeyframeId o : np.observers) m.AddObservation(np.id, o);
    }
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
  BaProblem problem;
  std::vector<VertexId> rest;  // window points left out of the BA (re-triangulated after it)
  map_->Read([&](const MapData& m) {
    std::vector<KeyframeId> window = {kf_id};
    for (const auto& [other, shared] : m.Covisible(kf_id, kMinCovisiblePoints)) {
      if (static_cast<int>(window.size()) >= options_.local_ba_window) break;
      window.push_back(other);
    }
    std::sort(window.begin(), window.end());
    std::unordered_map<KeyframeId, int> kf_index;
    for (const KeyframeId id : window) {
      kf_index[id] = static_cast<int>(problem.keyframes.size());
      problem.keyframes.push_back({id, m.keyframe(id)->world_from_camera.Inverse(), false});
    }
    // Points seen by the window; other observers become fixed keyframes (most shared first).
    std::vector<VertexId> point_ids;
    std::unordered_set<VertexId> seen;
    std::unordered_map<KeyframeId, int> outside;
    for (const KeyframeId id : window) {
      const Keyframe* kf = m.keyframe(id);
      for (const VertexId vid : kf->ids) {
        const MapPoint* p = m.point(vid);
        if (p == nullptr || !std::binary_search(p->observers.begin(), p->observers.end(), id))
          continue;
        if (!seen.insert(vid).second) continue;
        point_ids.push_back(vid);
        for (const KeyframeId o : p->observers) {
          if (!kf_index.count(o)) ++outside[o];
        }
      }
    }
    std::vector<std::pair<int, KeyframeId>> fixed;
    for (const auto& [id, n] : outside) fixed.emplace_back(n, id);
    std::sort(fixed.begin(), fixed.end(), [](const auto& a, const auto& b) {
      return a.first != b.first ? a.first > b.first : a.second > b.second;
    });
    const size_t max_fixed =
        static_cast<size_t>(kFixedKeyframesPerWindow * options_.local_ba_window);
    if (fixed.size() > max_fixed) fixed.resize(max_fixed);
    std::sort(fixed.begin(), fixed.end(),
              [](const auto& a, const auto& b) { return a.second < b.second; });
    for (const auto& [n, id] : fixed) {
      kf_index[id] = static_cast<int>(problem.keyframes.size());
      problem.keyframes.push_back({id, m.keyframe(id)->world_from_camera.Inverse(), true});
    }
    // Without an outside keyframe, hold the oldest window keyframe (the gauge); keyframe 0 and
    // its partner stay fixed while they are in the window, so early windows keep the scale.
    if (fixed.empty() && !problem.keyframes.empty()) problem.keyframes[0].fixed = true;
    std::sort(point_ids.begin(), point_ids.end());
    const int cap = options_.local_ba_max_points;
    if (cap > 0 && static_cast<int>(point_ids.size()) > cap) {
      std::vector<VertexId> kept;
      const double step = static_cast<double>(point_ids.size()) / cap;
      double next = 0.0;
      for (size_t i = 0; i < point_ids.size(); ++i) {
        if (static_cast<double>(i) >= next) {
          kept.push_back(point_ids[i]);
          next += step;
        } else {
          rest.push_back(point_ids[i]);
        }
      }
      point_ids.swap(kept);
    }
    for (const VertexId vid : point_ids) {
      const MapPoint* p = m.point(vid);
      const int pi = static_cast<int>(problem.points.size());
      problem.points.push_back({vid, p->position, false});
      for (const KeyframeId o : p->observers) {
        const auto it = kf_index.find(o);
        if (it == kf_index.end()) continue;
        problem.observations.push_back({it->second, pi, *m.keyframe(o)->Find(vid)});
      }
    }
  });
  if (problem.keyframes.size() < 2 || problem.observations.empty()) return;
  const BundleAdjustmentResult result =
      BundleAdjust(options_.camera, MakeBaOptions(options_, 10), &problem);
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.last_local_ba_ms = result.solve_ms;
    stats_.total_local_ba_ms += result.solve_ms;
  }
  if (result.success) ApplyBundleAdjustment(problem, result);
  RetriangulatePoints(rest);
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
    const auto q = TriangulateChecked(options_.camera, checks_, job_poses, job_uvs);
    if (q) updated.emplace_back(job.id, *q);
  }
  map_->Write([&](MapData& m) {
    for (const auto& [id, q] : updated) {
      if (m.point(id) == nullptr) continue;  // culled meanwhile
      m.SetPointPosition(id, q);
      if (new_view && m.keyframe(*new_view) != nullptr) m.AddObservation(id, *new_view);
    }
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
  });
}

void LocalMapper::GlobalBundleAdjust(int max_iterations, int max_points) {
  BaProblem problem;
  std::vector<VertexId> rest;
  map_->Read([&](const MapData& m) {
    std::unordered_map<KeyframeId, int> kf_index;
    for (const auto& [id, kf] : m.keyframes()) {
      kf_index[id] = static_cast<int>(problem.keyframes.size());
      problem.keyframes.push_back({id, kf.world_from_camera.Inverse(), problem.keyframes.empty()});
    }
    std::vector<VertexId> ids;
    for (const auto& [id, p] : m.points()) ids.push_back(id);
    std::sort(ids.begin(), ids.end());
    const double step = max_points > 0 && static_cast<int>(ids.size()) > max_points
                            ? static_cast<double>(ids.size()) / max_points
                            : 1.0;
    double next = 0.0;
    for (size_t i = 0; i < ids.size(); ++i) {
      const VertexId vid = ids[i];
      if (static_cast<double>(i) < next) {
        rest.push_back(vid);
        continue;
      }
      next += step;
      const MapPoint* p = m.point(vid);
      const int pi = static_cast<int>(problem.points.size());
      problem.points.push_back({vid, p->position, false});
      for (const KeyframeId o : p->observers) {
        problem.observations.push_back({kf_index.at(o), pi, *m.keyframe(o)->Find(vid)});
      }
    }
  });
  if (problem.keyframes.size() < 2) return;
  const BundleAdjustmentResult result =
      BundleAdjust(options_.camera, MakeBaOptions(options_, max_iterations), &problem);
  if (result.success) ApplyBundleAdjustment(problem, result);
  RetriangulatePoints(rest);
  std::lock_guard<std::mutex> lock(stats_mutex_);
  ++stats_.global_bundle_adjustments;
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
    if (m.keyframes().size() <= static_cast<size_t>(kGlobalBaKeyframes)) return;
    const KeyframeId first = m.keyframes().begin()->first;
    auto remove = [&](KeyframeId id) {
      const Keyframe* kf = m.keyframe(id);
      std::optional<KeyframeLink> link;
      // The link is rigid: the nearest covisible keyframe keeps its lever arm, and so the
      // error of a later change of scale around it, smallest.
      // Without a well-covisible one, the most covisible (Covisible sorts by shared points).
      const auto covisible = m.Covisible(id, 1);
      double nearest = std::numeric_limits<double>::infinity();
      for (const auto& [other, shared] : covisible) {
        if (shared < kMinCovisiblePoints) break;
        const Keyframe* o = m.keyframe(other);
        const double d = (o->world_from_camera.translation() - kf->world_from_camera.translation())
                             .squaredNorm();
        if (d < nearest) {
          nearest = d;
          link = KeyframeLink{other, o->world_from_camera.Inverse() * kf->world_from_camera};
        }
      }
      if (!link && !covisible.empty()) {
        const Keyframe* o = m.keyframe(covisible.front().first);
        link = KeyframeLink{o->id, o->world_from_camera.Inverse() * kf->world_from_camera};
      }
      if (!link) {
        // No covisible keyframe: link to the previous one by id.
        auto it = m.keyframes().find(id);
        const auto& prev =
            it == m.keyframes().begin() ? std::next(it)->second : std::prev(it)->second;
        link = KeyframeLink{prev.id, prev.world_from_camera.Inverse() * kf->world_from_camera};
      }
      std::vector<VertexId> touched;
      for (const VertexId vid : kf->ids) {
        if (m.point(vid) != nullptr) touched.push_back(vid);
      }
      m.RemoveKeyframe(id, link);
      for (const VertexId vid : touched) {
        const MapPoint* p = m.point(vid);
        if (p != nullptr && p->observers.size() < 2) m.RemovePoint(vid);
      }
      ++culled;
    };
    std::vector<KeyframeId> neighbours;
    for (const auto& [other, shared] : m.Covisible(kf_id, kMinCovisiblePoints)) {
      if (static_cast<int>(neighbours.size()) >= options_.local_ba_window) break;
      neighbours.push_back(other);
    }
    for (const KeyframeId id : neighbours) {
      if (id == first || id == kf_id) continue;
      const Keyframe* kf = m.keyframe(id);
      int observed = 0, redundant = 0;
      for (const VertexId vid : kf->ids) {
        const MapPoint* p = m.point(vid);
        if (p == nullptr || !std::binary_search(p->observers.begin(), p->observers.end(), id))
          continue;
        ++observed;
        if (static_cast<int>(p->observers.size()) - 1 >= kRedundancyObservers) ++redundant;
      }
      if (observed > 0 && redundant >= options_.keyframe_redundancy * observed) remove(id);
    }
    // Bounded map: beyond max_keyframes, the oldest keyframes (but the first) go.
    while (static_cast<int>(m.keyframes().size()) > options_.max_keyframes) {
      const KeyframeId oldest = std::next(m.keyframes().begin())->first;
      if (oldest == kf_id) break;
      remove(oldest);
    }
  });
  if (culled > 0) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.keyframes_culled += culled;
  }
}

}  // namespace m2s::slam
