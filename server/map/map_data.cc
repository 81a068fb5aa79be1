#include "map/map_data.h"

#include <algorithm>

#include "m2s/common/check.h"

namespace m2s::slam {

const Eigen::Vector2d* Keyframe::Find(VertexId id) const {
  const auto it = std::lower_bound(ids.begin(), ids.end(), id);
  if (it == ids.end() || *it != id) return nullptr;
  return &uvs[static_cast<size_t>(it - ids.begin())];
}

const Keyframe* MapData::keyframe(KeyframeId id) const {
  const auto it = keyframes_.find(id);
  return it == keyframes_.end() ? nullptr : &it->second;
}

const MapPoint* MapData::point(VertexId id) const {
  const auto it = points_.find(id);
  return it == points_.end() ? nullptr : &it->second;
}

const std::vector<KeyframeId>* MapData::KeyframesWithFeature(VertexId id) const {
  const auto it = feature_index_.find(id);
  return it == feature_index_.end() ? nullptr : &it->second;
}

std::vector<std::pair<KeyframeId, int>> MapData::Covisible(KeyframeId id, int min_shared) const {
  std::vector<std::pair<KeyframeId, int>> out;
  const Keyframe* kf = keyframe(id);
  if (kf == nullptr) return out;
  std::unordered_map<KeyframeId, int> counts;
  for (const VertexId vid : kf->ids) {
    const MapPoint* p = point(vid);
    if (p == nullptr || !std::binary_search(p->observers.begin(), p->observers.end(), id)) continue;
    for (const KeyframeId other : p->observers) {
      if (other != id) ++counts[other];
    }
  }
  for (const auto& [other, n] : counts) {
    if (n >= min_shared) out.emplace_back(other, n);
  }
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) {
    return a.second != b.second ? a.second > b.second : a.first > b.first;
  });
  return out;
}

std::optional<Pose3> MapData::ResolveKeyframePose(KeyframeId id) const {
  Pose3 acc;  // parent_from_camera accumulated along the chain
  for (int hops = 0; hops < 100000; ++hops) {
    if (const Keyframe* kf = keyframe(id)) return kf->world_from_camera * acc;
    const auto it = links_.find(id);
    if (it == links_.end()) return std::nullopt;
    acc = it->second.parent_from_camera * acc;
    id = it->second.parent;
  }
  return std::nullopt;
}

void MapData::AddKeyframe(Keyframe keyframe) {
  ++mutation_count_;
  const KeyframeId id = keyframe.id;
  M2S_CHECK(keyframes_.count(id) == 0) << "keyframe " << id << " added twice";
  M2S_CHECK(keyframe.ids.size() == keyframe.uvs.size());
  keyframe.num_points = 0;
  for (const VertexId vid : keyframe.ids) {
    auto& list = feature_index_[vid];
    list.insert(std::upper_bound(list.begin(), list.end(), id), id);
  }
  keyframes_.emplace(id, std::move(keyframe));
  links_.erase(id);
  changes_.removed_keyframes.erase(id);
  changes_.upserted_keyframes.insert(id);
}

void MapData::RemoveKeyframe(KeyframeId id, std::optional<KeyframeLink> link) {
  ++mutation_count_;
  const auto it = keyframes_.find(id);
  if (it == keyframes_.end()) return;
  const Keyframe& kf = it->second;
  for (const VertexId vid : kf.ids) {
    auto pit = points_.find(vid);
    if (pit != points_.end()) {
      auto& obs = pit->second.observers;
      const auto o = std::lower_bound(obs.begin(), obs.end(), id);
      if (o != obs.end() && *o == id) {
        obs.erase(o);
        changes_.upserted_points.insert(vid);
      }
    }
    auto fit = feature_index_.find(vid);
    if (fit != feature_index_.end()) {
      auto& list = fit->second;
      const auto f = std::lower_bound(list.begin(), list.end(), id);
      if (f != list.end() && *f == id) list.erase(f);
      if (list.empty()) feature_index_.erase(fit);
    }
  }
  keyframes_.erase(it);
  if (link) links_[id] = *link;
  changes_.upserted_keyframes.erase(id);
  changes_.removed_keyframes.insert(id);
}

