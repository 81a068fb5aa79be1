// One client session inside the SessionManager: a slam::System, its worker thread and a
// bounded latest-wins frame queue. Internal to server_app.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "m2s/common/wire_format.h"
#include "m2s/server_app/session_manager.h"
#include "m2s/slam/system.h"

namespace m2s::server_app {

// Every field equal (a session's frames, and an agent and its map group, share one camera).
bool SameCamera(const Camera& a, const Camera& b);

class Session {
 public:
  using Clock = std::chrono::steady_clock;

  // Starts the worker unless the manager is synchronous.
  // `owner` is the bus sender that opened the session (0 on an open bus or in-process).
  Session(SessionManager* manager, int64_t id, uint64_t owner, const Camera& camera,
          std::unique_ptr<slam::System> system);
  ~Session();  // Finish()

  // Caller's (IO) thread: checks the sequence number (strictly increasing, by at most
  // ServerOptions::max_seq_jump, from 0 before the first frame) and the camera, then queues
  // the frame (or tracks it now in synchronous mode) and counts it as activity. False with the
  // reason when the frame is not usable; a refused frame does not keep the session alive.
  bool Accept(wire::FeatureFrame frame, wire::DropReason* reason, std::string* detail);
  void RequestResync();
  void RequestReset();
  void Touch();
  double IdleSeconds(Clock::time_point now) const;
  // Stops the worker (queued frames are discarded and counted as skipped).
  void Stop();
  // Stop(), join, save the map when save_dir is not empty, shut the System down.
  void Finish(const std::string& save_dir);
  // Waits until the queue is empty and nothing is being processed.
  void Drain();

  int64_t id() const { return id_; }
  uint64_t owner() const { return owner_; }
  const Camera& camera() const { return camera_; }

 private:
  void WorkerLoop();
  void Process(const wire::FeatureFrame& frame);
  void PublishDelta();
  void PublishFull();
  // Synchronous mode: serves a resync / reset requested while not processing.
  void ServicePendingSync();

  SessionManager* const manager_;
  const int64_t id_;
  const uint64_t owner_;
  const Camera camera_;
  const std::chrono::duration<double> map_period_;
  std::unique_ptr<slam::System> system_;

  mutable std::mutex mutex_;  // guards the members below
  std::condition_variable cv_;
  std::condition_variable idle_cv_;
  std::deque<wire::FeatureFrame> queue_;
  int64_t last_seq_ = 0;
  Clock::time_point last_activity_;
  bool stop_ = false;
  bool busy_ = false;
  bool resync_pending_ = false;
  bool reset_pending_ = false;
  bool finished_ = false;

  // Touched only by the thread that tracks (worker, or the caller in synchronous mode).
  int64_t revision_ = 0;
  Clock::time_point next_map_time_;
  std::mutex sync_mutex_;  // synchronous mode: one tracking caller at a time

  std::thread worker_;
};

}  // namespace m2s::server_app
