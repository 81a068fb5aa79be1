#include "system/slam_system.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "system/refinement_internal.h"
#include "system/trajectory_refinement.h"
#include "tracking/feature_budget.h"

namespace m2s::slam {
namespace {

// Real time: after each tracked frame, frames between the map's two views are solved for about
// this long (0.2-0.5 ms each on 2 cores: the 53 of the demo's start over about 9 frames at
// 120 fps, against an 8.3 ms period).
constexpr double kInbetweenBudgetMs = 2.0;

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
      seeded_initializer_(options.measurement(), options.initializer,
                          options.mapper.num_ba_threads),
      tracker_(options.measurement(), options.tracker, options.drift, &map_),
      mapper_(options.measurement(), options.mapper, options.drift, &map_),
      localization_only_(options.localization_only),
      keyframes_(static_cast<size_t>(options.mapping_queue_capacity),
                 BoundedQueue<KeyframeCandidate>::Policy::kBlock),
      runner_(static_cast<size_t>(options.input_queue_capacity),
              [this](const Frame& frame) { return TrackLocked(frame); }) {
  tracker_.SetLocalizationOnly(localization_only_);
  tracker_.SetReportObservations(options_.frame_observations_kept > 0);
  initializer_.DeferInbetween(!options_.deterministic);
  seeded_initializer_.DeferInbetween(!options_.deterministic);
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
  while (auto kf = keyframes_.Pop()) {
    mapper_.Process(*kf, /*backlog=*/keyframes_.size() > 0);
    TryMergeSetAsideMaps();
  }
}

TrackResult SlamSystem::Track(const Frame& frame) { return runner_.Track(frame); }

void SlamSystem::Submit(Frame frame) {
  if (!shut_down_) runner_.Submit(std::move(frame));
}

bool SlamSystem::WaitForResult(TrackResult* result, double timeout_s) {
  return !shut_down_ && runner_.WaitForResult(result, timeout_s);
}

void SlamSystem::AppendRecord(Record* record) {
  std::lock_guard<std::mutex> lock(trajectory_mutex_);
  record->map_id = current_map_;
  // Tracked in the merged map's world, just before the merge.
  if (last_merge_ && record->correction_epoch < last_merge_->epoch) {
    MoveRecordInto(*last_merge_, record);
  }
  trajectory_.push_back(*record);
}

void SlamSystem::MoveRecordInto(const MergeNotice& notice, Record* record) {
  MoveRecord(notice.into_from_from, notice.into_map, record);
  record->correction_epoch = notice.epoch;
}

TrackResult SlamSystem::TrackLocked(const Frame& frame) {
  const auto t0 = std::chrono::steady_clock::now();
  TrackResult result;
  SortedFeatures features;
  {
    std::lock_guard<std::mutex> s(stats_mutex_);
    if (!TakeFrame(frame, shut_down_, options_.feature_budget, budget_grid_, &validator_, &features,
                   &result, &stats_)) {
      return result;
    }
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
  // A frame without a pose keeps its features: RefineMap may solve it on the final map.
  if (HasPose(out.state)) {
    KeepObservations(out.observed_ids, out.observed_uvs, options_.frame_observations_kept, &record);
  } else {
    KeepObservations(features.ids, features.uvs, options_.frame_observations_kept, &record);
  }
  record.correction_epoch = tracker_.correction_epoch();
  AppendRecord(&record);
  result.map_id = record.map_id;
  if (HasPose(out.state)) result.world_from_camera = record.world_from_camera;
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
      TryMergeSetAsideMaps();
    } else {
      keyframes_.Push(std::move(*out.keyframe));
    }
  }
  HandleLost(out, frame, features);
  SolvePendingInbetween(kInbetweenBudgetMs);
  result.tracking_ms = MsSince(t0);
  return result;
}

MapDelta SlamSystem::TakeMapDelta() { return map_.TakeDelta(); }

MapDelta SlamSystem::FullMap() const { return map_.FullDelta(); }

std::vector<TrajectoryEntry> SlamSystem::Trajectory() const {
  std::lock_guard<std::mutex> lock(trajectory_mutex_);
  std::vector<TrajectoryEntry> out;
  out.reserve(trajectory_.size());
  std::lock_guard<std::mutex> maps(maps_mutex_);
  map_.Read([&](const MapData& current) {
    auto map_of = [&](int id) -> const MapData* {
      if (id == current_map_) return &current;
      for (const SetAsideMap& m : set_aside_) {
        if (m.id == id) return &m.data;
      }
      return nullptr;  // dropped: the pose at tracking time
    };
    for (const Record& r : trajectory_) out.push_back(ToEntry(r, map_of(r.map_id)));
  });
  return out;
}

SystemStats SlamSystem::Stats() const {
  SystemStats s;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    s = stats_;
  }
  s.frames_submitted = runner_.submitted();
  s.frames_dropped_queue = runner_.dropped();
  s.mapping_queue = static_cast<int>(keyframes_.size());
  {
    std::lock_guard<std::mutex> t(trajectory_mutex_);
    std::lock_guard<std::mutex> m(maps_mutex_);
    s.maps_created = maps_created_;
    s.map_merges = map_merges_;
    s.current_map = current_map_;
    for (const Record& r : trajectory_) {
      if (HasPose(r.state) && r.map_id != current_map_) ++s.frames_in_unmerged_maps;
    }
  }
  s.loop_corrections = mapper_.stats().loop_corrections;
  map_.Read([&](const MapData& m) {
    s.keyframes = static_cast<int>(m.keyframes().size());
    s.map_points = static_cast<int>(m.points().size());
  });
  s.map_revision = map_.revision();
  return s;
}

