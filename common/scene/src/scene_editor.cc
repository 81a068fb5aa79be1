// SceneEditor and ScenePart: see scene_editor.h and scene.h.
#include "m2s/common/scene_editor.h"

#include <algorithm>
#include <iterator>
#include <limits>
#include <unordered_map>
#include <utility>

namespace m2s {
namespace {

bool Contains(const std::vector<VertexId>& sorted, VertexId id) {
  return std::binary_search(sorted.begin(), sorted.end(), id);
}

// a, b sorted: the sorted union.
std::vector<VertexId> Merge(const std::vector<VertexId>& a, const std::vector<VertexId>& b) {
  std::vector<VertexId> out;
  out.reserve(a.size() + b.size());
  std::set_union(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(out));
  return out;
}

std::vector<VertexId> Minus(const std::vector<VertexId>& a, const std::vector<VertexId>& b) {
  std::vector<VertexId> out;
  std::set_difference(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(out));
  return out;
}

Eigen::Vector3f Apply(const Pose3& motion, const Eigen::Vector3f& p) {
  return (motion * p.cast<double>()).cast<float>();
}

}  // namespace

bool ScenePart::Uses(VertexId id) const {
  if (id >= first_vertex && id < end_vertex) return !Contains(given_ids, id);
  return Contains(extra_ids, id);
}

std::vector<VertexId> ScenePart::Ids() const {
  std::vector<VertexId> range;
  range.reserve(end_vertex - first_vertex - given_ids.size());
  auto given = given_ids.begin();
  for (VertexId id = first_vertex; id < end_vertex; ++id) {
    if (given != given_ids.end() && *given == id) {
      ++given;
      continue;
    }
    range.push_back(id);
  }
  return Merge(range, extra_ids);
}

SceneEditor::SceneEditor(Scene scene) : scene_(std::move(scene)) {
  if (!scene_.parts.empty()) return;
  ScenePart all;
  all.name = "scene";
  all.num_triangles = static_cast<uint32_t>(scene_.num_triangles());
  all.end_vertex = static_cast<VertexId>(scene_.num_vertices());
  scene_.parts.push_back(std::move(all));
}

std::string SceneEditor::UnknownPart(const std::string& name) const {
  std::string message = "scene part '" + name + "': no such part (parts:";
  for (size_t i = 0; i < scene_.parts.size() && i < 5; ++i)
    message += (i == 0 ? " '" : ", '") + scene_.parts[i].name + "'";
  return message + (scene_.parts.size() > 5 ? ", ...)" : ")");
}

size_t SceneEditor::IndexOf(const std::string& name) const {
  for (size_t i = 0; i < scene_.parts.size(); ++i)
    if (scene_.parts[i].name == name) return i;
  return scene_.parts.size();
}

const ScenePart* SceneEditor::FindPart(const std::string& name) const {
  const size_t i = IndexOf(name);
  return i < scene_.parts.size() ? &scene_.parts[i] : nullptr;
}

Expected<SceneChange> SceneEditor::AddPart(const std::string& name,
                                           const std::vector<Eigen::Vector3f>& positions,
                                           const std::vector<uint32_t>& triangles,
                                           const Pose3& world_from_part) {
  const std::string where = "scene part '" + name + "': ";
  if (name.empty()) return Expected<SceneChange>::Error("scene part: empty name");
  if (FindPart(name) != nullptr) return Expected<SceneChange>::Error(where + "name already used");
  if (positions.empty()) return Expected<SceneChange>::Error(where + "no positions");
  if (!world_from_part.AllFinite()) return Expected<SceneChange>::Error(where + "non-finite pose");
  if (triangles.size() % 3 != 0)
    return Expected<SceneChange>::Error(where + "triangle index count is not a multiple of 3");
  for (uint32_t index : triangles) {
    if (index >= positions.size())
      return Expected<SceneChange>::Error(where + "triangle index out of range");
  }
  const size_t first = scene_.positions.size();
  if (first + positions.size() >= std::numeric_limits<VertexId>::max())
    return Expected<SceneChange>::Error(where + "too many vertices for 32-bit ids");
  std::vector<Eigen::Vector3f> placed;
  placed.reserve(positions.size());
  for (const Eigen::Vector3f& p : positions) {
    placed.push_back(Apply(world_from_part, p));
    if (!placed.back().allFinite())
      return Expected<SceneChange>::Error(where + "non-finite positions");
  }
  ScenePart part;
  part.name = name;
  part.first_triangle = static_cast<uint32_t>(scene_.num_triangles());
  part.first_vertex = static_cast<VertexId>(first);
  part.end_vertex = static_cast<VertexId>(first + positions.size());
  scene_.positions.insert(scene_.positions.end(), placed.begin(), placed.end());
  for (size_t t = 0; t < triangles.size(); t += 3) {
    const uint32_t a = triangles[t], b = triangles[t + 1], c = triangles[t + 2];
    if (a == b || b == c || a == c) continue;
    scene_.triangles.insert(scene_.triangles.end(),
                            {part.first_vertex + a, part.first_vertex + b, part.first_vertex + c});
  }
  part.num_triangles = static_cast<uint32_t>(scene_.num_triangles()) - part.first_triangle;
  SceneChange change;
  change.first_new_id = part.first_vertex;
  change.end_new_id = part.end_vertex;
  change.first_triangle = part.first_triangle;
  change.end_triangle = part.first_triangle + part.num_triangles;
  scene_.parts.push_back(std::move(part));
  return change;
}

std::vector<int> SceneEditor::UseCounts(const std::vector<VertexId>& ids) const {
  std::vector<int> counts(ids.size(), 0);
  for (const ScenePart& part : scene_.parts) {
    for (size_t i = 0; i < ids.size(); ++i) counts[i] += part.Uses(ids[i]) ? 1 : 0;
  }
  return counts;
}

namespace {

// The ids of part `self` that another part also uses: other parts' extra ids inside its range,
// and its own extra ids that another part uses (counts from UseCounts).
std::vector<VertexId> SharedIds(const std::vector<ScenePart>& parts, size_t self,
                                const std::vector<int>& extra_use_counts) {
  const ScenePart& part = parts[self];
  std::vector<VertexId> shared;
  for (size_t q = 0; q < parts.size(); ++q) {
    if (q == self) continue;
    for (VertexId id : parts[q].extra_ids) {
      if (id >= part.first_vertex && id < part.end_vertex && part.Uses(id)) shared.push_back(id);
    }
  }
  for (size_t i = 0; i < part.extra_ids.size(); ++i) {
    if (extra_use_counts[i] > 1) shared.push_back(part.extra_ids[i]);
  }
  std::sort(shared.begin(), shared.end());
  shared.erase(std::unique(shared.begin(), shared.end()), shared.end());
  return shared;
}

}  // namespace

Expected<SceneChange> SceneEditor::RemovePart(const std::string& name) {
  const size_t index = IndexOf(name);
  if (index == scene_.parts.size()) return Expected<SceneChange>::Error(UnknownPart(name));
  const ScenePart& part = scene_.parts[index];
  const std::vector<VertexId> shared = SharedIds(scene_.parts, index, UseCounts(part.extra_ids));
  SceneChange change;
  change.retired_ids = Minus(part.Ids(), shared);
  change.first_triangle = part.first_triangle;
  change.end_triangle = part.first_triangle + part.num_triangles;
  for (size_t t = change.first_triangle; t < change.end_triangle; ++t) {
    scene_.triangles[3 * t + 1] = scene_.triangles[3 * t];
    scene_.triangles[3 * t + 2] = scene_.triangles[3 * t];
  }
  scene_.retired_ids = Merge(scene_.retired_ids, change.retired_ids);
  scene_.parts.erase(scene_.parts.begin() + static_cast<ptrdiff_t>(index));
  return change;
}

Expected<SceneChange> SceneEditor::MovePart(const std::string& name, const Pose3& motion) {
  const std::string where = "scene part '" + name + "': ";
  const size_t index = IndexOf(name);
  if (index == scene_.parts.size()) return Expected<SceneChange>::Error(UnknownPart(name));
  if (!motion.AllFinite()) return Expected<SceneChange>::Error(where + "non-finite motion");
  ScenePart& part = scene_.parts[index];
  const std::vector<VertexId> shared = SharedIds(scene_.parts, index, UseCounts(part.extra_ids));
  if (scene_.positions.size() + shared.size() >= std::numeric_limits<VertexId>::max())
    return Expected<SceneChange>::Error(where + "too many vertices for 32-bit ids");
  for (VertexId id : part.Ids()) {
    if (!Apply(motion, scene_.positions[id]).allFinite())
      return Expected<SceneChange>::Error(where + "the motion gives non-finite positions");
  }
  SceneChange change;
  change.first_new_id = static_cast<VertexId>(scene_.positions.size());
  // Shared vertices stay for the other parts; this part gets fresh ids at the moved places.
  std::unordered_map<VertexId, VertexId> fresh;
  std::vector<VertexId> given, fresh_ids;
  for (VertexId id : shared) {
    const auto new_id = static_cast<VertexId>(scene_.positions.size());
    scene_.positions.push_back(Apply(motion, scene_.positions[id]));
    fresh.emplace(id, new_id);
    fresh_ids.push_back(new_id);
    if (id >= part.first_vertex && id < part.end_vertex) given.push_back(id);
  }
  change.end_new_id = static_cast<VertexId>(scene_.positions.size());
  part.given_ids = Merge(part.given_ids, given);
  part.extra_ids = Merge(Minus(part.extra_ids, shared), fresh_ids);
  change.first_triangle = part.first_triangle;
  change.end_triangle = part.first_triangle + part.num_triangles;
  if (!fresh.empty()) {
    for (size_t i = 3 * size_t{change.first_triangle}; i < 3 * size_t{change.end_triangle}; ++i) {
      if (auto it = fresh.find(scene_.triangles[i]); it != fresh.end())
        scene_.triangles[i] = it->second;
    }
  }
  change.moved_ids = Minus(part.Ids(), fresh_ids);
  for (VertexId id : change.moved_ids) scene_.positions[id] = Apply(motion, scene_.positions[id]);
  return change;
}

}  // namespace m2s
