// The map's contents: keyframes and points in containers keyed by id, with id back-links.
//
// A Keyframe keeps every feature of its frame (mapped or not), sorted by vertex id: they are
// the observations new points are triangulated from. A MapPoint (one per mesh vertex, keyed by
// VertexId) lists the keyframes whose observation of it is used (inliers), sorted by id.
// Covisibility is derived on demand from shared point ids.
//
// Thread-safety: none. MapData is only reached through Map::Read / Map::Write, which hold the
// map's mutex; every mutation is recorded in a change log that Map turns into MapDeltas.
//
//   map.Write([&](MapData& m) { m.AddPoint(id, position, keyframe_id); m.AddObservation(id, kf);
//   });
#pragma once

#include <map>
#include <optional>
#include <set>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/geometry.h"
#include "m2s/common/types.h"

namespace m2s::slam {

struct Keyframe {
  KeyframeId id = 0;
  int64_t seq = 0;
  double timestamp = 0.0;
  Pose3 world_from_camera;
  // Every feature of the frame, sorted by id (parallel arrays).
  std::vector<VertexId> ids;
  std::vector<Eigen::Vector2d> uvs;
  // Number of map points this keyframe observes (maintained by MapData).
  int num_points = 0;

  // The pixel position of vertex `id` in this keyframe, or nullptr.
  const Eigen::Vector2d* Find(VertexId id) const;
};

struct MapPoint {
  VertexId id = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  // The keyframe that created the point: drift correction moves the point with it.
  KeyframeId reference_keyframe = 0;
  std::vector<KeyframeId> observers;  // sorted ascending
  // Relative uncertainty (mapping/point_uncertainty.h): the standard deviation of the position
  // along its least constrained direction over its mean depth, at the measurement model's pixel
  // noise; negative while unknown (a point not yet evaluated, or read from a version-1 file).
  double uncertainty = -1.0;
  // Well constrained (uncertainty within MapperOptions::max_point_uncertainty and every
  // observation agreeing, or unknown): only such points are sent to clients (and, with
  // TrackerOptions::min_constrained_points, solve tracked poses).
  bool constrained = true;
  KeyframeId last_observer() const { return observers.empty() ? 0 : observers.back(); }
};

// Where a removed keyframe was, relative to a surviving one (trajectory entries that referred
// to it stay valid).
struct KeyframeLink {
  KeyframeId parent = 0;
  Pose3 parent_from_camera;
};

// Changes since the last delta, coalesced (an upsert after a removal cancels it and so on).
struct ChangeLog {
  std::set<KeyframeId> upserted_keyframes;
  std::set<KeyframeId> removed_keyframes;
  std::unordered_set<VertexId> upserted_points;
  std::unordered_set<VertexId> removed_points;
  // Points that stopped being well constrained: clients drop them.
  std::unordered_set<VertexId> hidden_points;
  bool empty() const {
    return upserted_keyframes.empty() && removed_keyframes.empty() && upserted_points.empty() &&
           removed_points.empty() && hidden_points.empty();
  }
  void Clear() { *this = ChangeLog(); }
};

class MapData {
 public:
  // ---- reads ----
  const std::map<KeyframeId, Keyframe>& keyframes() const { return keyframes_; }
  const std::unordered_map<VertexId, MapPoint>& points() const { return points_; }
  const Keyframe* keyframe(KeyframeId id) const;
  const MapPoint* point(VertexId id) const;
  // Keyframes (ascending) having a feature with this id, mapped or not; nullptr when none.
  const std::vector<KeyframeId>* KeyframesWithFeature(VertexId id) const;
  // Keyframes sharing at least `min_shared` points with `id`, most shared first (ties: newer
  // first).
  std::vector<std::pair<KeyframeId, int>> Covisible(KeyframeId id, int min_shared) const;
  // The current pose of a keyframe, following links of removed keyframes.
  std::optional<Pose3> ResolveKeyframePose(KeyframeId id) const;
  const ChangeLog& changes() const { return changes_; }
  bool empty() const { return keyframes_.empty(); }

  // ---- mutations (recorded in the change log) ----
  // Adds a keyframe without observations (ids must be sorted and unique).
  void AddKeyframe(Keyframe keyframe);
  // Removes a keyframe and its observations; `link` keeps trajectory entries resolvable.
  void RemoveKeyframe(KeyframeId id, std::optional<KeyframeLink> link);
  void SetKeyframePose(KeyframeId id, const Pose3& world_from_camera);
  // Adds a point without observers (replaces nothing: the id must be new).
  void AddPoint(VertexId id, const Eigen::Vector3d& position, KeyframeId reference_keyframe);
  void SetPointPosition(VertexId id, const Eigen::Vector3d& position);
  // Clients see a change of `constrained` (the point appears or goes); the uncertainty alone is
  // not a mutation.
  void SetPointUncertainty(VertexId id, double uncertainty, bool constrained);
  void RemovePoint(VertexId id);
  // The vertex `id` moved in the scene (its features in keyframes before `since` show where it
  // was): removes its point and those features, so that it is mapped anew from `since` on.
  void ForgetMovedVertex(VertexId id, KeyframeId since);
  // Observation of point `id` by keyframe `kf` (which must have a feature with that id).
  bool AddObservation(VertexId id, KeyframeId kf);
  void RemoveObservation(VertexId id, KeyframeId kf);
  void Clear();

  // Restores links of keyframes removed earlier (map loading).
  void SetLink(KeyframeId id, const KeyframeLink& link) { links_[id] = link; }
  const std::unordered_map<KeyframeId, KeyframeLink>& links() const { return links_; }
  void ClearChanges() { changes_.Clear(); }
  // Incremented by every mutation (Map turns it into revisions).
  uint64_t mutation_count() const { return mutation_count_; }

 private:
  std::map<KeyframeId, Keyframe> keyframes_;
  std::unordered_map<VertexId, MapPoint> points_;
  std::unordered_map<VertexId, std::vector<KeyframeId>> feature_index_;
  std::unordered_map<KeyframeId, KeyframeLink> links_;
  ChangeLog changes_;
  uint64_t mutation_count_ = 0;
};

}  // namespace m2s::slam