void SlamSystem::ForgetMapsLocked() {
  {
    std::lock_guard<std::mutex> lock(inbetween_mutex_);
    inbetween_.reset();
  }
  lost_since_.reset();
  lost_frames_.clear();
  tracked_in_map_ = 0;
  std::lock_guard<std::mutex> t(trajectory_mutex_);
  std::lock_guard<std::mutex> m(maps_mutex_);
  set_aside_.clear();
  current_map_ = 0;
  maps_created_ = 1;
  map_merges_ = 0;
  last_merge_.reset();
}

void SlamSystem::ResetLocked(bool keep_localization_only) {
  StopMapping(/*discard_queued=*/true);
  map_.Clear();
  tracker_.Reset();
  ResetInitializers();
  validator_.Reset();
  lost_streak_ = 0;
  ForgetMapsLocked();
  if (!keep_localization_only) localization_only_ = options_.localization_only;
  tracker_.SetLocalizationOnly(localization_only_);
  {
    std::lock_guard<std::mutex> lock(trajectory_mutex_);
    trajectory_.clear();
  }
  if (!shut_down_) StartMapping();
}

void SlamSystem::Reset() {
  runner_.Exclusive([this] { ResetLocked(/*keep_localization_only=*/false); });
}

void SlamSystem::RefineMap() {
  runner_.Exclusive([this] {
    if (localization_only_) return;
    SolvePendingInbetween(-1.0);
    mapper_.GlobalBundleAdjust(kFinalBaIterations, /*max_points=*/0);
    std::lock_guard<std::mutex> t(trajectory_mutex_);
    map_.Read([&](const MapData& current) {
      std::optional<Pose3> previous;  // camera_from_world of the last frame with a pose
      for (Record& r : trajectory_) {
        if (r.map_id != current_map_) continue;
        RefineFramePose(options_.measurement(), current, &r, previous ? &*previous : nullptr);
        if (const std::optional<Pose3> pose =
                refinement_internal::RecordPose(current, current_map_, r)) {
          previous = pose->Inverse();
        }
      }
      const int solved = SolveUnposedFrames(options_.measurement(), current, current_map_,
                                            kUnposedMinPoints, &trajectory_);
      if (solved > 0) M2S_LOG(kInfo) << solved << " frames without a pose solved on the map";
      const SmoothedFrames smoothed = SmoothLooseFrames(
          options_.measurement(), current, current_map_, options_.tracker.max_points, &trajectory_);
      if (smoothed.smoothed > 0)
        M2S_LOG(kInfo) << smoothed.smoothed << " loosely determined frames smoothed";
      if (smoothed.posed > 0) {
        M2S_LOG(kInfo) << smoothed.posed
                       << " frames without a pose given the centre interpolated between their "
                          "neighbours and the rotation their points fit there";
      }
      const MotionPriorResult prior = ApplyMotionPrior(
          options_.measurement(), current, current_map_, options_.tracker.max_points,
          options_.refine_acceleration_sigma, &trajectory_);
      if (prior.smoothed > 0) {
        M2S_LOG(kInfo) << prior.smoothed << " frames smoothed under the motion prior (pixel noise "
                       << prior.pixel_sigma << " px; " << prior.kept << " kept their pose)";
      }
    });
  });
}

Status SlamSystem::SaveMap(const std::string& path) const {
  return map_.Save(path, options_.camera);
}

Status SlamSystem::LoadMap(const std::string& path) {
  return runner_.Exclusive([&] { return LoadMapLocked(path); });
}

Status SlamSystem::LoadMapLocked(const std::string& path) {
  StopMapping(/*discard_queued=*/true);
  Status status = map_.Load(path, options_.camera);
  if (!status.ok()) {
    if (!shut_down_) StartMapping();
    return status;
  }
  tracker_.Reset();
  ResetInitializers();
  validator_.Reset();
  lost_streak_ = 0;
  ForgetMapsLocked();
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
  runner_.Stop();
  StopMapping(/*discard_queued=*/true);
}

}  // namespace m2s::slam
