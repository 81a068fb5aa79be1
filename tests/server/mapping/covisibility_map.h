// Test helper: a MapData with a chosen covisibility, built from groups of points each observed
// by a chosen set of keyframes (the keyframes measure exactly the points of their groups).
#pragma once

#include <algorithm>
#include <map>
#include <vector>

#include "map/map_data.h"

namespace m2s::slam::testing {

struct PointGroup {
  int count = 0;
  std::vector<KeyframeId> observers;
};

// Keyframes `keyframes` (camera k at x = 0.1 k, looking along z) and the groups' points (ids
// from 0, group after group), in `groups` order; `group_ids` receives each group's ids.
inline MapData MakeCovisibilityMap(const std::vector<KeyframeId>& keyframes,
                                   const std::vector<PointGroup>& groups,
                                   std::vector<std::vector<VertexId>>* group_ids = nullptr) {
  std::map<KeyframeId, std::vector<VertexId>> measured;
  std::vector<std::vector<VertexId>> ids(groups.size());
  VertexId next = 0;
  for (size_t g = 0; g < groups.size(); ++g) {
    for (int i = 0; i < groups[g].count; ++i) {
      ids[g].push_back(next);
      for (const KeyframeId k : groups[g].observers) measured[k].push_back(next);
      ++next;
    }
  }
  MapData m;
  for (const KeyframeId k : keyframes) {
    Keyframe kf;
    kf.id = k;
    kf.seq = k;
    kf.timestamp = 0.1 * k;
    kf.world_from_camera = Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * k, 0, 0));
    kf.ids = measured[k];
    std::sort(kf.ids.begin(), kf.ids.end());
    for (const VertexId v : kf.ids) kf.uvs.emplace_back(10.0 + v % 600, 10.0 + v / 600);
    m.AddKeyframe(std::move(kf));
  }
  for (size_t g = 0; g < groups.size(); ++g) {
    for (const VertexId v : ids[g]) {
      m.AddPoint(v, Eigen::Vector3d(0.01 * v, 0.0, 2.0), groups[g].observers.front());
      for (const KeyframeId k : groups[g].observers) m.AddObservation(v, k);
    }
  }
  if (group_ids != nullptr) *group_ids = std::move(ids);
  return m;
}

// The ids of the listed groups, ascending.
inline std::vector<VertexId> IdsOf(const std::vector<std::vector<VertexId>>& group_ids,
                                   const std::vector<int>& groups) {
  std::vector<VertexId> out;
  for (const int g : groups) out.insert(out.end(), group_ids[g].begin(), group_ids[g].end());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace m2s::slam::testing
