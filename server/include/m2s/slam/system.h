// The public API of the SLAM library (m2s::slam). The server executable and the on-device
// client use only this header.
//
// A System turns a stream of vertex-feature frames into camera poses and a sparse map. Map
// points are keyed by VertexId (a vertex is one 3-D point). Poses are world_from_camera with
// OpenCV camera axes (x right, y down, z forward); the world frame and scale are those of the
// monocular initialisation (first keyframe at the origin, median scene depth 1).
//
// Threading: Track()/Submit() are called from one producer thread; local mapping, loop
// (drift) correction and global BA run in their own threads unless Options::deterministic,
// where they run inline in Track() so results are bit-identical run to run. Every other method
// is safe to call from any thread.
//
//   auto system = slam::System::Create(options);        // Expected<std::unique_ptr<System>>
//   slam::TrackResult r = (*system)->Track(frame);      // synchronous
//   slam::MapDelta delta = (*system)->TakeMapDelta();   // changes since the last call
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/status.h"
#include "m2s/common/types.h"
#include "m2s/slam/options.h"

namespace m2s::slam {

enum class TrackingState {
  kNotInitialized = 0,  // waiting for two frames with enough parallax
  kOk = 1,              // tracked against the map
  kLost = 2,            // tracking failed; relocalising on the next frames
  kRelocalized = 3,     // this frame was relocalised against the map
  kRejected = 4,        // the frame was invalid and not used (see TrackResult::reject_reason)
};
const char* ToString(TrackingState state);

struct Frame {
  int64_t seq = 0;         // strictly increasing within a session
  double timestamp = 0.0;  // capture time, seconds
  std::vector<VertexFeature> features;
  // Ground truth, kept only for evaluation (never read by tracking).
  std::optional<Pose3> ground_truth_world_from_camera;
};

struct TrackResult {
  int64_t seq = 0;
  double timestamp = 0.0;
  TrackingState state = TrackingState::kNotInitialized;
  Pose3 world_from_camera;  // valid when state is kOk or kRelocalized
  int num_features = 0;
  int num_inliers = 0;
  bool keyframe_created = false;
  double tracking_ms = 0.0;
  std::string reject_reason;  // set when state == kRejected
  // The map the pose is in (TrajectoryEntry::map_id, as it was when the frame was tracked).
  int map_id = 0;
};

struct KeyframeState {
  KeyframeId id = 0;
  double timestamp = 0.0;
  Pose3 world_from_camera;
  // Created by the agent the delta is for (false: by another agent of its map group).
  bool own = true;
};

// Map changes between two revisions. Apply in order: a receiver at `base_revision` moves to
// `revision`; a full delta (base_revision 0) replaces everything.
struct MapDelta {
  uint64_t base_revision = 0;
  uint64_t revision = 0;
  bool full = false;
  std::vector<KeyframeState> keyframes;  // upserted
  std::vector<KeyframeId> removed_keyframes;
  std::vector<VertexId> point_ids;  // upserted, parallel to point_positions
  std::vector<Eigen::Vector3f> point_positions;
  std::vector<VertexId> removed_points;
  bool empty() const {
    return keyframes.empty() && removed_keyframes.empty() && point_ids.empty() &&
           removed_points.empty();
  }
};

struct TrajectoryEntry {
  int64_t seq = 0;
  double timestamp = 0.0;
  TrackingState state = TrackingState::kNotInitialized;
  Pose3 world_from_camera;  // latest estimate (refined by BA and drift correction for keyframes)
  bool is_keyframe = false;
  std::optional<Pose3> ground_truth_world_from_camera;
  // The map the pose is expressed in. Maps are numbered from 0 in the order they start; a map
  // merged into another takes that one's number. Poses of the current map (SystemStats::
  // current_map) form one trajectory in one world; other numbers are maps never merged.
  int map_id = 0;
};

struct SystemStats {
  int64_t frames_submitted = 0;
  int64_t frames_processed = 0;      // frames tracking took (valid or rejected), once each
  int64_t frames_tracked = 0;        // OK or relocalised (the initialiser's reference frame too)
  int64_t frames_dropped_queue = 0;  // dropped by the latest-wins input queue
  int mapping_queue = 0;             // keyframes waiting for the mapping thread now
  int64_t frames_rejected = 0;       // invalid frames (reasons counted below)
  int64_t features_over_budget = 0;  // valid features left out by Options::feature_budget
  int64_t frames_lost = 0;
  int64_t relocalisations = 0;
  int64_t loop_corrections = 0;
  // Multi-map: maps started (the first included), merges of a set-aside map into the current
  // one, the current map's number, and tracked frames whose map was never merged into it
  // (counted in frames_tracked too; their poses are in another world).
  int maps_created = 0;
  int64_t map_merges = 0;
  int current_map = 0;
  int64_t frames_in_unmerged_maps = 0;
  int keyframes = 0;
  int map_points = 0;
  uint64_t map_revision = 0;
  // Rejected frames by reason ("empty", "duplicate_id", "non_finite_uv", ...).
  std::map<std::string, int64_t> rejected_by_reason;
};

class System {
 public:
  static Expected<std::unique_ptr<System>> Create(const Options& options);
  virtual ~System() = default;  // stops and joins every thread

