#include "map/map.h"

#include <algorithm>

#include "map/map_merge.h"

namespace m2s::slam {

KeyframeId Map::NextKeyframeId() {
  std::unique_lock<std::shared_mutex> lock(mutex_);
  return next_keyframe_id_++;
}

KeyframeId Map::ReserveKeyframeIds(size_t count) {
  std::unique_lock<std::shared_mutex> lock(mutex_);
  const KeyframeId first = next_keyframe_id_;
  next_keyframe_id_ += static_cast<KeyframeId>(count);
  return first;
}

uint64_t Map::revision() const {
  std::shared_lock<std::shared_mutex> lock(mutex_);
  return revision_;
}

MapDelta Map::MakeDeltaLocked(bool full) const {
  MapDelta delta;
  delta.revision = revision_;
  delta.full = full;
  delta.base_revision = full ? 0 : taken_revision_;
  auto add_keyframe = [&](const Keyframe& kf) {
    delta.keyframes.push_back({kf.id, kf.timestamp, kf.world_from_camera});
  };
  auto add_point = [&](const MapPoint& p) {
    delta.point_ids.push_back(p.id);
    delta.point_positions.push_back(p.position.cast<float>());
  };
  if (full) {
    for (const auto& [id, kf] : data_.keyframes()) add_keyframe(kf);
    std::vector<VertexId> ids;
    ids.reserve(data_.points().size());
    for (const auto& [id, p] : data_.points()) ids.push_back(id);
    std::sort(ids.begin(), ids.end());
    for (const VertexId id : ids) {
      const MapPoint& p = *data_.point(id);
      if (p.constrained) add_point(p);
    }
    return delta;
  }
  const ChangeLog& log = data_.changes();
  for (const KeyframeId id : log.upserted_keyframes) {
    if (const Keyframe* kf = data_.keyframe(id)) add_keyframe(*kf);
  }
  delta.removed_keyframes.assign(log.removed_keyframes.begin(), log.removed_keyframes.end());
  std::vector<VertexId> ids(log.upserted_points.begin(), log.upserted_points.end());
  std::sort(ids.begin(), ids.end());
  for (const VertexId id : ids) {
    const MapPoint* p = data_.point(id);
    if (p != nullptr && p->constrained) add_point(*p);
  }
  delta.removed_points.assign(log.removed_points.begin(), log.removed_points.end());
  // A point that is no longer well constrained leaves the clients' maps (removing one a client
  // never received is harmless).
  for (const VertexId id : log.hidden_points) {
    const MapPoint* p = data_.point(id);
    if (p != nullptr && !p->constrained) delta.removed_points.push_back(id);
  }
  std::sort(delta.removed_points.begin(), delta.removed_points.end());
  return delta;
}

MapDelta Map::TakeDelta() {
  std::unique_lock<std::shared_mutex> lock(mutex_);
  MapDelta delta;
  if (next_delta_full_) {
    delta = MakeDeltaLocked(/*full=*/true);
    next_delta_full_ = false;
  } else if (revision_ != taken_revision_) {
    delta = MakeDeltaLocked(/*full=*/false);
  } else {
    delta.base_revision = delta.revision = revision_;
    return delta;
  }
  data_.ClearChanges();
  taken_revision_ = revision_;
  return delta;
}

MapDelta Map::FullDelta() const {
  std::shared_lock<std::shared_mutex> lock(mutex_);
  return MakeDeltaLocked(/*full=*/true);
}

void Map::Clear() {
  std::unique_lock<std::shared_mutex> lock(mutex_);
  data_.Clear();
  data_.ClearChanges();
  ++revision_;
  next_delta_full_ = true;
}

MapData Map::TakeData() {
  std::unique_lock<std::shared_mutex> lock(mutex_);
  MapData out = std::move(data_);
  out.ClearChanges();
  data_ = MapData();
  ++revision_;
  next_delta_full_ = true;
  return out;
}

uint64_t Map::MergeInto(MapData base, const Sim3& base_from_map) {
  std::unique_lock<std::shared_mutex> lock(mutex_);
  MergeMapInto(&base, data_, base_from_map);
  base.ClearChanges();
  data_ = std::move(base);
  ++revision_;
  next_delta_full_ = true;
  ++correction_.epoch;
  correction_.new_from_old = base_from_map;
  return correction_.epoch;
}

void Map::PublishCorrection(const Sim3& new_from_old) {
  std::unique_lock<std::shared_mutex> lock(mutex_);
  ++correction_.epoch;
  correction_.new_from_old = new_from_old;
}

WorldCorrection Map::correction() const {
  std::shared_lock<std::shared_mutex> lock(mutex_);
  return correction_;
}

}  // namespace m2s::slam
