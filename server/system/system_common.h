// What the single-session System (slam_system.h) and the agents of a map group (map_group.h)
// share: taking a frame in, the trajectory records and how they follow map changes, the start
// of tracking after initialisation, and the rules for young maps and merges. The refinement of
// the records at the end of a session is trajectory_refinement.h.
//
// A record keeps the pose relative to its reference keyframe, so later refinement of the
// keyframes (BA, drift correction, merges) refines every frame; the pose at tracking time is the
// fallback when the reference is gone.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <vector>

#include "m2s/slam/system.h"
#include "map/map_data.h"
#include "map/map_merge.h"
#include "tracking/feature_budget.h"
#include "tracking/frame_validation.h"
#include "tracking/initializer.h"
#include "tracking/tracker.h"

namespace m2s::slam {

struct TrajectoryRecord {
  int64_t seq = 0;
  double timestamp = 0.0;
  TrackingState state = TrackingState::kNotInitialized;
  Pose3 world_from_camera;  // at tracking time (used when the reference is unknown)
  std::optional<KeyframeId> reference;
  Pose3 reference_from_camera;
  bool is_keyframe = false;
  std::optional<Pose3> ground_truth;
  int map_id = 0;
  uint64_t correction_epoch = 0;  // the world the poses are in (Map::correction())
  // At most Options::frame_observations_kept of TrackerOutput::observed_ids/uvs, for
  // RefineFramePose.
  std::vector<VertexId> observed_ids{};
  std::vector<Eigen::Vector2f> observed_uvs{};
};

// A map this young (at most kSmallMapKeyframes keyframes, fewer than kYoungMapFrames frames
// tracked in it) that stays lost kLostFramesBeforeReinit frames in a row was initialised badly:
// it is dropped and initialisation starts over.
constexpr int kLostFramesBeforeReinit = 10;
constexpr int kSmallMapKeyframes = 4;
constexpr int kYoungMapFrames = 60;
inline bool IsYoungMap(size_t keyframes, int tracked_in_map) {
  return keyframes <= static_cast<size_t>(kSmallMapKeyframes) && tracked_in_map < kYoungMapFrames;
}
// Iterations of the global bundle adjustment that refines two maps after a merge.
constexpr int kMergeBaIterations = 15;
// A merge's Sim3 must hold in the keyframes' images (MapAlignmentOptions::camera): this
// fraction of the observations of shared points within this many pixel sigmas (chi-square
// with 2 degrees of freedom at 98.9 %). A wrong Sim3 that fits the shared points in 3D
// reprojects 1-2 % of them (testmodels drone, noisy); a right one fitted to a young map's
// depth errors a third or more (scanned-objects drone with occlusion: 36 %).
constexpr double kMergeImageErrorSigmas = 3.0;
constexpr double kMergeMinImageAgreement = 0.25;
// How two maps of a system or a group are aligned for a merge (multi_map options, the camera).
MapAlignmentOptions MergeAlignmentOptions(const Options& options);
inline bool HasPose(TrackingState state) {
  return state == TrackingState::kOk || state == TrackingState::kRelocalized;
}

inline double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// The start of tracking one frame: `result` gets the frame's identity, the frame is validated
// and its features sorted and budgeted into `features`. Returns false (result filled) for a
// frame that is not tracked: invalid, or after shutdown. Counts into `stats` (the caller holds
// its lock): frames processed, rejected (by reason), features over the budget.
bool TakeFrame(const Frame& frame, bool shut_down, int feature_budget, const FeatureGrid& grid,
               FrameValidator* validator, SortedFeatures* features, TrackResult* result,
               SystemStats* stats);

// Moves a record into another map's world: x_new = new_from_old * x_old.
void MoveRecord(const Sim3& new_from_old, int new_map_id, TrajectoryRecord* record);

// After a two-view initialisation: the initial map's first and second frames (records with
// those seqs) are the keyframes `first` and `second` of map `map_id`, and the frames between
// the two views that the initial map explains (InitialMap::inbetween) are tracked relative to
// the first, each keeping at most `kept` of its observations. Records of the frames between
// that have a pose already are left alone.
struct InitialFramesMarked {
  int64_t marked = 0;    // records given a pose
  int64_t was_lost = 0;  // of them, records counted lost
};
InitialFramesMarked MarkInitialFrames(const InitialMap& initial, KeyframeId first,
                                      KeyframeId second, int map_id, int kept,
                                      std::vector<TrajectoryRecord>* records);
// The same for one frame between the two views solved later (InbetweenSolver), its record
// found by seq.
InitialFramesMarked MarkInbetweenFrame(const InitialInbetween& frame, KeyframeId first, int map_id,
                                       int kept, std::vector<TrajectoryRecord>* records);

// Starts `tracker` from the initial map's second keyframe `second`.
void StartTracking(const InitialMap& initial, KeyframeId second, double timestamp,
                   Tracker* tracker);

// The record's current estimate: through its reference keyframe in `map` (nullptr: the map is
// gone, the pose at tracking time).
TrajectoryEntry ToEntry(const TrajectoryRecord& record, const MapData* map);

// Keeps an even subset of at most `kept` of the observations (ids and pixels, parallel) in
// the record: the tracker's associated points for a tracked frame, the frame's features for
// one without a pose.
void KeepObservations(const std::vector<VertexId>& ids, const std::vector<Eigen::Vector2d>& uvs,
                      int kept, TrajectoryRecord* record);

}  // namespace m2s::slam
