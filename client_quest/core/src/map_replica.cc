#include "m2s/client/map_replica.h"

#include <algorithm>

namespace m2s::client {

void MapReplica::Reset(int64_t session_id) {
  std::lock_guard<std::mutex> lock(mutex_);
  session_id_ = session_id;
  revision_ = 0;
  keyframes_.clear();
  points_.clear();
}

MapReplica::ApplyResult MapReplica::Apply(const map_delta_t& delta) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (delta.session_id != session_id_) return ApplyResult::kOtherSession;
  if (delta.full) {
    if (delta.revision < revision_) return ApplyResult::kStale;
    keyframes_.clear();
    points_.clear();
  } else {
    if (delta.revision <= revision_) return ApplyResult::kStale;
    if (delta.base_revision != revision_) return ApplyResult::kGap;
  }
  for (int32_t id : delta.removed_keyframes) keyframes_.erase(id);
  for (int32_t id : delta.removed_points) points_.erase(id);
  for (const keyframe_t& k : delta.keyframes) {
    auto pose = wire::FromMessage(k.world_from_camera);
    if (!pose) continue;
    keyframes_[k.id] = {k.id, static_cast<double>(k.capture_time_us) * 1e-6, *pose, k.own != 0};
  }
  const size_t n = std::min(delta.point_ids.size(), delta.point_xyz.size());
  for (size_t i = 0; i < n; ++i) {
    const auto& p = delta.point_xyz[i];
    points_[delta.point_ids[i]] = Eigen::Vector3f(p[0], p[1], p[2]);
  }
  revision_ = delta.revision;
  return delta.full ? ApplyResult::kFull : ApplyResult::kApplied;
}

int64_t MapReplica::revision() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return revision_;
}

int64_t MapReplica::session_id() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return session_id_;
}

size_t MapReplica::num_points() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return points_.size();
}

size_t MapReplica::num_keyframes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return keyframes_.size();
}

MapSnapshot MapReplica::Snapshot() const {
  std::lock_guard<std::mutex> lock(mutex_);
  MapSnapshot snapshot;
  snapshot.session_id = session_id_;
  snapshot.revision = revision_;
  for (const auto& entry : keyframes_) snapshot.keyframes.push_back(entry.second);
  std::vector<int32_t> ids;
  ids.reserve(points_.size());
  for (const auto& entry : points_) ids.push_back(entry.first);
  std::sort(ids.begin(), ids.end());
  for (int32_t id : ids) {
    snapshot.point_ids.push_back(static_cast<VertexId>(id));
    snapshot.points.push_back(points_.at(id));
  }
  return snapshot;
}

}  // namespace m2s::client
