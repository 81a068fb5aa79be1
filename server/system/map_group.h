// The concrete MapGroup (m2s/slam/system.h): one map shared by several agents.
//
// MapGroupImpl owns the group's map, its LocalMapper and the group's one mapping thread, fed by
// a bounded queue of keyframes from every agent (inline in Track() when Options::deterministic).
// GroupAgent is one agent's System: frame validation, its initialiser, a tracker on the group's
// map and one on a map of its own, and its trajectory.
//
// An agent tracks in the group's map whenever it can: it relocalises there by vertex id when it
// joins a non-empty group or after a loss. An agent that joins an empty group initialises the
// group's map. An agent that stays lost in the group's map (MultiMapOptions) starts a map of its
// own (map ids 1, 2, ... across the group); after each of that map's keyframes the mapping
// thread aligns it with the group's map on their shared vertex ids and, as soon as they fit,
// copies it into the group's map (moved by the fitted Sim3, keyframes renumbered) and tells the
// agent, which moves its records into the group's world and relocalises in the group's map on its
// next frame.
//
// Threads and locks: every write of any map of the group (the group's and the agents' own) runs
// under mapping_mutex_: the mapping thread's steps, and an agent's initialisation or switch of
// maps. Lock order: an agent's FrameRunner (tracking), then the group's mapping_mutex_, then
// agents_mutex_, then an agent's records_mutex_ / notice_mutex_, then a map's own lock. Each agent
// holds a shared_ptr to its group; the group knows its active agents by raw pointer and forgets one
// in Leave() (called by the agent's Shutdown), after which no mapping step touches it.
#pragma once

#include <atomic>
#include <chrono>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <unordered_map>
#include <vector>

#include "m2s/slam/system.h"
#include "map/map.h"
#include "mapping/local_mapper.h"
#include "system/bounded_queue.h"
#include "system/frame_runner.h"
#include "system/system_common.h"
#include "tracking/feature_budget.h"
#include "tracking/frame_validation.h"
#include "tracking/initializer.h"
#include "tracking/tracker.h"

namespace m2s::slam {

class GroupAgent;

class MapGroupImpl final : public MapGroup, public std::enable_shared_from_this<MapGroupImpl> {
 public:
  static constexpr int kGroupMapId = 0;

  explicit MapGroupImpl(const Options& options);
  ~MapGroupImpl() override;

  Expected<std::unique_ptr<System>> Join() override;
  GroupStats Stats() const override;
  const Options& options() const override { return options_; }
  Status SaveMap(const std::string& path) const override;
  Status LoadMap(const std::string& path) override;
  Status ResumeMap(const std::string& path) override;

  // ---- for the agents ----
  Map& map() { return map_; }
  const Map& map() const { return map_; }
  bool localization_only() const { return localization_only_; }
  bool mapping_busy() const { return !options_.deterministic && jobs_.full(); }
  int mapping_queue() const { return static_cast<int>(jobs_.size()); }
  std::mutex& mapping_mutex() { return mapping_mutex_; }
  int NewMapId() { return next_map_id_++; }
  // Writes an initial map into the group's map (when it is still empty and `prefer_group`) or
  // into the agent's own map (a fresh own map id); returns the map id it went to. Takes
  // mapping_mutex_.
  int InsertInitialMap(GroupAgent* agent, const InitialMap& initial, bool prefer_group,
                       KeyframeId* first, KeyframeId* second);
  // Maps a keyframe of `map_id` (the group's or the agent's own map): queued for the mapping
  // thread, or mapped now in deterministic mode.
  void MapKeyframe(GroupAgent* agent, int map_id, KeyframeCandidate keyframe);
  // The group map's changes since this agent's previous call (own flags set for `agent`).
  MapDelta TakeDeltaFor(int agent);
  MapDelta FullDeltaFor(int agent) const;
  // The next delta of this agent is a full one (after it switched maps).
  void ResetDeltaFor(int agent);
  void Leave(GroupAgent* agent);

 private:
  struct Job {
    int agent = 0;
    int map_id = 0;
    KeyframeCandidate keyframe;
    std::chrono::steady_clock::time_point queued;
  };
  void MappingLoop();
  // One mapping step; mapping_mutex_ held.
  void RunJobLocked(const Job& job);
  // Merges the agent's own map into the group's map when they align; mapping_mutex_ held.
  void TryMergeLocked(GroupAgent* agent, int map_id, std::chrono::steady_clock::time_point queued);
  GroupAgent* FindAgent(int index) const;
  void MarkOwner(KeyframeId id, int agent);
  void SetOwnFlags(int agent, MapDelta* delta) const;
  Status Load(const std::string& path, bool localization_only);

