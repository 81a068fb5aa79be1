#include "session.h"

#include <filesystem>

#include "m2s/common/logging.h"
#include "m2s/server_app/messages.h"

namespace m2s::server_app {

bool SameCamera(const Camera& a, const Camera& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy && a.near == b.near && a.far == b.far;
}

Session::Session(SessionManager* manager, int64_t id, uint64_t owner, const Camera& camera,
                 std::unique_ptr<slam::System> system)
    : manager_(manager),
      id_(id),
      owner_(owner),
      camera_(camera),
      map_period_(1.0 / manager->options().map_rate_hz),
      system_(std::move(system)),
      last_activity_(manager->Now()),
      next_map_time_(Clock::now()) {
  if (!manager_->options().synchronous) worker_ = std::thread([this] { WorkerLoop(); });
}

Session::~Session() { Finish(""); }

bool Session::Accept(wire::FeatureFrame frame, wire::DropReason* reason, std::string* detail) {
  const bool synchronous = manager_->options().synchronous;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stop_) {
      *reason = wire::DropReason::kEndedSession;
      *detail = "session " + std::to_string(id_) + " is ending";
      return false;
    }
    if (frame.seq <= last_seq_) {
      *reason = wire::DropReason::kSeqNotIncreasing;
      *detail = "session " + std::to_string(id_) + ": seq " + std::to_string(frame.seq) +
                " after " + std::to_string(last_seq_);
      return false;
    }
    if (frame.seq - last_seq_ > manager_->options().max_seq_jump) {
      *reason = wire::DropReason::kSeqJump;
      *detail = "session " + std::to_string(id_) + ": seq " + std::to_string(frame.seq) +
                " after " + std::to_string(last_seq_);
      return false;
    }
    if (!SameCamera(frame.camera, camera_)) {
      *reason = wire::DropReason::kCameraChanged;
      *detail = "session " + std::to_string(id_) + ": frame camera differs from the session's";
      return false;
    }
    last_seq_ = frame.seq;
    last_activity_ = manager_->Now();
    if (!synchronous) {
      while (static_cast<int>(queue_.size()) >= manager_->options().queue_capacity) {
        queue_.pop_front();
        manager_->CountSkipped();
      }
      queue_.push_back(std::move(frame));
      cv_.notify_one();
      return true;
    }
    busy_ = true;
  }
  {
    std::lock_guard<std::mutex> tracking(sync_mutex_);
    Process(frame);
    PublishDelta();
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    busy_ = false;
  }
  ServicePendingSync();
  return true;
}

void Session::RequestResync() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    last_activity_ = manager_->Now();
    resync_pending_ = true;
    cv_.notify_one();
  }
  if (manager_->options().synchronous) ServicePendingSync();
}

void Session::RequestReset() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    last_activity_ = manager_->Now();
    reset_pending_ = true;
    cv_.notify_one();
  }
  if (manager_->options().synchronous) ServicePendingSync();
}

void Session::ServicePendingSync() {
  bool resync = false;
  bool reset = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (busy_) return;  // served by the frame being processed, after it
    resync = resync_pending_;
    reset = reset_pending_;
    resync_pending_ = reset_pending_ = false;
    if (!resync && !reset) return;
    busy_ = true;
  }
  {
    std::lock_guard<std::mutex> tracking(sync_mutex_);
    if (reset) system_->Reset();
    if (reset || resync) PublishFull();
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    busy_ = false;
  }
  ServicePendingSync();  // a request that arrived while publishing
}

void Session::Touch() {
  std::lock_guard<std::mutex> lock(mutex_);
  last_activity_ = manager_->Now();
}

double Session::IdleSeconds(Clock::time_point now) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return std::chrono::duration<double>(now - last_activity_).count();
}

void Session::Stop() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (stop_) return;
  stop_ = true;
  for (size_t i = 0; i < queue_.size(); ++i) manager_->CountSkipped();
  queue_.clear();
  cv_.notify_all();
  idle_cv_.notify_all();
}

void Session::Finish(const std::string& save_dir) {
  Stop();
  if (worker_.joinable()) worker_.join();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_) return;
    finished_ = true;
  }
  std::lock_guard<std::mutex> tracking(sync_mutex_);
  if (!save_dir.empty() && system_) {
    const std::string path =
        (std::filesystem::path(save_dir) / ("session_" + std::to_string(id_) + kMapFileExtension))
            .string();
    const Status saved = system_->SaveMap(path);
    if (saved) {
      M2S_LOG(kInfo) << "session " << id_ << ": map saved to " << path;
    } else {
      M2S_LOG(kWarning) << "session " << id_ << ": saving the map failed: " << saved.message();
    }
  }
  if (system_) system_->Shutdown();
}

void Session::Drain() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_cv_.wait(lock, [this] {
    return stop_ || (queue_.empty() && !busy_ && !resync_pending_ && !reset_pending_);
  });
}

void Session::WorkerLoop() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (true) {
    cv_.wait_until(lock, next_map_time_, [this] {
      return stop_ || !queue_.empty() || resync_pending_ || reset_pending_;
    });
    if (stop_) break;
    std::optional<wire::FeatureFrame> frame;
    if (!queue_.empty()) {
      frame = std::move(queue_.front());
      queue_.pop_front();
    }
    const bool resync = resync_pending_;
    const bool reset = reset_pending_;
    resync_pending_ = reset_pending_ = false;
    busy_ = true;
    lock.unlock();

    if (reset) system_->Reset();
    if (frame) Process(*frame);
    if (reset || resync) PublishFull();
    if (Clock::now() >= next_map_time_) {
      PublishDelta();
      next_map_time_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(map_period_);
    }

    lock.lock();
    busy_ = false;
    if (queue_.empty() && !resync_pending_ && !reset_pending_) idle_cv_.notify_all();
  }
  busy_ = false;
  idle_cv_.notify_all();
}

void Session::Process(const wire::FeatureFrame& frame) {
  const slam::TrackResult result = system_->Track(ToSlamFrame(frame));
  manager_->RecordTrackingTime(result.tracking_ms);
  manager_->CountProcessed();
  manager_->Publish(
      wire::kPoseChannel,
      wire::Encode(ToPoseMessage(result, frame, manager_->server_instance(), revision_)));
}

void Session::PublishDelta() {
  const slam::MapDelta delta = system_->TakeMapDelta();
  if (delta.empty() && !delta.full) return;
  const int64_t base = revision_;
  ++revision_;
  manager_->Publish(wire::kMapChannel,
                    wire::Encode(ToMapMessage(delta, id_, manager_->server_instance(),
                                              delta.full ? 0 : base, revision_)));
}

void Session::PublishFull() {
  // Changes not yet sent are part of the full map; the next delta repeats them (upserts and
  // removals are idempotent), so the replica stays consistent.
  slam::MapDelta full = system_->FullMap();
  full.full = true;
  ++revision_;
  manager_->Publish(wire::kMapChannel, wire::Encode(ToMapMessage(
                                           full, id_, manager_->server_instance(), 0, revision_)));
}

}  // namespace m2s::server_app
