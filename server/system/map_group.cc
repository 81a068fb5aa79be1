#include "system/map_group.h"

#include <algorithm>

#include "m2s/common/logging.h"
#include "map/map_delta.h"
#include "map/map_merge.h"

namespace m2s::slam {
namespace {

// Merge latencies kept for GroupStats.
constexpr size_t kMergeTimesKept = 64;

double MsBetween(std::chrono::steady_clock::time_point t0,
                 std::chrono::steady_clock::time_point t1) {
  return std::chrono::duration<double, std::milli>(t1 - t0).count();
}

}  // namespace

Expected<std::shared_ptr<MapGroup>> MapGroup::Create(const Options& options) {
  if (Status valid = options.Check(); !valid) return valid.Prefixed("invalid SLAM options: ");
  return std::shared_ptr<MapGroup>(std::make_shared<MapGroupImpl>(options));
}

// ---------------------------------------------------------------------------------------------
// MapGroupImpl

MapGroupImpl::MapGroupImpl(const Options& options)
    : options_(options),
      mapper_(options.measurement(), options.mapper, options.drift, &map_),
      localization_only_(options.localization_only),
      jobs_(static_cast<size_t>(options.mapping_queue_capacity),
            BoundedQueue<Job>::Policy::kBlock) {
  if (!options_.deterministic) mapping_thread_ = std::thread([this] { MappingLoop(); });
}

MapGroupImpl::~MapGroupImpl() {
  jobs_.Clear();
  jobs_.Stop();
  if (mapping_thread_.joinable()) mapping_thread_.join();
}

Expected<std::unique_ptr<System>> MapGroupImpl::Join() {
  int index = 0;
  {
    std::lock_guard<std::mutex> lock(agents_mutex_);
    index = agents_joined_++;
  }
  auto agent = std::make_unique<GroupAgent>(shared_from_this(), index);
  {
    std::lock_guard<std::mutex> lock(agents_mutex_);
    agents_[index] = agent.get();
  }
  ResetDeltaFor(index);
  return std::unique_ptr<System>(std::move(agent));
}

void MapGroupImpl::Leave(GroupAgent* agent) {
  std::lock_guard<std::mutex> mapping(mapping_mutex_);  // no mapping step of it runs now
  {
    std::lock_guard<std::mutex> lock(agents_mutex_);
    agents_.erase(agent->index());
  }
  std::lock_guard<std::mutex> deltas(deltas_mutex_);
  pending_deltas_.erase(agent->index());
}

GroupAgent* MapGroupImpl::FindAgent(int index) const {
  std::lock_guard<std::mutex> lock(agents_mutex_);
  const auto it = agents_.find(index);
  return it == agents_.end() ? nullptr : it->second;
}

GroupStats MapGroupImpl::Stats() const {
  GroupStats s;
  {
    std::lock_guard<std::mutex> lock(agents_mutex_);
    s.agents_joined = agents_joined_;
    s.agents_active = static_cast<int>(agents_.size());
    s.merges = merges_;
    s.merge_ms.assign(merge_ms_.begin(), merge_ms_.end());
  }
  map_.Read([&](const MapData& m) {
    s.keyframes = static_cast<int>(m.keyframes().size());
    s.map_points = static_cast<int>(m.points().size());
  });
  s.localization_only = localization_only_;
  return s;
}

Status MapGroupImpl::SaveMap(const std::string& path) const {
  return map_.Save(path, options_.camera);
}

Status MapGroupImpl::LoadMap(const std::string& path) {
  return Load(path, /*localization_only=*/true);
}

Status MapGroupImpl::ResumeMap(const std::string& path) {
  return Load(path, /*localization_only=*/false);
}

Status MapGroupImpl::Load(const std::string& path, bool localization_only) {
  {
    std::lock_guard<std::mutex> lock(agents_mutex_);
    if (!agents_.empty())
      return Status::Error("cannot load a map into a group with active agents (" +
                           std::to_string(agents_.size()) + ")");
  }
  std::lock_guard<std::mutex> mapping(mapping_mutex_);
  if (Status status = map_.Load(path, options_.camera); !status.ok()) return status;
  localization_only_ = localization_only;
  std::lock_guard<std::mutex> lock(agents_mutex_);
  keyframe_owner_.clear();  // made by agents of an earlier server: nobody's own
  return Status::Ok();
}

void MapGroupImpl::MarkOwner(KeyframeId id, int agent) {
  std::lock_guard<std::mutex> lock(agents_mutex_);
  keyframe_owner_[id] = agent;
}

void MapGroupImpl::SetOwnFlags(int agent, MapDelta* delta) const {
  std::lock_guard<std::mutex> lock(agents_mutex_);
  for (KeyframeState& kf : delta->keyframes) {
    const auto it = keyframe_owner_.find(kf.id);
    kf.own = it != keyframe_owner_.end() && it->second == agent;
  }
}

int MapGroupImpl::InsertInitialMap(GroupAgent* agent, const InitialMap& initial, bool prefer_group,
                                   KeyframeId* first, KeyframeId* second) {
  std::lock_guard<std::mutex> mapping(mapping_mutex_);
  const bool group_empty = map_.Read([](const MapData& m) { return m.keyframes().empty(); });
  if (prefer_group && group_empty && !localization_only_) {
    *first = map_.NextKeyframeId();
    *second = map_.NextKeyframeId();
    mapper_.InsertInitialMap(initial, *first, *second);
    MarkOwner(*first, agent->index());
    MarkOwner(*second, agent->index());
    return kGroupMapId;
  }
  const std::optional<int> own = agent->own_map_id();
  const int id = own ? *own : NewMapId();
  agent->UseOwnMapLocked(id);
  *first = agent->own_map().NextKeyframeId();
  *second = agent->own_map().NextKeyframeId();
  agent->own_mapper().InsertInitialMap(initial, *first, *second);
  return id;
}

void MapGroupImpl::MapKeyframe(GroupAgent* agent, int map_id, KeyframeCandidate keyframe) {
  if (map_id == kGroupMapId) MarkOwner(keyframe.id, agent->index());
  Job job{agent->index(), map_id, std::move(keyframe), std::chrono::steady_clock::now()};
  if (options_.deterministic) {
    std::lock_guard<std::mutex> mapping(mapping_mutex_);
    RunJobLocked(job);
  } else {
    jobs_.Push(std::move(job));
  }
}

void MapGroupImpl::MappingLoop() {
  while (auto job = jobs_.Pop()) {
    std::lock_guard<std::mutex> mapping(mapping_mutex_);
    RunJobLocked(*job);
  }
}

void MapGroupImpl::RunJobLocked(const Job& job) {
  const bool backlog = jobs_.size() > 0;
  if (job.map_id == kGroupMapId) {
    // An agent that left still contributes the keyframes it made.
    mapper_.Process(job.keyframe, backlog);
    return;
  }
  GroupAgent* agent = FindAgent(job.agent);
  // Gone, merged or abandoned since: the keyframe belongs to no map any more.
  if (agent == nullptr || agent->own_map_id() != job.map_id) return;
  agent->own_mapper().Process(job.keyframe, backlog);
  TryMergeLocked(agent, job.map_id, job.queued);
}

void MapGroupImpl::TryMergeLocked(GroupAgent* agent, int map_id,
                                  std::chrono::steady_clock::time_point queued) {
  const MapAlignmentOptions align = MergeAlignmentOptions(options_);
  bool enough_shared = false;
  std::optional<MapAlignment> alignment;
  map_.Read([&](const MapData& group) {
    if (group.keyframes().size() < 2) return;
    agent->own_map().Read([&](const MapData& own) {
      if (own.keyframes().size() < 2) return;
      int shared = 0;
      for (const auto& [id, point] : own.points()) shared += group.point(id) != nullptr ? 1 : 0;
      if (shared < align.min_shared_points) return;
      enough_shared = true;
      if (Expected<MapAlignment> a = AlignMaps(group, own, align)) alignment = *a;
    });
  });
  if (!enough_shared) return;
  std::chrono::steady_clock::time_point first_shared;
  {
    std::lock_guard<std::mutex> lock(agents_mutex_);
    first_shared = first_shared_.emplace(map_id, queued).first->second;
  }
  if (!alignment) return;
  const MapData own = agent->own_map().Read([](const MapData& m) { return m; });
  const KeyframeId first = map_.ReserveKeyframeIds(own.keyframes().size() + own.links().size());
  std::unordered_map<KeyframeId, KeyframeId> ids;
  map_.Write(
      [&](MapData& group) { ids = MergeMapInto(&group, own, alignment->into_from_from, first); });
  const double ms = MsBetween(first_shared, std::chrono::steady_clock::now());
  {
    std::lock_guard<std::mutex> lock(agents_mutex_);
    for (const auto& [from, to] : ids) keyframe_owner_[to] = agent->index();
    first_shared_.erase(map_id);
    ++merges_;
    merge_ms_.push_back(ms);
    if (merge_ms_.size() > kMergeTimesKept) merge_ms_.pop_front();
  }
  M2S_LOG(kInfo) << "map group: agent " << agent->index() << "'s map " << map_id
                 << " merged into the group's map (" << alignment->inliers << " of "
                 << alignment->shared_points << " shared points fit, rms "
                 << alignment->rms_residual << ", " << alignment->image_agreement * 100.0
                 << " % of their observations agree, scale " << alignment->into_from_from.scale()
                 << ", " << ms << " ms)";
  agent->NotifyMerged(map_id, alignment->into_from_from, std::move(ids));
  mapper_.GlobalBundleAdjust(kMergeBaIterations, options_.mapper.local_ba_max_points);
}

MapDelta MapGroupImpl::TakeDeltaFor(int agent) {
  std::lock_guard<std::mutex> lock(deltas_mutex_);
  const MapDelta latest = map_.TakeDelta();
  if (latest.full || latest.revision != latest.base_revision) {
    for (auto& [index, pending] : pending_deltas_) AppendDelta(&pending, latest);
  }
  MapDelta out;
  const auto it = pending_deltas_.find(agent);
  if (it == pending_deltas_.end()) {
    out = map_.FullDelta();
  } else {
    out = std::move(it->second);
    it->second = MapDelta();
    it->second.base_revision = it->second.revision = out.revision;
  }
  SetOwnFlags(agent, &out);
  return out;
}

MapDelta MapGroupImpl::FullDeltaFor(int agent) const {
  MapDelta out = map_.FullDelta();
  SetOwnFlags(agent, &out);
  return out;
}

void MapGroupImpl::ResetDeltaFor(int agent) {
  std::lock_guard<std::mutex> lock(deltas_mutex_);
  // The others get what changed so far; this agent starts over from the whole map.
  const MapDelta latest = map_.TakeDelta();
  if (latest.full || latest.revision != latest.base_revision) {
    for (auto& [index, pending] : pending_deltas_) AppendDelta(&pending, latest);
  }
  pending_deltas_[agent] = map_.FullDelta();
}

}  // namespace m2s::slam
