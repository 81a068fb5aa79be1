// The concrete System: validation -> initialisation / tracking (calling thread, or the tracking
// thread fed by the latest-wins input queue) -> bounded keyframe queue -> local mapping thread
// (inline when Options::deterministic). See m2s/slam/system.h for the contract. slam_system.cc
// holds the frame path, results and map I/O; slam_system_maps.cc initialisation and multi-map.
//
// Multi-map: when tracking stays lost (MultiMapOptions), the map is set aside and a new one
// initialises from the next frames. After each keyframe the mapping stage tries to align every
// set-aside map with the current one on their shared vertex ids (map/map_merge.h); the first
// that fits is the base the current map merges into: the current map's keyframes and points
// move by the fitted Sim3 into the set-aside map's world, the move is published as a world
// correction (tracking carries its pose over, as after drift correction), a global BA refines
// the union, and the trajectory records of the merged map follow.
//
// Threads: Track() and the tracking thread serialise in runner_ (FrameRunner); mapping runs in
// mapping_thread_ and is the map's only writer while it runs (merges included); Reset/LoadMap
// and starting a new map stop mapping, change the map, and start it again. Shutdown stops the
// queues (end of stream), discards queued frames and keyframes, and joins both threads.
// In real time (not Options::deterministic) the frames between a new map's two views are solved
// after it, a few after each tracked frame (the solves of a few dozen frames took most of the
// initialisation's time), and all of them before a merge, a new map or RefineMap.
// Lock order: inbetween_mutex_, then trajectory_mutex_, then maps_mutex_, then the map's own
// lock.
#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "m2s/common/feature_rank.h"
#include "m2s/slam/system.h"
#include "map/map.h"
#include "mapping/local_mapper.h"
#include "system/bounded_queue.h"
#include "system/frame_runner.h"
#include "system/system_common.h"
#include "tracking/frame_validation.h"
#include "tracking/initializer.h"
#include "tracking/tracker.h"

namespace m2s::slam {

class SlamSystem final : public System {
 public:
  explicit SlamSystem(const Options& options);
  ~SlamSystem() override;

  TrackResult Track(const Frame& frame) override;
  void Submit(Frame frame) override;
  bool WaitForResult(TrackResult* result, double timeout_s) override;
  MapDelta TakeMapDelta() override;
  MapDelta FullMap() const override;
  std::vector<TrajectoryEntry> Trajectory() const override;
  SystemStats Stats() const override;
  void Reset() override;
  void RefineMap() override;
  Status SaveMap(const std::string& path) const override;
  Status LoadMap(const std::string& path) override;
  void Shutdown() override;

 private:
  using Record = TrajectoryRecord;
  // The last merge: records tracked in the merged map before it (an older correction epoch)
  // and appended after it are moved likewise.
  struct MergeNotice {
    uint64_t epoch = 0;
    int from_map = 0;
    int into_map = 0;
    Sim3 into_from_from;
  };
  // A map set aside when tracking stayed lost in it, until it merges.
  struct SetAsideMap {
    int id = 0;
    MapData data;
  };

  TrackResult TrackLocked(const Frame& frame);
  TrackResult Initialise(const Frame& frame, const SortedFeatures& features, TrackResult result);
  // Starts the current (empty) map from an initial map whose second view is the frame of
  // `result`, already recorded: the records of its two views and of the frames between them
  // that it explains get their poses.
  TrackResult StartFromInitialMap(InitialMap initial, TrackResult result);
  // Solves frames between the current map's two views still pending (inbetween_) for about
  // `budget_ms` (at least one frame; all with a negative budget) and gives their records
  // their poses.
  void SolvePendingInbetween(double budget_ms);
  void ResetInitializers();
  void ResetLocked(bool keep_localization_only);
  Status LoadMapLocked(const std::string& path);
  void StartMapping();
  void StopMapping(bool discard_queued);
  void MappingLoop();
  // Appends the record, setting its map (the current one) and moving it into the merged
  // map's world when it was tracked just before a merge.
  void AppendRecord(Record* record);
  // Lost-time bookkeeping after a tracked or lost frame; may start a new map (or discard a
  // young one).
  void HandleLost(const TrackerOutput& out, const Frame& frame, const SortedFeatures& features);
  // Sets the current map aside (when `keep`; otherwise drops it) and starts a new one.
  void StartNewMap(bool keep);
  // Merges the current map into the first set-aside map that aligns with it (the map's
  // writer calls this: the mapping thread, or Track() in deterministic mode).
  void TryMergeSetAsideMaps();
  // Reset/LoadMap: no set-aside maps, the next map is map 0 again.
  void ForgetMapsLocked();
  // Moves a record of map `notice.from_map` into the merged map's world.
  static void MoveRecordInto(const MergeNotice& notice, Record* record);

  Options options_;
  Map map_;
  FrameValidator validator_;
  FeatureGrid budget_grid_;  // the feature budget's cells, from the camera
  Initializer initializer_;
  // A new map's second initialiser, from the earliest full view of the lost frames (HandleLost),
  // while seeded_reference_ (its reference's seq) holds.
  Initializer seeded_initializer_;
  std::optional<int64_t> seeded_reference_;
  Tracker tracker_;
  LocalMapper mapper_;
  bool localization_only_;
  int lost_streak_ = 0;
  std::optional<double> lost_since_;  // frame time of the first lost frame that counts
  // The lost frames that count (at most max_reference_age + 1): the next map's initialiser
  // starts from them.
  std::vector<InitialFrame> lost_frames_;
  int tracked_in_map_ = 0;  // frames tracked in the current map

  BoundedQueue<KeyframeCandidate> keyframes_;
  std::mutex threads_mutex_;
  std::thread mapping_thread_;
  std::atomic<bool> shut_down_{false};

  mutable std::mutex trajectory_mutex_;
  std::vector<Record> trajectory_;

  mutable std::mutex maps_mutex_;
  std::vector<SetAsideMap> set_aside_;
  int current_map_ = 0;  // written under trajectory_mutex_ and maps_mutex_
  int maps_created_ = 1;
  int64_t map_merges_ = 0;
  std::optional<MergeNotice> last_merge_;  // under trajectory_mutex_

  // The frames between the current map's two views still to solve (SolvePendingInbetween),
  // with the map's first keyframe and the map.
  struct PendingInbetween {
    InbetweenSolver solver;
    KeyframeId first = 0;
    int map_id = 0;
  };
  std::mutex inbetween_mutex_;
  std::optional<PendingInbetween> inbetween_;

  mutable std::mutex stats_mutex_;
  SystemStats stats_;  // frame counters (map and queue figures are filled in by Stats())

  FrameRunner runner_;  // last: constructed when everything TrackLocked() uses is
};

}  // namespace m2s::slam
