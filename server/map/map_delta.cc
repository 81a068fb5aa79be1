#include "map/map_delta.h"

#include <algorithm>
#include <map>
#include <set>

#include "m2s/common/logging.h"

namespace m2s::slam {

void AppendDelta(MapDelta* accumulated, const MapDelta& next) {
  if (next.full) {
    *accumulated = next;
    return;
  }
  // A delta may overlap what was accumulated (taken after a full snapshot): its items are the
  // map's state when it was taken, never older than the snapshot.
  M2S_CHECK(next.base_revision <= accumulated->revision)
      << "delta " << next.base_revision << " -> " << next.revision << " does not follow "
      << accumulated->revision;
  MapDelta& acc = *accumulated;
  std::map<KeyframeId, KeyframeState> keyframes;
  for (const KeyframeState& kf : acc.keyframes) keyframes[kf.id] = kf;
  std::set<KeyframeId> removed_keyframes(acc.removed_keyframes.begin(),
                                         acc.removed_keyframes.end());
  std::map<VertexId, Eigen::Vector3f> points;
  for (size_t i = 0; i < acc.point_ids.size(); ++i)
    points[acc.point_ids[i]] = acc.point_positions[i];
  std::set<VertexId> removed_points(acc.removed_points.begin(), acc.removed_points.end());

  for (const KeyframeId id : next.removed_keyframes) {
    keyframes.erase(id);
    if (!acc.full) removed_keyframes.insert(id);
  }
  for (const KeyframeState& kf : next.keyframes) {
    keyframes[kf.id] = kf;
    removed_keyframes.erase(kf.id);
  }
  for (const VertexId id : next.removed_points) {
    points.erase(id);
    if (!acc.full) removed_points.insert(id);
  }
  for (size_t i = 0; i < next.point_ids.size(); ++i) {
    points[next.point_ids[i]] = next.point_positions[i];
    removed_points.erase(next.point_ids[i]);
  }

  acc.revision = std::max(acc.revision, next.revision);
  acc.keyframes.clear();
  for (const auto& [id, kf] : keyframes) acc.keyframes.push_back(kf);
  acc.removed_keyframes.assign(removed_keyframes.begin(), removed_keyframes.end());
  acc.point_ids.clear();
  acc.point_positions.clear();
  for (const auto& [id, p] : points) {
    acc.point_ids.push_back(id);
    acc.point_positions.push_back(p);
  }
  acc.removed_points.assign(removed_points.begin(), removed_points.end());
}

}  // namespace m2s::slam
