#include "mapping/keyframe_culling.h"

#include <algorithm>
#include <iterator>
#include <limits>

#include "mapping/ba_window.h"

namespace m2s::slam {

Redundancy MeasureRedundancy(const MapData& m, KeyframeId id, int min_other_observers) {
  Redundancy r;
  const Keyframe* kf = m.keyframe(id);
  if (kf == nullptr) return r;
  for (const VertexId vid : kf->ids) {
    const MapPoint* p = m.point(vid);
    if (p == nullptr || !std::binary_search(p->observers.begin(), p->observers.end(), id)) continue;
    ++r.observed;
    if (static_cast<int>(p->observers.size()) - 1 >= min_other_observers) ++r.redundant;
  }
  return r;
}

bool IsRedundant(const MapData& m, KeyframeId id, const MapperOptions& options) {
  const Redundancy r = MeasureRedundancy(m, id, options.keyframe_redundancy_observers);
  return r.observed > 0 && r.redundant >= options.keyframe_redundancy * r.observed;
}

std::vector<KeyframeId> CullingCandidates(const MapData& m, KeyframeId newest,
                                          const MapperOptions& options) {
  std::vector<KeyframeId> out;
  if (m.empty()) return out;
  const KeyframeId first = m.keyframes().begin()->first;
  for (const KeyframeId id : CovisibleNeighbours(m, newest, options.local_ba_window)) {
    if (id != first && id != newest) out.push_back(id);
  }
  return out;
}

std::optional<KeyframeId> OldestBeyondBound(const MapData& m, KeyframeId newest,
                                            const MapperOptions& options) {
  if (static_cast<int>(m.keyframes().size()) <= options.max_keyframes) return std::nullopt;
  const KeyframeId oldest = std::next(m.keyframes().begin())->first;
  if (oldest == newest) return std::nullopt;
  return oldest;
}

KeyframeLink CullLink(const MapData& m, KeyframeId id) {
  const Keyframe* kf = m.keyframe(id);
  const auto covisible = m.Covisible(id, 1);
  std::optional<KeyframeLink> link;
  double nearest = std::numeric_limits<double>::infinity();
  for (const auto& [other, shared] : covisible) {
    if (shared < kMinCovisiblePoints) break;
    const Keyframe* o = m.keyframe(other);
    const double d =
        (o->world_from_camera.translation() - kf->world_from_camera.translation()).squaredNorm();
    if (d < nearest) {
      nearest = d;
      link = KeyframeLink{other, o->world_from_camera.Inverse() * kf->world_from_camera};
    }
  }
  if (link) return *link;
  if (!covisible.empty()) {
    const Keyframe* o = m.keyframe(covisible.front().first);
    return KeyframeLink{o->id, o->world_from_camera.Inverse() * kf->world_from_camera};
  }
  const auto it = m.keyframes().find(id);
  const Keyframe& neighbour =
      it == m.keyframes().begin() ? std::next(it)->second : std::prev(it)->second;
  return KeyframeLink{neighbour.id, neighbour.world_from_camera.Inverse() * kf->world_from_camera};
}

void CullKeyframe(MapData* m, KeyframeId id) {
  const Keyframe* kf = m->keyframe(id);
  if (kf == nullptr) return;
  const KeyframeLink link = CullLink(*m, id);
  std::vector<VertexId> touched;
  for (const VertexId vid : kf->ids) {
    if (m->point(vid) != nullptr) touched.push_back(vid);
  }
  m->RemoveKeyframe(id, link);
  for (const VertexId vid : touched) {
    const MapPoint* p = m->point(vid);
    if (p != nullptr && p->observers.size() < 2) m->RemovePoint(vid);
  }
}

}  // namespace m2s::slam