void MapData::SetKeyframePose(KeyframeId id, const Pose3& world_from_camera) {
  ++mutation_count_;
  auto it = keyframes_.find(id);
  if (it == keyframes_.end()) return;
  it->second.world_from_camera = world_from_camera;
  changes_.upserted_keyframes.insert(id);
}

void MapData::AddPoint(VertexId id, const Eigen::Vector3d& position,
                       KeyframeId reference_keyframe) {
  ++mutation_count_;
  M2S_CHECK(points_.count(id) == 0) << "point " << id << " added twice";
  MapPoint p;
  p.id = id;
  p.position = position;
  p.reference_keyframe = reference_keyframe;
  points_.emplace(id, std::move(p));
  changes_.removed_points.erase(id);
  changes_.upserted_points.insert(id);
}

void MapData::SetPointPosition(VertexId id, const Eigen::Vector3d& position) {
  ++mutation_count_;
  auto it = points_.find(id);
  if (it == points_.end()) return;
  it->second.position = position;
  changes_.upserted_points.insert(id);
}

void MapData::SetPointUncertainty(VertexId id, double uncertainty, bool constrained) {
  auto it = points_.find(id);
  if (it == points_.end()) return;
  it->second.uncertainty = uncertainty;
  if (it->second.constrained == constrained) return;
  ++mutation_count_;
  it->second.constrained = constrained;
  if (constrained) {
    changes_.hidden_points.erase(id);
    changes_.upserted_points.insert(id);
  } else {
    changes_.hidden_points.insert(id);
  }
}

void MapData::RemovePoint(VertexId id) {
  ++mutation_count_;
  auto it = points_.find(id);
  if (it == points_.end()) return;
  for (const KeyframeId kf : it->second.observers) {
    auto kit = keyframes_.find(kf);
    if (kit != keyframes_.end()) --kit->second.num_points;
  }
  points_.erase(it);
  changes_.upserted_points.erase(id);
  changes_.hidden_points.erase(id);
  changes_.removed_points.insert(id);
}

void MapData::ForgetMovedVertex(VertexId id, KeyframeId since) {
  RemovePoint(id);
  auto fit = feature_index_.find(id);
  if (fit == feature_index_.end()) return;
  std::vector<KeyframeId>& list = fit->second;
  for (const KeyframeId kf : list) {
    if (kf >= since) continue;
    Keyframe& k = keyframes_.at(kf);
    const auto at = std::lower_bound(k.ids.begin(), k.ids.end(), id);
    if (at == k.ids.end() || *at != id) continue;
    k.uvs.erase(k.uvs.begin() + (at - k.ids.begin()));
    k.ids.erase(at);
  }
  std::erase_if(list, [since](KeyframeId kf) { return kf < since; });
  if (list.empty()) feature_index_.erase(fit);
}

bool MapData::AddObservation(VertexId id, KeyframeId kf) {
  ++mutation_count_;
  auto pit = points_.find(id);
  auto kit = keyframes_.find(kf);
  if (pit == points_.end() || kit == keyframes_.end() || kit->second.Find(id) == nullptr) {
    return false;
  }
  auto& obs = pit->second.observers;
  const auto o = std::lower_bound(obs.begin(), obs.end(), kf);
  if (o != obs.end() && *o == kf) return true;
  obs.insert(o, kf);
  ++kit->second.num_points;
  changes_.upserted_points.insert(id);
  return true;
}

void MapData::RemoveObservation(VertexId id, KeyframeId kf) {
  ++mutation_count_;
  auto pit = points_.find(id);
  if (pit == points_.end()) return;
  auto& obs = pit->second.observers;
  const auto o = std::lower_bound(obs.begin(), obs.end(), kf);
  if (o == obs.end() || *o != kf) return;
  obs.erase(o);
  auto kit = keyframes_.find(kf);
  if (kit != keyframes_.end()) --kit->second.num_points;
  changes_.upserted_points.insert(id);
}

void MapData::Clear() {
  ++mutation_count_;
  for (const auto& [id, kf] : keyframes_) changes_.removed_keyframes.insert(id);
  for (const auto& [id, p] : points_) changes_.removed_points.insert(id);
  changes_.upserted_keyframes.clear();
  changes_.upserted_points.clear();
  changes_.hidden_points.clear();
  keyframes_.clear();
  points_.clear();
  feature_index_.clear();
  links_.clear();
}

}  // namespace m2s::slam
