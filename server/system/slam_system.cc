#include "system/slam_system.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "map/map_merge.h"
#include "system/trajectory_refinement.h"
#include "tracking/feature_budget.h"

namespace m2s::slam {
namespace {

// Set-aside maps kept for merging; beyond this the one with the fewest keyframes is dropped.
constexpr size_t kMaxSetAsideMaps = 8;
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

void SlamSystem::HandleLost(const TrackerOutput& out, const Frame& frame,
                            const SortedFeatures& features) {
  if (out.state != TrackingState::kLost) {
    lost_streak_ = 0;
    lost_since_.reset();
    lost_frames_.clear();
    ++tracked_in_map_;
    return;
  }
  ++lost_streak_;
  if (localization_only_) return;
  const size_t keyframes = map_.Read([](const MapData& m) { return m.keyframes().size(); });
  if (IsYoungMap(keyframes, tracked_in_map_)) {
    // A map this young that loses track was initialised badly: start over without it.
    if (lost_streak_ >= kLostFramesBeforeReinit) {
      M2S_LOG(kWarning) << "lost right after initialisation; initialising again";
      StartNewMap(/*keep=*/false);
    }
    return;
  }
  const MultiMapOptions& multi = options_.multi_map;
  if (!multi.enabled || features.size() < static_cast<size_t>(multi.min_features)) return;
  if (!lost_since_) lost_since_ = frame.timestamp;
  if (lost_frames_.size() <= static_cast<size_t>(options_.initializer.max_reference_age)) {
    lost_frames_.push_back(InitialFrame{frame.seq, frame.timestamp, features, Pose3::Identity()});
  }
  if (frame.timestamp - *lost_since_ >= multi.new_map_after_lost_s) {
    M2S_LOG(kInfo) << "lost for " << frame.timestamp - *lost_since_ << " s; map " << current_map_
                   << " set aside, a new map starts";
    std::vector<InitialFrame> lost = std::move(lost_frames_);
    StartNewMap(/*keep=*/true);
    // The new map starts from the lost frames, which get poses once it initialises. Two
    // initialisers try, the first to initialise makes the map: one from the earliest full view
    // (the most parallax when the camera moves on), one from the latest (when the camera only
    // hovers and turns, the earlier views stay ambiguous until they leave the view).
    initializer_.Seed(lost, Initializer::SeedReference::kLatest);
    seeded_initializer_.Seed(lost, Initializer::SeedReference::kEarliestFull);
    seeded_reference_ = seeded_initializer_.reference_seq();
    if (seeded_reference_ == initializer_.reference_seq()) seeded_reference_.reset();
  }
}

void SlamSystem::StartNewMap(bool keep) {
  if (keep) {
    SolvePendingInbetween(-1.0);
  } else {
    std::lock_guard<std::mutex> lock(inbetween_mutex_);
    inbetween_.reset();
  }
  // A kept map's queued keyframes are mapped into it first.
  StopMapping(/*discard_queued=*/!keep);
  {
    std::lock_guard<std::mutex> t(trajectory_mutex_);
    std::lock_guard<std::mutex> m(maps_mutex_);
    MapData data = map_.TakeData();
    if (keep && !data.empty()) {
      if (set_aside_.size() >= kMaxSetAsideMaps) {
        const auto smallest = std::min_element(
            set_aside_.begin(), set_aside_.end(), [](const SetAsideMap& a, const SetAsideMap& b) {
              return a.data.keyframes().size() < b.data.keyframes().size();
            });
        M2S_LOG(kWarning) << "too many set-aside maps: map " << smallest->id << " dropped";
        set_aside_.erase(smallest);
      }
      set_aside_.push_back({current_map_, std::move(data)});
    }
    current_map_ = maps_created_++;
  }
  tracker_.Reset();
  ResetInitializers();
  lost_streak_ = 0;
  lost_since_.reset();
  lost_frames_.clear();
  tracked_in_map_ = 0;
  StartMapping();
}

void SlamSystem::TryMergeSetAsideMaps() {
  if (!options_.multi_map.enabled) return;
  const MapAlignmentOptions align = MergeAlignmentOptions(options_);
  std::optional<size_t> base;
  MapAlignment alignment;
  {
    std::lock_guard<std::mutex> m(maps_mutex_);
    if (set_aside_.empty()) return;
    map_.Read([&](const MapData& current) {
      if (current.keyframes().size() < 2) return;
      for (size_t i = set_aside_.size(); i-- > 0;) {  // the newest first
        Expected<MapAlignment> a = AlignMaps(set_aside_[i].data, current, align);
        if (a) {
          base = i;
          alignment = *a;
          return;
        }
        M2S_LOG(kDebug) << "map " << current_map_ << " not merged into map " << set_aside_[i].id
                        << ": " << a.error();
      }
    });
  }
  if (!base) return;
  // The merge moves the current map's records: every one of them must have its pose first.
  SolvePendingInbetween(-1.0);
  int from = 0, into = 0;
  {
    std::lock_guard<std::mutex> t(trajectory_mutex_);
    std::lock_guard<std::mutex> m(maps_mutex_);
    SetAsideMap target = std::move(set_aside_[*base]);
    set_aside_.erase(set_aside_.begin() + static_cast<std::ptrdiff_t>(*base));
    const uint64_t epoch = map_.MergeInto(std::move(target.data), alignment.into_from_from);
    const MergeNotice notice{epoch, current_map_, target.id, alignment.into_from_from};
    for (Record& r : trajectory_) {
      if (r.map_id == current_map_) MoveRecordInto(notice, &r);
    }
    from = current_map_;
    into = target.id;
    current_map_ = target.id;
    last_merge_ = notice;
    ++map_merges_;
  }
  M2S_LOG(kInfo) << "map " << from << " merged into map " << into << ": " << alignment.inliers
                 << " of " << alignment.shared_points << " shared points fit, rms "
                 << alignment.rms_residual << " (" << alignment.rms_residual / alignment.spread
                 << " of their spread), " << alignment.image_agreement * 100.0
                 << " % of their observations in the keyframes agree, scale "
                 << alignment.into_from_from.scale();
  mapper_.GlobalBundleAdjust(kMergeBaIterations, options_.mapper.local_ba_max_points);
}

TrackResult SlamSystem::Initialise(const Frame& frame, const SortedFeatures& features,
                                   TrackResult result) {
  std::optional<InitialMap> initial;
  if (seeded_reference_) {
    initial = seeded_initializer_.Process(frame.seq, frame.timestamp, features);
    // Once its reference gives way, it would only repeat initializer_.
    if (!initial && seeded_initializer_.reference_seq() != seeded_reference_) {
      seeded_initializer_.Reset();
      seeded_reference_.reset();
    }
  }
  if (!initial) initial = initializer_.Process(frame.seq, frame.timestamp, features);
  if (initial) ResetInitializers();
  // While a later map initialises, the frames have no pose in any map: they are lost.
  bool later_map = false;
  {
    std::lock_guard<std::mutex> lock(maps_mutex_);
    later_map = maps_created_ > 1;
  }
  const TrackingState waiting = later_map ? TrackingState::kLost : TrackingState::kNotInitialized;
  Record record{frame.seq,    frame.timestamp, waiting, Pose3(),
                std::nullopt, Pose3(),         false,   frame.ground_truth_world_from_camera};
  record.correction_epoch = map_.correction().epoch;
  KeepObservations(features.ids, features.uvs, options_.frame_observations_kept, &record);
  AppendRecord(&record);
  result.state = waiting;
  result.map_id = record.map_id;
  if (later_map) {
    std::lock_guard<std::mutex> s(stats_mutex_);
    ++stats_.frames_lost;
  }
  if (!initial) return result;
  return StartFromInitialMap(std::move(*initial), result);
}

void SlamSystem::SolvePendingInbetween(double budget_ms) {
  std::lock_guard<std::mutex> lock(inbetween_mutex_);
  if (!inbetween_) return;
  const auto t0 = std::chrono::steady_clock::now();
  InitialFramesMarked marked;
  do {
    const std::optional<InitialInbetween> f = inbetween_->solver.SolveNext();
    if (!f) continue;
    std::lock_guard<std::mutex> t(trajectory_mutex_);
    const InitialFramesMarked one = MarkInbetweenFrame(
        *f, inbetween_->first, inbetween_->map_id, options_.frame_observations_kept, &trajectory_);
    marked.marked += one.marked;
    marked.was_lost += one.was_lost;
  } while (!inbetween_->solver.done() && (budget_ms < 0.0 || MsSince(t0) < budget_ms));
  if (inbetween_->solver.done()) inbetween_.reset();
  std::lock_guard<std::mutex> s(stats_mutex_);
  stats_.frames_tracked += marked.marked;
  stats_.frames_lost -= marked.was_lost;
}

void SlamSystem::ResetInitializers() {
  initializer_.Reset();
  seeded_initializer_.Reset();
  seeded_reference_.reset();
}

TrackResult SlamSystem::StartFromInitialMap(InitialMap initial, TrackResult result) {
  SolvePendingInbetween(-1.0);  // none: StartNewMap solved them
  const KeyframeId first = map_.NextKeyframeId();
  const KeyframeId second = map_.NextKeyframeId();
  mapper_.InsertInitialMap(initial, first, second);
  StartTracking(initial, second, initial.second.timestamp, &tracker_);
  InitialFramesMarked marked;
  {
    std::lock_guard<std::mutex> lock(trajectory_mutex_);
    marked = MarkInitialFrames(initial, first, second, current_map_,
                               options_.frame_observations_kept, &trajectory_);
  }
  {
    std::lock_guard<std::mutex> s(stats_mutex_);
    stats_.frames_tracked += marked.marked;
    stats_.frames_lost -= marked.was_lost;
  }
  if (!initial.unsolved.empty()) {
    std::lock_guard<std::mutex> lock(inbetween_mutex_);
    inbetween_.emplace(
        PendingInbetween{InbetweenSolver(options_.measurement(), options_.initializer.min_points,
                                         initial, std::move(initial.unsolved)),
                         first, current_map_});
  }
  result.map_id = current_map_;
  if (options_.deterministic) TryMergeSetAsideMaps();
  result.state = TrackingState::kOk;
  result.world_from_camera = initial.second.world_from_camera;
  result.num_inliers = static_cast<int>(initial.points.size());
  result.keyframe_created = true;
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
      for (Record& r : trajectory_) {
        if (r.map_id == current_map_) RefineFramePose(options_.measurement(), current, &r);
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
