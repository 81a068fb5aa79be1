// How a System's frames reach its tracking function: now, in the caller's thread (Track), or
// through the latest-wins input queue and a tracking thread started on the first Submit(), with
// results handed out in order by WaitForResult(). Both paths run the tracking function under one
// mutex, which Reset/LoadMap take too (Exclusive).
//
//   FrameRunner runner(capacity, [this](const Frame& f) { return TrackLocked(f); });
//   runner.Submit(frame);  ...  runner.WaitForResult(&result, 1.0);
//   runner.Stop();         // end of stream: queued frames discarded, the thread joined
//
// Thread-safety: every method may be called from any thread.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>

#include "m2s/slam/system.h"
#include "system/bounded_queue.h"

namespace m2s::slam {

class FrameRunner {
 public:
  using TrackFn = std::function<TrackResult(const Frame&)>;
  // Results waiting for WaitForResult(); beyond this the oldest are dropped (nobody reads them).
  static constexpr size_t kResultQueueCapacity = 4096;

  FrameRunner(size_t input_capacity, TrackFn track)
      : track_(std::move(track)),
        input_(input_capacity, BoundedQueue<Frame>::Policy::kDropOldest),
        results_(kResultQueueCapacity, BoundedQueue<TrackResult>::Policy::kDropOldest) {}
  ~FrameRunner() { Stop(); }
  FrameRunner(const FrameRunner&) = delete;
  FrameRunner& operator=(const FrameRunner&) = delete;

  TrackResult Track(const Frame& frame) {
    ++submitted_;
    std::lock_guard<std::mutex> lock(track_mutex_);
    return track_(frame);
  }

  void Submit(Frame frame) {
    {
      std::lock_guard<std::mutex> lock(thread_mutex_);
      if (stopped_) return;
      if (!thread_.joinable()) thread_ = std::thread([this] { Loop(); });
    }
    ++submitted_;
    input_.Push(std::move(frame));
  }

  bool WaitForResult(TrackResult* result, double timeout_s) {
    auto r = results_.PopFor(timeout_s);
    if (!r) return false;
    *result = std::move(*r);
    return true;
  }

  // Runs f() with queued frames discarded and no frame being tracked.
  template <typename F>
  decltype(auto) Exclusive(F&& f) {
    std::lock_guard<std::mutex> lock(track_mutex_);
    input_.Clear();
    return f();
  }

  int64_t submitted() const { return submitted_; }
  int64_t dropped() const { return input_.dropped(); }

  // Idempotent; WaitForResult() returns false from now on.
  void Stop() {
    std::thread thread;
    {
      std::lock_guard<std::mutex> lock(thread_mutex_);
      if (stopped_) return;
      stopped_ = true;
      thread = std::move(thread_);
    }
    input_.Clear();
    input_.Stop();
    if (thread.joinable()) thread.join();
    results_.Stop();
  }

 private:
  void Loop() {
    while (auto frame = input_.Pop()) {
      TrackResult r;
      {
        std::lock_guard<std::mutex> lock(track_mutex_);
        r = track_(*frame);
      }
      results_.Push(std::move(r));
    }
  }

  const TrackFn track_;
  std::atomic<int64_t> submitted_{0};
  std::mutex track_mutex_;
  BoundedQueue<Frame> input_;
  BoundedQueue<TrackResult> results_;
  std::mutex thread_mutex_;
  bool stopped_ = false;
  std::thread thread_;
};

}  // namespace m2s::slam
