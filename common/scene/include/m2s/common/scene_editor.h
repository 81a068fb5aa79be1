// SceneEditor: parts of a scene added, removed and moved at run time, with ids that users can
// rely on.
//
// Contract (deterministic: the same calls on the same scene give the same ids and positions):
//  - AddPart gives the new part fresh ids after every id ever used in the scene (loaded,
//    added or retired), in the order of its positions, and appends its triangles. Positions
//    are never merged with existing ones, so a part added twice has two sets of ids.
//  - RemovePart retires the ids only that part used: they are never projected again and
//    never reused. Its triangles become zero-area slots (v, v, v), so the other parts'
//    triangle ranges do not shift. An id it shared with another part stays with that part.
//  - MovePart applies a rigid motion x' = motion * x (in double, rounded to float) to the
//    part's vertices and keeps their ids (a door that opens, an object that is carried). A
//    vertex the part shared with another part (LoadScene merged two equal positions) stays
//    where it was with its id, for the other part; the moved part gets a fresh id for it
//    (after every id ever used) and its triangles are re-indexed to it.
//  - Each call returns the SceneChange it made, for the projectors that follow the scene
//    (CpuProjector::ApplyChange) and for the SLAM side (the ids that moved or retired).
// Errors (one line, nothing changed): unknown part, a name already used, an empty part,
// triangle indices out of range, non-finite positions or motion, more than 2^32 - 2 ids.
//
// Memory: nothing per vertex beyond the scene's 12 bytes of position (and 12 bytes per
// triangle); 4 bytes per retired id and per id a part shares with another.
//
// Thread-safety: none; one thread owns the editor and the projectors that follow it, and
// applies each change to them before projecting again.
//
//   SceneEditor editor(*LoadScene("room.glb"));
//   auto projector = CpuProjector::Create(editor.scene(), ProjectorOptions::Occluding());
//   Expected<SceneChange> change = editor.MovePart("root/door", door_motion);
//   if (change) (*projector)->ApplyChange(editor.scene(), *change);
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/geometry.h"
#include "m2s/common/scene.h"
#include "m2s/common/status.h"
#include "m2s/common/types.h"

namespace m2s {

// What one edit changed. Ids [first_new_id, end_new_id) were appended; moved_ids changed
// position (keeping their id); retired_ids were retired; triangles [first_triangle,
// end_triangle) were rewritten or appended. Sorted, disjoint id lists.
struct SceneChange {
  VertexId first_new_id = 0;
  VertexId end_new_id = 0;
  std::vector<VertexId> moved_ids;
  std::vector<VertexId> retired_ids;
  uint32_t first_triangle = 0;
  uint32_t end_triangle = 0;
};

class SceneEditor {
 public:
  // A scene without parts is seen as one part named "scene" holding everything.
  explicit SceneEditor(Scene scene);

  const Scene& scene() const { return scene_; }
  // The live part of that name, or null.
  const ScenePart* FindPart(const std::string& name) const;

  // `positions` in the part's frame, placed by world_from_part; `triangles` index into
  // `positions` (3 per triangle; degenerate ones are dropped).
  Expected<SceneChange> AddPart(const std::string& name,
                                const std::vector<Eigen::Vector3f>& positions,
                                const std::vector<uint32_t>& triangles,
                                const Pose3& world_from_part = Pose3::Identity());
  Expected<SceneChange> RemovePart(const std::string& name);
  // `motion` is applied in the world frame: x' = motion * x.
  Expected<SceneChange> MovePart(const std::string& name, const Pose3& motion);

 private:
  size_t IndexOf(const std::string& name) const;  // parts().size() when absent
  // "no such part", with the first part names.
  std::string UnknownPart(const std::string& name) const;
  // How many live parts use each of `ids` (sorted).
  std::vector<int> UseCounts(const std::vector<VertexId>& ids) const;

  Scene scene_;
};

}  // namespace m2s
