// MapReplica: the client's copy of a session's map, kept current from map_delta_t messages.
//
// Deltas are applied in order: a delta whose base_revision equals the replica's revision moves
// it to `revision`; a full delta replaces everything; an older delta is ignored; a delta from
// further ahead means one was missed: Apply() reports kGap and the owner asks the server for a
// resync (session_control_t RESYNC_REQUEST), whose answer is a full delta.
//
// Thread-safety: all methods may be called from any thread (one internal mutex).
//
//   MapReplica replica;
//   replica.Reset(session_id);
//   if (replica.Apply(delta) == MapReplica::ApplyResult::kGap) RequestResync();
//   MapSnapshot map = replica.Snapshot();
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/geometry.h"
#include "m2s/common/wire_format.h"

namespace m2s::client {

struct ReplicaKeyframe {
  int32_t id = 0;
  double timestamp = 0.0;  // seconds
  Pose3 world_from_camera;
  // Created by this session's agent (false: by another agent of its map group).
  bool own = true;
};

struct MapSnapshot {
  int64_t session_id = 0;
  int64_t revision = 0;
  std::vector<ReplicaKeyframe> keyframes;  // sorted by id
  std::vector<VertexId> point_ids;         // sorted by id
  std::vector<Eigen::Vector3f> points;     // parallel to point_ids
};

class MapReplica {
 public:
  enum class ApplyResult { kApplied, kFull, kStale, kGap, kOtherSession };

  // Forgets the map and follows `session_id` from revision 0.
  void Reset(int64_t session_id);
  ApplyResult Apply(const map_delta_t& delta);

  int64_t revision() const;
  int64_t session_id() const;
  size_t num_points() const;
  size_t num_keyframes() const;
  MapSnapshot Snapshot() const;

 private:
  mutable std::mutex mutex_;
  int64_t session_id_ = 0;
  int64_t revision_ = 0;
  std::map<int32_t, ReplicaKeyframe> keyframes_;
  std::unordered_map<int32_t, Eigen::Vector3f> points_;
};

}  // namespace m2s::client
