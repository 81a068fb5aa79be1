#include "system/slam_system.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "tracking/feature_budget.h"

namespace m2s::slam {
namespace {

// Results waiting for WaitForResult(); beyond this the oldest are dropped (nobody reads them).
constexpr size_t kResultQueueCapacity = 4096;
// Lost this many frames in a row with a map this small: the initialisation was bad, start over.
constexpr int kLostFramesBeforeReinit = 10;
constexpr int kSmallMapKeyframes = 4;

double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

Expected<std::unique_ptr<System>> System::Create(const Options& options) {
  if (Status valid = options.Check(); !valid) return valid.Prefixed("invalid SLAM options: ");
  return std::unique_ptr<System>(std::make_unique<SlamSystem>(options));
}

SlamSystem::SlamSystem(const Options& options)
    : options_(options),
      validator_(options.camera, options.max_features_per_frame, options.image_margin_px),
      budget_grid_(FeatureGrid::ForImage(options.camera.width, options.camera.height)),
      initializer_(options.measurement(), options.initializer, options.mapper.num_ba_threads),
      tracker_(options.measurement(), options.tracker, options.drift, &map_),
      mapper_(options.measurement(), options.mapper, options.drift, &map_),
      localization_only_(options.localization_only),
      input_(static_cast<size_t>(options.input_queue_capacity),
             BoundedQueue<Frame>::Policy::kDropOldest),
      results_(kResultQueueCapacity, BoundedQueue<TrackResult>::Policy::kDropOldest),
      keyframes_(static_cast<size_t>(options.mapping_queue_capacity),
                 BoundedQueue<KeyframeCandidate>::Policy::kBlock) {
  tracker_.SetLocalizationOnly(localization_only_);
  StartMapping();
}

SlamSystem::~SlamSystem() { Shutdown(); }

void SlamSystem::StartMapping() {
  if (options_.deterministic) return;
  std::lock_guard<std::mutex> lock(threads_mutex_);
  keyframes_.Restart();
  mapping_thread_ = std::thread([this] { MappingLoop(); });
}

void SlamSystem::StopMapping(bool discard_queued) {
  std::lock_guard<std::mutex> lock(threads_mutex_);
  if (discard_queued) keyframes_.Clear();
  keyframes_.Stop();
  if (mapping_thread_.joinable()) mapping_thread_.join();
}

void SlamSystem::MappingLoop() {
  if (options_.mapping_nice > 0) {
    // Per-thread niceness (Linux): tracking, the latency-critical stage, wins the CPU.
    const auto tid = static_cast<id_t>(syscall(SYS_gettid));
    const int nice = getpriority(PRIO_PROCESS, tid) + options_.mapping_nice;
    if (setpriority(PRIO_PROCESS, tid, std::min(nice, 19)) != 0)
      M2S_LOG(kWarning) << "could not lower the mapping thread's priority";
  }
  while (auto kf = keyframes_.Pop()) mapper_.Process(*kf, /*backlog=*/keyframes_.size() > 0);
}

void SlamSystem::TrackingLoop() {
  while (auto frame = input_.Pop()) {
    TrackResult r;
    {
      std::lock_guard<std::mutex> lock(track_mutex_);
      r = TrackLocked(*frame);
    }
    results_.Push(std::move(r));
  }
}

TrackResult SlamSystem::Track(const Frame& frame) {
  std::lock_guard<std::mutex> lock(track_mutex_);
  {
    std::lock_guard<std::mutex> s(stats_mutex_);
    ++stats_.frames_submitted;
  }
  return TrackLocked(frame);
}

void SlamSystem::Submit(Frame frame) {
  if (shut_down_) return;
  {
    std::lock_guard<std::mutex> lock(threads_mutex_);
    if (shut_down_) return;
    if (!tracking_thread_.joinable()) tracking_thread_ = std::thread([this] { TrackingLoop(); });
  }
  {
    std::lock_guard<std::mutex> s(stats_mutex_);
    ++stats_.frames_submitted;
  }
  input_.Push(std::move(frame));
}

bool SlamSystem::WaitForResult(TrackResult* result, double timeout_s) {
  if (shut_down_) return false;
  auto r = results_.PopFor(timeout_s);
  if (!r) return false;
  *result = std::move(*r);
  return true;
}

void SlamSystem::AppendRecord(const Record& record) {
  std::lock_guard<std::mutex> lock(trajectory_mutex_);
  trajectory_.push_back(record);
}

TrackResult SlamSystem::TrackLocked(const Frame& frame) {
  const auto t0 = std::chrono::steady_clock::now();
  TrackResult result;
  result.seq = frame.seq;
  result.timestamp = frame.timestamp;
  result.num_features = static_cast<int>(frame.features.size());
  if (shut_down_) {
    result.state = TrackingState::kRejected;
    result.reject_reason = "shut_down";
    return result;
  }
  {
    std::lock_guard<std::mutex> s(stats_mutex_);
    ++stats_.frames_processed;
  }
  SortedFeatures features;
  if (const Status valid = validator_.Validate(frame, &features); !valid) {
    const char* reason = ToString(*valid.reason());
    result.state = TrackingState::kRejected;
    result.reject_reason = reason;
    std::lock_guard<std::mutex> s(stats_mutex_);
    ++stats_.frames_rejected;
    ++stats_.rejected_by_reason[reason];
    return result;
  }
  if (const size_t removed = ApplyFeatureBudget(options_.feature_budget, budget_grid_, &features)) {
    std::lock_guard<std::mutex> s(stats_mutex_);
    stats_.features_over_budget += static_cast<int64_t>(removed);
  }
  if (!tracker_.started()) {
    if (localization_only_) {
      tracker_.StartLost();
    } else {
      result = Initialise(frame, features, result);
      result.tracking_ms = MsSince(t0);
      return result;
    }
  }
  const bool mapping_busy = !options_.deterministic && keyframes_.full();
  TrackerOutput out = tracker_.Track(frame.seq, frame.timestamp, features, mapping_busy);
  result.state = out.state;
  result.world_from_camera = out.world_from_camera;
  result.num_inliers = out.num_inliers;
  result.keyframe_created = out.keyframe.has_value();
  Record record{frame.seq,
                frame.timestamp,
                out.state,
                out.world_from_camera,
                out.reference_keyframe,
                out.reference_from_camera,
                result.keyframe_created,
                frame.ground_truth_world_from_camera};
  AppendRecord(record);
  {
    std::lock_guard<std::mutex> s(stats_mutex_);
    if (out.state == TrackingState::kLost) {
      ++stats_.frames_lost;
    } else {
      ++stats_.frames_tracked;
    }
    if (out.state == TrackingState::kRelocalized) ++stats_.relocalisations;
  }
  if (out.keyframe) {
    if (options_.deterministic) {
      mapper_.Process(*out.keyframe);
    } else {
      keyframes_.Push(std::move(*out.keyframe));
    }
  }
  // A map this young that loses track was initialised badly: start over.
  lost_streak_ = out.state == TrackingState::kLost ? lost_streak_ + 1 : 0;
  if (lost_streak_ >= kLostFramesBeforeReinit && !localization_only_) {
    const size_t keyframes = map_.Read([](const MapData& m) { return m.keyframes().size(); });
    if (keyframes <= static_cast<size_t>(kSmallMapKeyframes)) {
      M2S_LOG(kWarning) << "lost right after initialisation; initialising again";
      StopMapping(/*discard_queued=*/true);
      map_.Clear();
      tracker_.Reset();
      initializer_.Reset();
      StartMapping();
      lost_streak_ = 0;
    }
  }
  result.tracking_ms = MsSince(t0);
  return result;
}

TrackResult SlamSystem::Initialise(const Frame& frame, const SortedFeatures& features,
                                   TrackResult result) {
  auto initial = initializer_.Process(frame.seq, frame.timestamp, features);
  Record record{
      frame.seq, frame.timestamp, TrackingState::kNotInitialized,      Pose3(), std::nullopt,
      Pose3(),   false,           frame.ground_truth_world_from_camera};
  if (!initial) {
    result.state = TrackingState::kNotInitialized;
    AppendRecord(record);
    return result;
  }
  const KeyframeId first = map_.NextKeyframeId();
  const KeyframeId second = map_.NextKeyframeId();
  mapper_.InsertInitialMap(*initial, first, second);
  tracker_.Start(second, initial->second.world_from_camera,
                 static_cast<int>(initial->points.size()), frame.timestamp,
                 MedianDepth(initial->second.world_from_camera.Inverse(), initial->points));
  {
    std::lock_guard<std::mutex> lock(trajectory_mutex_);
    for (Record& r : trajectory_) {
      if (r.seq == initial->first.seq) {
        r.state = TrackingState::kOk;
        r.reference = first;
        r.reference_from_camera = Pose3::Identity();
        r.is_keyframe = true;
      }
    }
  }
  record.state = TrackingState::kOk;
  record.world_from_camera = initial->second.world_from_camera;
  record.reference = second;
  record.is_keyframe = true;
  AppendRecord(record);
  {
    std::lock_guard<std::mutex> s(stats_mutex_);
    stats_.frames_tracked += 2;
  }
  result.state = TrackingState::kOk;
  result.world_from_camera = initial->second.world_from_camera;
  result.num_inliers = static_cast<int>(initial->points.size());
  result.keyframe_created = true;
  return result;
}

MapDelta SlamSystem::TakeMapDelta() { return map_.TakeDelta(); }

MapDelta SlamSystem::FullMap() const { return map_.FullDelta(); }

std::vector<TrajectoryEntry> SlamSystem::Trajectory() const {
  std::lock_guard<std::mutex> lock(trajectory_mutex_);
  std::vector<TrajectoryEntry> out;
  out.reserve(trajectory_.size());
  map_.Read([&](const MapData& m) {
    for (const Record& r : trajectory_) {
      TrajectoryEntry e;
      e.seq = r.seq;
      e.timestamp = r.timestamp;
      e.state = r.state;
      e.world_from_camera = r.world_from_camera;
      if (r.reference) {
        if (auto ref = m.ResolveKeyframePose(*r.reference))
          e.world_from_camera = *ref * r.reference_from_camera;
      }
      e.is_keyframe = r.is_keyframe;
      e.ground_truth_world_from_camera = r.ground_truth;
      out.push_back(e);
    }
  });
  return out;
}

SystemStats SlamSystem::Stats() const {
  SystemStats s;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    s = stats_;
  }
  s.frames_dropped_queue = input_.dropped();
  s.loop_corrections = mapper_.stats().loop_corrections;
  map_.Read([&](const MapData& m) {
    s.keyframes = static_cast<int>(m.keyframes().size());
    s.map_points = static_cast<int>(m.points().size());
  });
  s.map_revision = map_.revision();
  return s;
}

void SlamSystem::ResetLocked(bool keep_localization_only) {
  StopMapping(/*discard_queued=*/true);
  map_.Clear();
  tracker_.Reset();
  initializer_.Reset();
  validator_.Reset();
  lost_streak_ = 0;
  if (!keep_localization_only) localization_only_ = options_.localization_only;
  tracker_.SetLocalizationOnly(localization_only_);
  {
    std::lock_guard<std::mutex> lock(trajectory_mutex_);
    trajectory_.clear();
  }
  if (!shut_down_) StartMapping();
}

void SlamSystem::Reset() {
  std::lock_guard<std::mutex> lock(track_mutex_);
  input_.Clear();
  ResetLocked(/*keep_localization_only=*/false);
}

Status SlamSystem::SaveMap(const std::string& path) const {
  return map_.Save(path, options_.camera);
}

Status SlamSystem::LoadMap(const std::string& path) {
  std::lock_guard<std::mutex> lock(track_mutex_);
  StopMapping(/*discard_queued=*/true);
  Status status = map_.Load(path, options_.camera);
  if (!status.ok()) {
    if (!shut_down_) StartMapping();
    return status;
  }
  tracker_.Reset();
  initializer_.Reset();
  validator_.Reset();
  lost_streak_ = 0;
  localization_only_ = true;
  tracker_.SetLocalizationOnly(true);
  tracker_.StartLost();
  {
    std::lock_guard<std::mutex> t(trajectory_mutex_);
    trajectory_.clear();
  }
  return Status::Ok();
}

void SlamSystem::Shutdown() {
  if (shut_down_.exchange(true)) return;
  input_.Clear();
  input_.Stop();
  std::thread tracking;
  {
    std::lock_guard<std::mutex> lock(threads_mutex_);
    tracking = std::move(tracking_thread_);
  }
  if (tracking.joinable()) tracking.join();
  results_.Stop();
  StopMapping(/*discard_queued=*/true);
}

}  // namespace m2s::slam
