// A scene: triangle meshes flattened into one vertex array with stable ids.
//
// Every distinct 3-D position has exactly one VertexId, dense from 0. Ids are assigned in a
// documented, deterministic order (see LoadScene) so the same file gives the same ids on every
// run and machine. Triangles index into `positions` and are kept for rendering and occlusion.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "m2s/common/status.h"
#include "m2s/common/types.h"

namespace m2s {

struct Scene {
  std::string name;
  std::vector<Eigen::Vector3f> positions;  // world coordinates (metres); index == VertexId
  std::vector<uint32_t> triangles;         // 3 indices per triangle into positions

  size_t num_vertices() const { return positions.size(); }
  size_t num_triangles() const { return triangles.size() / 3; }
};

// Transform applied to every vertex on load: x' = scale * rotation * x + translation.
struct SceneLoadOptions {
  double scale = 1.0;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  bool Check(std::string* why) const;
};

// Loads any format assimp reads (OBJ, PLY, glTF, FBX, 3DS, IFC...). The node hierarchy is
// flattened with node transforms; all meshes of the scene are used. Returns a clear error for
// a missing, unreadable, unsupported or vertex-less file.
Expected<Scene> LoadScene(const std::string& path, const SceneLoadOptions& options = {});

// The embedded default scene: a procedurally built furnished room (see default_scene.cc).
Scene MakeDefaultScene();

}  // namespace m2s