  // Tracks one frame now, in the calling thread.
  virtual TrackResult Track(const Frame& frame) = 0;

  // Asynchronous mode (the paper's): enqueue into the latest-wins queue; a tracking thread
  // processes frames and WaitForResult() hands out results in order. When tracking is behind,
  // the oldest queued frame is dropped and counted (SystemStats::frames_dropped_queue).
  virtual void Submit(Frame frame) = 0;
  // Waits up to timeout_s for the next result; false on timeout or after Shutdown().
  virtual bool WaitForResult(TrackResult* result, double timeout_s) = 0;

  // Map changes since the previous call (empty when nothing changed).
  virtual MapDelta TakeMapDelta() = 0;
  // The whole map as a full delta, for resync; does not disturb TakeMapDelta().
  virtual MapDelta FullMap() const = 0;

  virtual std::vector<TrajectoryEntry> Trajectory() const = 0;
  virtual SystemStats Stats() const = 0;

  // Forgets the map and the trajectory; the next frames initialise again.
  virtual void Reset() = 0;
  // Saves / loads the map (keyframes, points, observations). Loading switches to
  // localisation-only tracking.
  virtual Status SaveMap(const std::string& path) const = 0;
  virtual Status LoadMap(const std::string& path) = 0;

  // Refines the whole current map by a global bundle adjustment (every keyframe and point, as
  // at the end of a session), then re-solves every other tracked frame of that map on the
  // refined map from the observations it kept (Options::frame_observations_kept), solves
  // frames returned without a pose on it from the features they kept when the map determines
  // them, smooths the frames whose points leave their centre loosely determined between the
  // well-determined frames around them, and gives frames still without a pose whose points fix
  // only their rotation the centre interpolated between those (docs/design/map_refinement.md).
  // Trajectory() follows;
  // the poses and states Track() returned stay as they were. Tracking may go on. Systems without
  // a map of their own (a plug-in method, a map group's agent) and a loaded map tracked in
  // localisation-only mode are left as they are.
  virtual void RefineMap() {}

  // Stops every thread (queued frames are discarded); idempotent, also done by the destructor.
  virtual void Shutdown() = 0;
};

// The camera a saved map file was made with (size and intrinsics; near and far are the
// defaults): the camera of the System or MapGroup that is to load it.
Expected<Camera> ReadMapFileCamera(const std::string& path);

struct GroupStats {
  int agents_joined = 0;  // every Join() so far
  int agents_active = 0;  // joined and not yet shut down
  // Agents' own maps merged into the group's map, and how long each merge took from the
  // agent's first keyframe that shared enough points with the group's map to the merged map
  // (milliseconds; the most recent merges, oldest first).
  int64_t merges = 0;
  std::vector<double> merge_ms;
  int keyframes = 0;   // in the group's map
  int map_points = 0;  // in the group's map
  bool localization_only = false;
};

// A map shared by several agents (a map group, e.g. the headsets in one room). Each agent is a
// System of its own (its frames, trajectory, results, deltas) whose map is the group's: an agent
// that joins a non-empty group first relocalises in the group's map by vertex id (no
// initialisation where the map covers its view); otherwise, or when it stays lost, it builds a
// map of its own and merges it into the group's as soon as the two share enough vertex ids
// (map/map_merge.h); from then on its poses, including those tracked before the merge, are in
// the group's world. Mapping of the whole group (the group's map and the agents' own maps) runs
// in one thread (inline in Track() when Options::deterministic). An agent that shuts down
// leaves its keyframes in the group's map. Trajectory map ids: 0 is the group's map, agents'
// own maps are numbered from 1.
//
//   auto group = slam::MapGroup::Create(options);            // Expected<shared_ptr<MapGroup>>
//   auto agent = (*group)->Join();                           // Expected<unique_ptr<System>>
//   (*agent)->Track(frame);
//
// Thread-safety: every method may be called from any thread; an agent may outlive its group
// object only as long as it holds it (each agent keeps the group alive).
class MapGroup {
 public:
  // All agents share options.camera (and the other options).
  static Expected<std::shared_ptr<MapGroup>> Create(const Options& options);
  virtual ~MapGroup() = default;

  virtual Expected<std::unique_ptr<System>> Join() = 0;
  virtual GroupStats Stats() const = 0;
  virtual const Options& options() const = 0;
  // The group's map. Loading one makes the group localisation-only (a shared anchor): agents
  // relocalise and track in it and never change it. Loading fails while agents are active.
  virtual Status SaveMap(const std::string& path) const = 0;
  virtual Status LoadMap(const std::string& path) = 0;
  // Loads a saved map and keeps mapping into it (a server restarted after it stopped: its
  // agents relocalise in the map they built before and extend it). Fails while agents are
  // active.
  virtual Status ResumeMap(const std::string& path) = 0;
};

}  // namespace m2s::slam