  const Options options_;
  Map map_;
  LocalMapper mapper_;
  std::atomic<bool> localization_only_;
  std::atomic<int> next_map_id_{1};

  std::mutex mapping_mutex_;
  BoundedQueue<Job> jobs_;
  std::thread mapping_thread_;

  mutable std::mutex agents_mutex_;
  std::map<int, GroupAgent*> agents_;  // active agents by index
  int agents_joined_ = 0;
  std::unordered_map<KeyframeId, int> keyframe_owner_;
  std::unordered_map<int, std::chrono::steady_clock::time_point> first_shared_;  // own map id
  int64_t merges_ = 0;
  std::deque<double> merge_ms_;

  mutable std::mutex deltas_mutex_;
  std::map<int, MapDelta> pending_deltas_;  // per active agent
};

class GroupAgent final : public System {
 public:
  GroupAgent(std::shared_ptr<MapGroupImpl> group, int index);
  ~GroupAgent() override;

  TrackResult Track(const Frame& frame) override;
  void Submit(Frame frame) override;
  bool WaitForResult(TrackResult* result, double timeout_s) override;
  MapDelta TakeMapDelta() override;
  MapDelta FullMap() const override;
  std::vector<TrajectoryEntry> Trajectory() const override;
  SystemStats Stats() const override;
  // Forgets this agent's trajectory and own map (the group's map stays); it relocalises in the
  // group's map, or initialises when that is empty.
  void Reset() override;
  // The group's map.
  Status SaveMap(const std::string& path) const override;
  // Refused: a group's map is loaded through MapGroup::LoadMap.
  Status LoadMap(const std::string& path) override;
  void Shutdown() override;

  // ---- for the group (mapping_mutex_ held) ----
  int index() const { return index_; }
  // The own map being built, or nullopt while tracking in the group's map.
  std::optional<int> own_map_id() const;
  Map& own_map() { return own_map_; }
  LocalMapper& own_mapper() { return own_mapper_; }
  // Makes `map_id` the agent's own map (a fresh one when the id is new).
  void UseOwnMapLocked(int map_id);
  // The own map `map_id` was copied into the group's map: group_from_own moves its world, `ids`
  // renumbers its keyframes. Applied on the agent's next frame.
  void NotifyMerged(int map_id, const Sim3& group_from_own,
                    std::unordered_map<KeyframeId, KeyframeId> ids);

 private:
  struct MergeNotice {
    int map_id = 0;
    Sim3 group_from_own;
    std::unordered_map<KeyframeId, KeyframeId> ids;
  };
  TrackResult TrackLocked(const Frame& frame);
  void ResetLocked();
  TrackResult Initialise(const Frame& frame, const SortedFeatures& features, TrackResult result);
  // After a merge (NotifyMerged): the agent relocalises in the group's map.
  void SwitchToGroupMapIfMerged();
  static void MoveMergedRecord(const MergeNotice& notice, TrajectoryRecord* record);
  void HandleLost(TrackingState state, double timestamp, size_t num_features);
  // Leaves the current map for a fresh own map (mapping_mutex_ taken here).
  void StartOwnMap();
  // Relocalisation in the group's map while the own map is not initialised; on success the
  // agent is in the group's map again.
  std::optional<TrackerOutput> TryGroupMap(const Frame& frame, const SortedFeatures& features);
  void AppendRecord(TrajectoryRecord record);

  const std::shared_ptr<MapGroupImpl> group_;
  const int index_;
  const Options options_;
  FrameValidator validator_;
  FeatureGrid budget_grid_;
  Initializer initializer_;
  Map own_map_;
  LocalMapper own_mapper_;
  Tracker group_tracker_;
  Tracker own_tracker_;
  std::atomic<int> own_map_id_{-1};  // -1: in the group's map
  std::optional<double> lost_since_;
  int lost_streak_ = 0;
  int tracked_in_map_ = 0;

  std::atomic<bool> shut_down_{false};

  std::mutex notice_mutex_;
  bool switch_pending_ = false;

  mutable std::mutex records_mutex_;
  std::vector<TrajectoryRecord> records_;
  std::optional<MergeNotice> last_merge_;
  SystemStats stats_;  // frame counters, maps_created (1 + own maps initialised), map_merges

  FrameRunner runner_;  // last: constructed when everything TrackLocked() uses is
};

}  // namespace m2s::slam
