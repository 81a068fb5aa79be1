// The concrete System: validation -> initialisation / tracking (calling thread, or the tracking
// thread fed by the latest-wins input queue) -> bounded keyframe queue -> local mapping thread
// (inline when Options::deterministic). See m2s/slam/system.h for the contract.
//
// Threads: Track() and the tracking thread serialise on track_mutex_; mapping runs in
// mapping_thread_ and is the map's only writer while it runs; Reset/LoadMap stop mapping, change
// the map, and start it again. Shutdown stops the queues (end of stream), discards queued frames
// and keyframes, and joins both threads.
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
  Status SaveMap(const std::string& path) const override;
  Status LoadMap(const std::string& path) override;
  void Shutdown() override;

 private:
  // What the trajectory keeps per frame: the pose relative to its reference keyframe, so
  // later refinement of keyframes (BA, drift correction) refines every frame.
  struct Record {
    int64_t seq = 0;
    double timestamp = 0.0;
    TrackingState state = TrackingState::kNotInitialized;
    Pose3 world_from_camera;  // at tracking time (used when the reference is unknown)
    std::optional<KeyframeId> reference;
    Pose3 reference_from_camera;
    bool is_keyframe = false;
    std::optional<Pose3> ground_truth;
  };

  TrackResult TrackLocked(const Frame& frame);
  TrackResult Initialise(const Frame& frame, const SortedFeatures& features, TrackResult result);
  void ResetLocked(bool keep_localization_only);
  void StartMapping();
  void StopMapping(bool discard_queued);
  void MappingLoop();
  void TrackingLoop();
  void AppendRecord(const Record& record);

  Options options_;
  Map map_;
  FrameValidator validator_;
  FeatureGrid budget_grid_;  // the feature budget's cells, from the camera
  Initializer initializer_;
  Tracker tracker_;
  LocalMapper mapper_;
  bool localization_only_;
  int lost_streak_ = 0;

  std::mutex track_mutex_;
  BoundedQueue<Frame> input_;
  BoundedQueue<TrackResult> results_;
  BoundedQueue<KeyframeCandidate> keyframes_;
  std::mutex threads_mutex_;
  std::thread tracking_thread_;
  std::thread mapping_thread_;
  std::atomic<bool> shut_down_{false};

  mutable std::mutex trajectory_mutex_;
  std::vector<Record> trajectory_;

  mutable std::mutex stats_mutex_;
  SystemStats stats_;  // frame counters (map and queue figures are filled in by Stats())
};

}  // namespace m2s::slam
