// SlamSystem's initialisation and multi-map stages (slam_system.h): a new map from the
// initialiser, the frames between its two views solved after it in real time, the lost-time
// bookkeeping that sets a map aside and starts another, and merging set-aside maps.
#include "system/slam_system.h"

#include <algorithm>
#include <chrono>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "map/map_merge.h"

namespace m2s::slam {
namespace {

// Set-aside maps kept for merging; beyond this the one with the fewest keyframes is dropped.
constexpr size_t kMaxSetAsideMaps = 8;

}  // namespace

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

}  // namespace m2s::slam
