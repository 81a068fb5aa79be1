// A scene: triangle meshes flattened into one vertex array with stable ids.
//
// Every distinct 3-D position has exactly one VertexId, dense from 0. Ids are assigned in a
// documented, deterministic order (see LoadScene) so the same file gives the same ids on every
// run and machine. Triangles index into `positions` and are kept for rendering and occlusion.
// The scene keeps its parts (one per mesh instance of the file's node graph); SceneEditor
// (scene_editor.h) adds, removes and moves parts at run time.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "m2s/common/status.h"
#include "m2s/common/types.h"

namespace m2s {

// One part of a scene: a mesh placed by one node of the file's graph (a mesh instanced by
// three nodes gives three parts, each with its own ids), or a part added at run time.
// Its vertices are the ids [first_vertex, end_vertex) it introduced, less `given_ids`, plus
// `extra_ids`; its triangles are triangles [first_triangle, first_triangle + num_triangles)
// of Scene::triangles. Ids are implicit (a range), so a part costs no memory per vertex
// except for the few ids it shares with another part (4 bytes each).
struct ScenePart {
  // The node path from the root, names joined by '/', then "#k" for the k-th mesh of a node
  // with several meshes; "~2", "~3"... when the path is already taken. Unique in a scene.
  std::string name;
  uint32_t first_triangle = 0;
  uint32_t num_triangles = 0;
  VertexId first_vertex = 0;
  VertexId end_vertex = 0;
  // Sorted. Ids outside the range the part uses: corners at exactly the position of a vertex
  // an earlier part introduced (LoadScene merges them), or ids given to it when it moved.
  std::vector<VertexId> extra_ids;
  // Sorted. Ids of the range it no longer uses (it moved away from a vertex it shared).
  std::vector<VertexId> given_ids;

  bool Uses(VertexId id) const;
  // Every id of the part, ascending.
  std::vector<VertexId> Ids() const;
};

struct Scene {
  std::string name;
  std::vector<Eigen::Vector3f> positions;  // world coordinates (metres); index == VertexId
  std::vector<uint32_t> triangles;         // 3 indices per triangle into positions
  // The parts in id order (LoadScene: the node graph's instances; MakeDefaultScene: one part
  // "room"). A scene built by hand may leave it empty (SceneEditor then sees one part "scene").
  std::vector<ScenePart> parts;
  // Sorted ids of removed parts' vertices: never projected again, never reused. Their
  // positions stay in `positions` (index == id) with no triangle using them.
  std::vector<VertexId> retired_ids;

  size_t num_vertices() const { return positions.size(); }
  size_t num_triangles() const { return triangles.size() / 3; }
};

// Transform applied to every vertex on load: x' = scale * rotation * x + translation.
struct SceneLoadOptions {
  double scale = 1.0;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  // Binary cache of loaded scenes: a file of at least cache_min_bytes is parsed once; later
  // loads of the same content with the same transform read the cached positions, ids and
  // triangles (exactly what parsing gives: the cache is an accelerator, never another
  // numbering), bound by the disk. Entries are keyed by a 64-bit hash of the file's bytes and
  // this transform; a damaged or stale entry is ignored and rewritten. The folder: cache_dir,
  // else $M2S_CACHE_DIR, else $XDG_CACHE_HOME/mesh2slam, else ~/.cache/mesh2slam.
  bool use_cache = true;
  std::string cache_dir;
  uint64_t cache_min_bytes = uint64_t{16} << 20;  // smaller files parse in well under a second

  Status Check() const;
};

// Loads any format assimp reads (through the cache above when the file is large enough) (OBJ, PLY,
// glTF, FBX, 3DS, IFC...). Only aiProcess_Triangulate is applied (no post-process step that
// reorders or joins vertices).
//
// Id order, stable across runs, machines and formats that keep face order (OBJ and PLY of the
// same mesh give the same ids):
//  1. Nodes are visited depth-first from the root, children in file order; each node's
//     transform is the product of its ancestors' transforms and its own.
//  2. In each node, its meshes in order; in each mesh, its faces in order and each face's
//     corners in order, then the mesh vertices no face uses, in vertex order.
//  3. Each position is transformed (node transform in float as assimp stores it, then the
//     SceneLoadOptions transform in double, rounded to float). A transformed position that
//     equals (exactly, -0 == +0) one seen before gets that earlier id; otherwise the next id.
// Triangles are the triangulated faces in the same order, re-indexed to ids; degenerate ones
// (two corners with the same id) are dropped. Point and line primitives give vertices only.
// Parts: one per (node, mesh) visit of step 1-2, in that order, with the triangles and the new
// ids of that visit (consecutive) and, as extra_ids, the earlier ids its corners merged into.
// Errors (one line, naming the file): missing, unreadable or empty file, unsupported format,
// no vertices, non-finite positions, invalid options.
Expected<Scene> LoadScene(const std::string& path, const SceneLoadOptions& options = {});

// The embedded default scene: a procedurally built furnished room, about 6 m x 5 m x 2.7 m,
// with tens of thousands of vertices at varied density (dense wall panels, sparse floor).
// World frame z up, floor at z = 0, room centred on the origin in x and y. Deterministic.
Scene MakeDefaultScene();

// The scene in `path`, or the default scene when `path` is empty (what the tools and apps do
// with an optional --mesh flag).
Expected<Scene> LoadSceneOrDefault(const std::string& path);

// The floor plan of MakeDefaultScene(), for trajectory generators: the room box and the (x, y)
// footprints of its furniture.
struct RoomLayout {
  Eigen::AlignedBox3d room;
  std::vector<Eigen::AlignedBox2d> obstacles;
};
RoomLayout DefaultRoomLayout();

}  // namespace m2s
