// Composed benchmark scenes: a box room (each wall, the floor and the ceiling one quad of four
// vertices unless subdivided) plus props, each a mesh file of any format assimp reads or a box,
// placed by a transform that fits it to a size, stands it on a point and turns it about z.
// The composition is one Scene (props appended in order, so vertex ids are deterministic), the
// floor plan for the motion generators (room box and prop footprints) and the centres of the
// props marked as targets (what a hand-held camera looks at).
//
//   Expected<std::vector<SceneSpec>> specs = ReadSceneManifest("tools/bench_slam/scenes.json");
//   Expected<ComposedScene> composed = ComposeScene((*specs)[0], "/root/.cache/m2s-corpus");
//   Expected<Trajectory> motion = MakeMotion("handheld", *composed, /*seed=*/1, /*duration=*/30);
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/scene.h"
#include "m2s/common/status.h"
#include "m2s/common/trajectory.h"

namespace m2s::bench {

struct PropSpec {
  std::string name;
  // A mesh file (relative paths are resolved against the mesh root); empty: a box of box_size.
  std::string mesh;
  Eigen::Vector3d box_size = Eigen::Vector3d::Ones();  // x, y, z extent of a box prop (m)
  double size_m = 0.0;  // mesh: scaled so that its largest extent is this (0: keep its scale)
  bool y_up = false;    // the mesh's +y axis is up (OBJ / glTF habit); otherwise +z
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // bottom centre of the placed prop
  double yaw_deg = 0.0;                                // turn about world z
  bool obstacle = true;  // its footprint is an obstacle for the motion generators
  bool target = false;   // its centre is a look-at target for hand-held motion
};

struct SceneSpec {
  std::string name;
  Eigen::Vector3d room_size = Eigen::Vector3d(6.0, 5.0, 2.7);  // centred on x, y; floor z = 0
  int wall_divisions = 1;  // quads along each side of every wall, floor and ceiling
  std::vector<PropSpec> props;
};

struct ComposedScene {
  struct Part {  // vertices [first_vertex, first_vertex + num_vertices) of one room or prop
    std::string name;
    uint32_t first_vertex = 0;
    uint32_t num_vertices = 0;
  };
  Scene scene;
  std::vector<Part> parts;                     // the room, then the props in order
  RoomLayout layout;                           // obstacles: footprints of obstacle props
  std::vector<Eigen::AlignedBox3d> obstacles;  // the same props' bounds (for flying motion)
  std::vector<Eigen::Vector3d> targets;
};

// Builds the scene; fails (naming the prop) when a mesh cannot be loaded or a spec is invalid.
Expected<ComposedScene> ComposeScene(const SceneSpec& spec, const std::string& mesh_root);

// A JSON manifest: {"scenes": [{"name", "room": {"size": [x, y, z], "divisions"}, "props":
// [{"name", "mesh" | "box": [x, y, z], "size", "up": "y" | "z", "position": [x, y, z],
// "yaw_deg", "obstacle", "target"}]}]}. Errors name the file and the field.
Expected<std::vector<SceneSpec>> ReadSceneManifest(const std::string& path);

// The motions of the benchmark, generated in the scene's room around its obstacles:
// "head" (GenerateHeadMotion), "handheld" (looking at the targets) and "drone" (flying over
// obstacles whose top is lower than its lowest altitude less its clearance).
const std::vector<std::string>& MotionKinds();
Expected<Trajectory> MakeMotion(const std::string& kind, const ComposedScene& scene, uint64_t seed,
                                double duration_s);

}  // namespace m2s::bench
