// What the single-session System (slam_system.h) and the agents of a map group (map_group.h)
// share: taking a frame in, the trajectory records and how they follow map changes, the start
// of tracking after initialisation, and the rules for young maps and merges.
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
// SmoothLooseFrames: a frame is loosely determined when its centre's standard deviation is
// above kLooseCentreSigmaFraction of its points' median depth (the worst frames of the
// scene-diversity runs are all above it, docs/design/dense_objects.md), unless its squared
// reprojection errors average below kExactDataVarianceFactor of the model's (2 per point, 6
// for the pose: exact data, whose points' centre stands). Anchors at most
// kSmoothingConsecutiveS apart count as consecutive; a frame is smoothed from anchors at most
// kSmoothingMaxSpanS from it, with the deviation of at least kSmoothingMinSamples anchors
// within kSmoothingWindowS of it.
constexpr double kLooseCentreSigmaFraction = 0.01;
constexpr double kExactDataVarianceFactor = 0.01;
constexpr double kSmoothingConsecutiveS = 0.1;
constexpr double kSmoothingMaxSpanS = 1.0;
constexpr double kSmoothingWindowS = 1.0;
constexpr int kSmoothingMinSamples = 5;
// System::RefineMap: iterations of the global bundle adjustment over every keyframe and point.
constexpr int kFinalBaIterations = 20;
// RefineMap: the map points a frame without a pose is solved on, at least. SmoothLooseFrames
// gives such a frame whose points fix its rotation but not its centre the interpolated centre
// when the interpolation's deviation is within kUnposedPriorSigmaFraction of the points'
// depth (the scanned-objects drone with occlusion: its frames at 2.0-2.2 % end 2-7 mm off;
// of the two at 4.0-4.2 %, one would be 37 mm off; docs/design/map_refinement.md).
constexpr int kUnposedMinPoints = 20;
constexpr double kUnposedPriorSigmaFraction = 0.025;

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

// Re-solves the pose of a tracked frame that is not a keyframe against `map` (after a global
// bundle adjustment): pose-only, from its current estimate, on the map points it observed.
// The record's pose relative to its reference keyframe takes the result when the solve
// converges with at least 75 % of those observations as inliers (tracking's sparse-view
// rule). Returns whether it did.
bool RefineFramePose(const MeasurementModel& model, const MapData& map, TrajectoryRecord* record);

// Gives poses on `map` (the map `map_id`, after RefineMap's bundle adjustment) to frames that
// have none (lost, or waiting for a map) and kept their features, between two frames with a
// pose in that map. Each is solved pose-only on the map points among its features twice:
// starting from the nearest frame with a pose before it (a sweep forward in time, each solved
// frame starting the next, as tracking solves from the previous frame) and from the nearest
// after it (a sweep backward). A solve counts when at least `min_points` map points are seen,
// 75 % of them inliers (tracking's sparse-view rule), and they determine the camera's centre
// within 1 % of their median depth, or fit it as exact data (noise-free features: their
// squared errors below kExactDataVarianceFactor of the model's); the frame takes the pose when
// both solves count and agree within 1 % of that depth and 1 degree, or when one counts and
// the other found no inliers at all from its start (a fast turn since the frame it started
// from: no second opinion). A frame with a pose on one side only (before the map's first
// posed frame, after its last) takes its sweep's pose when a solve started from PnP + RANSAC
// on the same points (no start needed) agrees with it the same way, unless the map is young
// (at most kSmallMapKeyframes keyframes). It then counts as tracked, relative to the reference
// keyframe of the posed frame its sweep came from. Returns how many frames got a pose.
int SolveUnposedFrames(const MeasurementModel& model, const MapData& map, int map_id,
                       int min_points, std::vector<TrajectoryRecord>* records);

// Smooths, on `map` (the map `map_id`, after RefineMap's re-solves), the frames whose points
// leave the centre loosely determined (its standard deviation for pixel_sigma noise above
// kLooseCentreSigmaFraction of their median depth): the centre the points
// give is fused, by their covariance, with the one interpolated in time between the nearest
// well-determined frames (or keyframes) on either side, whose deviation is that of anchors
// from their neighbours' interpolation within kSmoothingWindowS, grown with the span; the
// rotation is refitted to the frame's bearings from the fused centre. `max_points`: the
// tracker's (dense views are judged on an even subset, its information scaled up).
// Frames still without a pose that see at least kUnposedMinPoints map points, between two
// well-determined frames at most kSmoothingMaxSpanS from them, take the centre interpolated
// between those two and the rotation their points fit there (most of them within the
// chi-square bound, widened by the centre's deviation), when that deviation is within
// kUnposedPriorSigmaFraction of the points' median depth. The deviation is measured, not
// grown: the RMS distance of the well-determined frames within kSmoothingWindowS from the
// interpolation between frames the same span apart around each (the motion's curvature and
// the poses' noise at that span). They then count as tracked, relative to the nearest posed
// frame's reference keyframe. Returns how many frames it moved and how many it posed.
struct SmoothedFrames {
  int smoothed = 0;  // frames with a pose moved
  int posed = 0;     // frames without one given one
};
SmoothedFrames SmoothLooseFrames(const MeasurementModel& model, const MapData& map, int map_id,
                                 int max_points, std::vector<TrajectoryRecord>* records);

}  // namespace m2s::slam
