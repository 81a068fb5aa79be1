#include "mapping/ba_window.h"

#include <algorithm>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include "m2s/common/numeric.h"

namespace m2s::slam {
namespace {

// Splits ascending `ids` into the evenly spaced subset kept (at most max_points of them; 0:
// all) and the rest.
void CapPoints(std::vector<VertexId> ids, int max_points, BaWindow* window) {
  const std::vector<size_t> kept = EvenlySpacedIndices(
      ids.size(), static_cast<size_t>(std::max(max_points, 0)), IndexRounding::kUp);
  size_t next = 0;
  for (size_t i = 0; i < ids.size(); ++i) {
    if (next < kept.size() && kept[next] == i) {
      window->points.push_back(ids[i]);
      ++next;
    } else {
      window->rest.push_back(ids[i]);
    }
  }
}

bool Observes(const MapPoint& p, KeyframeId keyframe) {
  return std::binary_search(p.observers.begin(), p.observers.end(), keyframe);
}

}  // namespace

std::vector<KeyframeId> CovisibleNeighbours(const MapData& m, KeyframeId id, int max_count) {
  std::vector<KeyframeId> out;
  for (const auto& [other, shared] : m.Covisible(id, kMinCovisiblePoints)) {
    if (static_cast<int>(out.size()) >= max_count) break;
    out.push_back(other);
  }
  return out;
}

BaWindow SelectLocalBaWindow(const MapData& m, KeyframeId newest, const MapperOptions& options) {
  BaWindow window;
  std::vector<KeyframeId> optimised = {newest};
  for (const KeyframeId id : CovisibleNeighbours(m, newest, options.local_ba_window - 1)) {
    optimised.push_back(id);
  }
  std::sort(optimised.begin(), optimised.end());
  const std::unordered_set<KeyframeId> in_window(optimised.begin(), optimised.end());
  // Points seen by the window; their other observers, with the number of points they share.
  std::vector<VertexId> point_ids;
  std::unordered_set<VertexId> seen;
  std::unordered_map<KeyframeId, int> outside;
  for (const KeyframeId id : optimised) {
    const Keyframe* kf = m.keyframe(id);
    if (kf == nullptr) continue;
    for (const VertexId vid : kf->ids) {
      const MapPoint* p = m.point(vid);
      if (p == nullptr || !Observes(*p, id) || !seen.insert(vid).second) continue;
      point_ids.push_back(vid);
      for (const KeyframeId o : p->observers) {
        if (!in_window.count(o)) ++outside[o];
      }
    }
  }
  // The most sharing outside observers (ties: the newer), then in id order.
  std::vector<std::pair<int, KeyframeId>> fixed;
  for (const auto& [id, n] : outside) fixed.emplace_back(n, id);
  std::sort(fixed.begin(), fixed.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second > b.second;
  });
  const size_t max_fixed = static_cast<size_t>(kFixedKeyframesPerWindow * options.local_ba_window);
  if (fixed.size() > max_fixed) fixed.resize(max_fixed);
  std::sort(fixed.begin(), fixed.end(),
            [](const auto& a, const auto& b) { return a.second < b.second; });

  for (const KeyframeId id : optimised) {
    if (m.keyframe(id) != nullptr) window.keyframes.push_back({id, false});
  }
  for (const auto& [n, id] : fixed) window.keyframes.push_back({id, true});
  // Without an outside keyframe, hold the oldest window keyframe (the gauge); keyframe 0 and
  // its partner stay fixed while they are in the window, so early windows keep the scale.
  if (fixed.empty() && !window.keyframes.empty()) window.keyframes[0].fixed = true;
  std::sort(point_ids.begin(), point_ids.end());
  CapPoints(std::move(point_ids), options.local_ba_max_points, &window);
  return window;
}

BaWindow SelectGlobalBaWindow(const MapData& m, int max_points) {
  BaWindow window;
  for (const auto& [id, kf] : m.keyframes()) {
    window.keyframes.push_back({id, window.keyframes.empty()});
  }
  std::vector<VertexId> ids;
  ids.reserve(m.points().size());
  for (const auto& [id, p] : m.points()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  CapPoints(std::move(ids), max_points, &window);
  return window;
}

BaProblem MakeBaProblem(const MapData& m, const BaWindow& window) {
  BaProblem problem;
  std::unordered_map<KeyframeId, int> kf_index;
  for (const BaWindow::Member& member : window.keyframes) {
    kf_index[member.id] = static_cast<int>(problem.keyframes.size());
    problem.keyframes.push_back(
        {member.id, m.keyframe(member.id)->world_from_camera.Inverse(), member.fixed});
  }
  for (const VertexId vid : window.points) {
    const MapPoint* p = m.point(vid);
    const int pi = static_cast<int>(problem.points.size());
    problem.points.push_back({vid, p->position, false});
    for (const KeyframeId o : p->observers) {
      const auto it = kf_index.find(o);
      if (it == kf_index.end()) continue;
      problem.observations.push_back({it->second, pi, *m.keyframe(o)->Find(vid)});
    }
  }
  return problem;
}

}  // namespace m2s::slam
