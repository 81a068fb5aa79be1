// Local mapping: inserts the keyframes tracking hands over, triangulates new points from ids
// seen in two or more keyframes, runs the local bundle adjustment over the covisible window
// (mapping/ba_window.h: other keyframes observing the window's points held fixed), culls
// outlier observations, unsupported points and redundant keyframes (mapping/keyframe_culling.h),
// and asks the drift corrector to close loops: re-observed old points become observations when
// it finds that the old map agrees (or after it corrected it), and stay dormant otherwise.
//
// Thread-safety: one mapper, called from one thread (the mapping thread, or inline in
// deterministic mode); it is the map's only writer while tracking runs.
//
//   LocalMapper mapper(options.measurement(), options.mapper, options.drift, &map);
//   mapper.InsertInitialMap(initial, kf0, kf1);
//   mapper.Process(candidate);   // per keyframe
#pragma once

#include <atomic>
#include <deque>
#include <memory>
#include <vector>

#include "m2s/slam/system.h"
#include "map/map.h"
#include "mapping/ba_window.h"
#include "mapping/drift_corrector.h"
#include "mapping/triangulation.h"
#include "optimization/problems.h"
#include "tracking/initializer.h"
#include "tracking/tracker.h"

namespace m2s::slam {

struct MappingStats {
  int64_t keyframes_processed = 0;
  int64_t points_created = 0;
  int64_t keyframes_culled = 0;
  int64_t loop_corrections = 0;
  int64_t global_bundle_adjustments = 0;
  int64_t keyframes_dropped_stale = 0;  // made before two or more drift corrections
  int64_t local_ba_deferred = 0;        // local BAs left to the next keyframe (mapping backlog)
  int64_t points_extended = 0;  // observations added by ExtendPoints (re-triangulated with them)
  double last_local_ba_ms = 0.0;
  double total_local_ba_ms = 0.0;
};

class LocalMapper {
 public:
  LocalMapper(const MeasurementModel& model, const MapperOptions& options,
              const DriftOptions& drift, Map* map);

  // Writes the two initial keyframes and their points (ids reserved by the caller).
  void InsertInitialMap(const InitialMap& initial, KeyframeId first, KeyframeId second);
  // Processes one keyframe: insert, drift check, triangulate, local BA, cull. With `backlog`
  // (more keyframes are waiting) the local BA is left to the next keyframe, whose window covers
  // this one: new points first, so that tracking keeps map points ahead of a fast camera.
  void Process(const KeyframeCandidate& candidate, bool backlog = false);
  // Bundle adjustment of the whole map (first keyframe fixed); with max_points > 0 at most
  // that many points (evenly spread over ids) enter it and the others are re-triangulated.
  void GlobalBundleAdjust(int max_iterations, int max_points);

  MappingStats stats() const;

 private:
  // Inserts the keyframe (its pose carried through a drift correction made since tracking
  // proposed it); false when it is stale (made before two or more corrections) and dropped.
  bool InsertKeyframe(const KeyframeCandidate& candidate);
  // The drift check of the candidate's dormant points, and their observations merged when the
  // old map agrees or was corrected; true after a correction.
  bool CheckDrift(const KeyframeCandidate& candidate);
  void TriangulateNewPoints(KeyframeId kf_id);
  void LocalBundleAdjust(KeyframeId kf_id);
  void CullKeyframes(KeyframeId kf_id);
  void CullRecentPoints();
  // Multi-view DLT of points from all their observers (poses as they are now), with the
  // triangulation checks; a point that fails keeps its position. With `new_view`, that
  // keyframe's measurement of each point joins the DLT and, when all of them agree, becomes an
  // observation: a point whose depth was poorly known (low parallax) and which tracking
  // therefore rejected gets the wider baseline that fixes it.
  void RetriangulatePoints(const std::vector<VertexId>& ids,
                           std::optional<KeyframeId> new_view = std::nullopt);
  // The new keyframe's measurements of mapped points it does not observe yet (except those
  // left to the drift check), through RetriangulatePoints(ids, keyframe).
  void ExtendPoints(const KeyframeCandidate& candidate);
  // Solves a BA problem and applies it, then re-triangulates the window's points left out of
  // it (`rest`). Returns the solve time (ms).
  double SolveAndApply(BaProblem* problem, const std::vector<VertexId>& rest, int max_iterations);
  // Applies a solved BA problem: poses, positions, outlier observations, unsupported points.
  void ApplyBundleAdjustment(const BaProblem& problem, const BundleAdjustmentResult& result);
  // Marks the points `ids` for re-evaluation of whether they are well constrained (inside
  // map_->Write; every change of a point's position, observers or observers' poses goes
  // through it); FlushUncertainty() evaluates them under the map's shared lock and writes the
  // result under the exclusive one, at the end of each public entry point.
  void UpdateUncertainty(const std::vector<VertexId>& ids, MapData* m);
  void FlushUncertainty();

  MeasurementModel model_;
  MapperOptions options_;
  DriftOptions drift_options_;
  Map* map_;
  TriangulationChecks checks_;
  DriftCorrector drift_;
  // Two-view points of the last keyframes, checked for new observations.
  struct RecentPoints {
    KeyframeId keyframe = 0;
    std::vector<VertexId> ids;
  };
  std::deque<RecentPoints> recent_points_;
  mutable std::mutex stats_mutex_;
  MappingStats stats_;
  std::mutex pending_mutex_;
  std::vector<VertexId> pending_uncertainty_;
};

}  // namespace m2s::slam
