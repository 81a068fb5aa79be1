// GroupAgent: one agent's System in a map group (system/map_group.h).
#include <algorithm>

#include "m2s/common/logging.h"
#include "system/map_group.h"

namespace m2s::slam {

GroupAgent::GroupAgent(std::shared_ptr<MapGroupImpl> group, int index)
    : group_(std::move(group)),
      index_(index),
      options_(group_->options()),
      validator_(options_.camera, options_.max_features_per_frame, options_.image_margin_px),
      budget_grid_(FeatureGrid::ForImage(options_.camera.width, options_.camera.height)),
      initializer_(options_.measurement(), options_.initializer, options_.mapper.num_ba_threads),
      own_mapper_(options_.measurement(), options_.mapper, options_.drift, &own_map_),
      group_tracker_(options_.measurement(), options_.tracker, options_.drift, &group_->map()),
      own_tracker_(options_.measurement(), options_.tracker, options_.drift, &own_map_),
      runner_(static_cast<size_t>(options_.input_queue_capacity),
              [this](const Frame& frame) { return TrackLocked(frame); }) {
  group_tracker_.SetLocalizationOnly(group_->localization_only());
  stats_.maps_created = 1;
}

GroupAgent::~GroupAgent() { Shutdown(); }

std::optional<int> GroupAgent::own_map_id() const {
  const int id = own_map_id_;
  return id < 0 ? std::nullopt : std::optional<int>(id);
}

void GroupAgent::UseOwnMapLocked(int map_id) {
  if (own_map_id_ == map_id) return;
  own_map_.Clear();
  own_tracker_.Reset();
  own_map_id_ = map_id;
}

void GroupAgent::NotifyMerged(int map_id, const Sim3& group_from_own,
                              std::unordered_map<KeyframeId, KeyframeId> ids) {
  MergeNotice notice{map_id, group_from_own, std::move(ids)};
  {
    std::lock_guard<std::mutex> lock(records_mutex_);
    for (TrajectoryRecord& r : records_) {
      if (r.map_id == map_id) MoveMergedRecord(notice, &r);
    }
    ++stats_.map_merges;
    last_merge_ = notice;
  }
  own_map_id_ = -1;
  std::lock_guard<std::mutex> lock(notice_mutex_);
  switch_pending_ = true;
}

void GroupAgent::MoveMergedRecord(const MergeNotice& notice, TrajectoryRecord* record) {
  MoveRecord(notice.group_from_own, MapGroupImpl::kGroupMapId, record);
  if (record->reference) {
    const auto it = notice.ids.find(*record->reference);
    if (it != notice.ids.end()) {
      record->reference = it->second;
    } else {
      record->reference.reset();
    }
  }
}

void GroupAgent::AppendRecord(TrajectoryRecord record) {
  std::lock_guard<std::mutex> lock(records_mutex_);
  // Tracked in an own map that merged while the frame was being tracked.
  if (last_merge_ && record.map_id == last_merge_->map_id) MoveMergedRecord(*last_merge_, &record);
  records_.push_back(std::move(record));
}

void GroupAgent::SwitchToGroupMapIfMerged() {
  {
    std::lock_guard<std::mutex> lock(notice_mutex_);
    if (!switch_pending_) return;
    switch_pending_ = false;
  }
  // The merged own map stays as it is (the mapping thread no longer touches it; the next own
  // map clears it): waiting here for the mapping mutex would stall tracking for the global BA
  // that follows the merge.
  own_tracker_.Reset();
  initializer_.Reset();
  // The merged map holds this agent's own keyframes and points: relocalisation by id succeeds
  // on the next frame that sees them.
  group_tracker_.StartLost();
  lost_since_.reset();
  lost_streak_ = 0;
  tracked_in_map_ = 0;
  group_->ResetDeltaFor(index_);
}

TrackResult GroupAgent::Track(const Frame& frame) { return runner_.Track(frame); }

void GroupAgent::Submit(Frame frame) {
  if (!shut_down_) runner_.Submit(std::move(frame));
}

bool GroupAgent::WaitForResult(TrackResult* result, double timeout_s) {
  return !shut_down_ && runner_.WaitForResult(result, timeout_s);
}

TrackResult GroupAgent::TrackLocked(const Frame& frame) {
  const auto t0 = std::chrono::steady_clock::now();
  TrackResult result;
  SortedFeatures features;
  {
    std::lock_guard<std::mutex> s(records_mutex_);
    if (!TakeFrame(frame, shut_down_, options_.feature_budget, budget_grid_, &validator_, &features,
                   &result, &stats_)) {
      return result;
    }
  }
  SwitchToGroupMapIfMerged();
  std::optional<int> own = own_map_id();
  std::optional<TrackerOutput> joined;
  if (own && !own_tracker_.started()) {
    // While its own map is not initialised yet, the agent keeps trying the group's map (which
    // other agents extend meanwhile); the first success ends the own map before it began.
    joined = TryGroupMap(frame, features);
    if (joined) own.reset();
  }
  Tracker& tracker = own ? own_tracker_ : group_tracker_;
  if (!joined && !tracker.started()) {
    const bool group_has_map =
        group_->map().Read([](const MapData& m) { return !m.keyframes().empty(); });
    if (own || (!group_has_map && !group_->localization_only())) {
      result = Initialise(frame, features, result);
      result.tracking_ms = MsSince(t0);
      return result;
    }
    // Localise in the group's map by vertex id, without initialising.
    tracker.StartLost();
  }
  TrackerOutput out =
      joined ? std::move(*joined)
             : tracker.Track(frame.seq, frame.timestamp, features, group_->mapping_busy());
  bool never_posed = false;
  {
    std::lock_guard<std::mutex> s(records_mutex_);
    never_posed = stats_.frames_tracked == 0;
  }
  if (never_posed && out.state == TrackingState::kLost) {
    // A joining agent whose view the group's map does not cover is not lost: it has not
    // started. It builds a map of its own from the next frames (HandleLost).
    out.state = TrackingState::kNotInitialized;
  }
  const int map_id = own.value_or(MapGroupImpl::kGroupMapId);
  result.state = out.state;
  result.world_from_camera = out.world_from_camera;
  result.num_inliers = out.num_inliers;
  result.keyframe_created = out.keyframe.has_value();
  result.map_id = map_id;
  TrajectoryRecord record{frame.seq,
                          frame.timestamp,
                          out.state,
                          out.world_from_camera,
                          out.reference_keyframe,
                          out.reference_from_camera,
                          result.keyframe_created,
                          frame.ground_truth_world_from_camera,
                          map_id,
                          tracker.correction_epoch()};
  AppendRecord(record);
  {
    std::lock_guard<std::mutex> s(records_mutex_);
    if (out.state == TrackingState::kLost) {
      ++stats_.frames_lost;
    } else if (HasPose(out.state)) {
      ++stats_.frames_tracked;
    }
    if (out.state == TrackingState::kRelocalized) ++stats_.relocalisations;
  }
  if (out.keyframe) group_->MapKeyframe(this, map_id, std::move(*out.keyframe));
  HandleLost(out.state, frame.timestamp, features.size());
  result.tracking_ms = MsSince(t0);
  return result;
}

TrackResult GroupAgent::Initialise(const Frame& frame, const SortedFeatures& features,
                                   TrackResult result) {
  auto initial = initializer_.Process(frame.seq, frame.timestamp, features);
  // Frames without a pose in any map after this agent had one are lost.
  bool had_pose = false;
  {
    std::lock_guard<std::mutex> lock(records_mutex_);
    had_pose = stats_.frames_tracked > 0;
  }
  const TrackingState waiting = had_pose ? TrackingState::kLost : TrackingState::kNotInitialized;
  const int waiting_map = own_map_id().value_or(MapGroupImpl::kGroupMapId);
  TrajectoryRecord record{frame.seq,    frame.timestamp,
                          waiting,      Pose3(),
                          std::nullopt, Pose3(),
                          false,        frame.ground_truth_world_from_camera,
                          waiting_map,  0};
  result.map_id = waiting_map;
  if (!initial) {
    result.state = waiting;
    AppendRecord(record);
    if (had_pose) {
      std::lock_guard<std::mutex> s(records_mutex_);
      ++stats_.frames_lost;
    }
    return result;
  }
  KeyframeId first = 0, second = 0;
  const int map_id =
      group_->InsertInitialMap(this, *initial, /*prefer_group=*/!own_map_id(), &first, &second);
  Tracker& tracker = map_id == MapGroupImpl::kGroupMapId ? group_tracker_ : own_tracker_;
  StartTracking(*initial, second, frame.timestamp, &tracker);
  {
    std::lock_guard<std::mutex> lock(records_mutex_);
    const InitialFramesMarked marked =
        MarkInitialFrames(*initial, first, second, map_id, /*kept=*/0, &records_);
    stats_.frames_tracked += 1 + marked.marked;
    stats_.frames_lost -= marked.was_lost;
    if (map_id != MapGroupImpl::kGroupMapId) ++stats_.maps_created;
  }
  record.state = TrackingState::kOk;
  record.world_from_camera = initial->second.world_from_camera;
  record.reference = second;
  record.is_keyframe = true;
  record.map_id = map_id;
  AppendRecord(record);
  lost_since_.reset();
  lost_streak_ = 0;
  tracked_in_map_ = 0;
  result.state = TrackingState::kOk;
  result.world_from_camera = initial->second.world_from_camera;
  result.num_inliers = static_cast<int>(initial->points.size());
  result.keyframe_created = true;
  result.map_id = map_id;
  return result;
}

void GroupAgent::HandleLost(TrackingState state, double timestamp, size_t num_features) {
  if (state == TrackingState::kNotInitialized) {
    if (!group_->localization_only() && options_.multi_map.enabled) StartOwnMap();
    return;
  }
  if (state != TrackingState::kLost) {
    lost_streak_ = 0;
    lost_since_.reset();
    ++tracked_in_map_;
    return;
  }
  ++lost_streak_;
  if (group_->localization_only()) return;
  if (own_map_id()) {
    const size_t keyframes = own_map_.Read([](const MapData& m) { return m.keyframes().size(); });
    if (IsYoungMap(keyframes, tracked_in_map_)) {
      if (lost_streak_ >= kLostFramesBeforeReinit) {
        M2S_LOG(kWarning) << "map group agent " << index_
                          << ": lost right after initialising its own map; initialising again";
        StartOwnMap();
      }
      return;
    }
  }
  const MultiMapOptions& multi = options_.multi_map;
  if (!multi.enabled || num_features < static_cast<size_t>(multi.min_features)) return;
  if (!lost_since_) lost_since_ = timestamp;
  if (timestamp - *lost_since_ >= multi.new_map_after_lost_s) {
    M2S_LOG(kInfo) << "map group agent " << index_ << ": lost for " << timestamp - *lost_since_
                   << " s; starting a map of its own";
    StartOwnMap();
  }
}

std::optional<TrackerOutput> GroupAgent::TryGroupMap(const Frame& frame,
                                                     const SortedFeatures& features) {
  if (group_->map().Read([](const MapData& m) { return m.keyframes().size() < 2; }))
    return std::nullopt;
  if (!group_tracker_.started()) group_tracker_.StartLost();
  TrackerOutput out =
      group_tracker_.Track(frame.seq, frame.timestamp, features, group_->mapping_busy());
  if (!HasPose(out.state)) return std::nullopt;
  {
    std::lock_guard<std::mutex> mapping(group_->mapping_mutex());
    own_map_.Clear();
    own_map_id_ = -1;
  }
  initializer_.Reset();
  return out;
}

void GroupAgent::StartOwnMap() {
  bool had_pose = false;
  {
    std::lock_guard<std::mutex> lock(records_mutex_);
    had_pose = stats_.frames_tracked > 0;
  }
  {
    std::lock_guard<std::mutex> mapping(group_->mapping_mutex());
    // A fresh id: the keyframes still queued for the previous own map are dropped.
    own_map_id_ = -1;
    UseOwnMapLocked(group_->NewMapId());
  }
  group_tracker_.Reset();
  // An agent that never had a pose keeps its initialiser's reference frame: it has been
  // collecting parallax since it joined.
  if (had_pose) initializer_.Reset();
  lost_since_.reset();
  lost_streak_ = 0;
  tracked_in_map_ = 0;
}

MapDelta GroupAgent::TakeMapDelta() {
  if (own_map_id()) return own_map_.TakeDelta();
  return group_->TakeDeltaFor(index_);
}

MapDelta GroupAgent::FullMap() const {
  if (own_map_id()) return own_map_.FullDelta();
  return group_->FullDeltaFor(index_);
}

std::vector<TrajectoryEntry> GroupAgent::Trajectory() const {
  std::lock_guard<std::mutex> lock(records_mutex_);
  std::vector<TrajectoryEntry> out;
  out.reserve(records_.size());
  const std::optional<int> own = own_map_id();
  group_->map().Read([&](const MapData& group) {
    own_map_.Read([&](const MapData& own_data) {
      for (const TrajectoryRecord& r : records_) {
        const MapData* map = r.map_id == MapGroupImpl::kGroupMapId ? &group
                             : own && r.map_id == *own             ? &own_data
                                                                   : nullptr;
        out.push_back(ToEntry(r, map));
      }
    });
  });
  return out;
}

SystemStats GroupAgent::Stats() const {
  SystemStats s;
  {
    std::lock_guard<std::mutex> lock(records_mutex_);
    s = stats_;
    for (const TrajectoryRecord& r : records_) {
      if (HasPose(r.state) && r.map_id != MapGroupImpl::kGroupMapId) ++s.frames_in_unmerged_maps;
    }
  }
  s.frames_submitted = runner_.submitted();
  s.frames_dropped_queue = runner_.dropped();
  s.mapping_queue = group_->mapping_queue();
  const std::optional<int> own = own_map_id();
  s.current_map = own.value_or(MapGroupImpl::kGroupMapId);
  const Map& map = own ? own_map_ : group_->map();
  map.Read([&](const MapData& m) {
    s.keyframes = static_cast<int>(m.keyframes().size());
    s.map_points = static_cast<int>(m.points().size());
  });
  s.map_revision = map.revision();
  return s;
}

void GroupAgent::Reset() {
  runner_.Exclusive([this] { ResetLocked(); });
}

void GroupAgent::ResetLocked() {
  {
    std::lock_guard<std::mutex> mapping(group_->mapping_mutex());
    own_map_.Clear();
    own_map_id_ = -1;
  }
  {
    std::lock_guard<std::mutex> n(notice_mutex_);
    switch_pending_ = false;
  }
  group_tracker_.Reset();
  own_tracker_.Reset();
  initializer_.Reset();
  validator_.Reset();
  lost_since_.reset();
  lost_streak_ = 0;
  tracked_in_map_ = 0;
  {
    std::lock_guard<std::mutex> r(records_mutex_);
    records_.clear();
    last_merge_.reset();
    stats_ = SystemStats();
    stats_.maps_created = 1;
  }
  group_->ResetDeltaFor(index_);
}

Status GroupAgent::SaveMap(const std::string& path) const { return group_->SaveMap(path); }

Status GroupAgent::LoadMap(const std::string& /*path*/) {
  return Status::Error("an agent of a map group does not load maps: load the group's map");
}

void GroupAgent::Shutdown() {
  if (shut_down_.exchange(true)) return;
  runner_.Stop();
  group_->Leave(this);
}

}  // namespace m2s::slam
