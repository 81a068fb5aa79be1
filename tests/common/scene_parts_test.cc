// Scene parts (one per node-graph instance, ids exactly LoadScene's) and run-time edits
// (SceneEditor) followed by the CPU projector, against a naive projection written here.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/cpu_projector.h"
#include "m2s/common/scene.h"
#include "m2s/common/scene_editor.h"
#include "m2s/common/scene_events.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;

// A unit quad in its own frame (z = 0), corners in the order its two triangles first use them.
const std::vector<Eigen::Vector3f> kQuad = {
    {-0.5f, -0.5f, 0.f}, {0.5f, -0.5f, 0.f}, {0.5f, 0.5f, 0.f}, {-0.5f, 0.5f, 0.f}};
const std::vector<uint32_t> kQuadTriangles = {0, 1, 2, 0, 2, 3};

// A glTF 2.0 file whose one mesh (the quad) is instanced by four nodes:
//   world
//   |- a   at (0, 0, 4)
//   |- b   at (1.2, 0, 4)
//   |- c   at (0, 1.2, 0)
//   |  `- d at (0, 0, 4)   (world (0, 1.2, 4))
//   `- e   at (0, 0, 4)    (exactly where a is)
fs::path WriteInstancedGltf(const fs::path& dir) {
  fs::create_directories(dir);
  {
    std::ofstream bin(dir / "quad.bin", std::ios::binary);
    for (const Eigen::Vector3f& p : kQuad) bin.write(reinterpret_cast<const char*>(p.data()), 12);
    for (uint32_t i : kQuadTriangles) {
      const auto index = static_cast<uint16_t>(i);
      bin.write(reinterpret_cast<const char*>(&index), 2);
    }
  }
  std::ofstream gltf(dir / "instances.gltf");
  gltf << R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
  "nodes": [
    {"name": "world", "children": [1, 2, 3, 5]},
    {"name": "a", "mesh": 0, "translation": [0, 0, 4]},
    {"name": "b", "mesh": 0, "translation": [1.2, 0, 4]},
    {"name": "c", "children": [4], "translation": [0, 1.2, 0]},
    {"name": "d", "mesh": 0, "translation": [0, 0, 4]},
    {"name": "e", "mesh": 0, "translation": [0, 0, 4]}],
  "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
  "buffers": [{"uri": "quad.bin", "byteLength": 60}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                  {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
  "accessors": [
    {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
     "min": [-0.5, -0.5, 0], "max": [0.5, 0.5, 0]},
    {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}]})";
  return dir / "instances.gltf";
}

fs::path TempDir(const std::string& name) {
  return fs::temp_directory_path() / ("m2s_scene_parts_" + std::to_string(::getpid())) / name;
}

class ScenePartsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    SceneLoadOptions options;
    options.use_cache = false;
    auto scene = LoadScene(WriteInstancedGltf(TempDir("gltf")).string(), options);
    ASSERT_TRUE(scene.ok()) << scene.error();
    scene_ = std::move(*scene);
  }
  static void TearDownTestSuite() { fs::remove_all(TempDir("").parent_path()); }
  Scene scene_;
};

TEST_F(ScenePartsTest, EachInstanceIsAPartWithLoadSceneIds) {
  // LoadScene's order: depth first (a, b, c/d, e), corners in triangle order, equal positions
  // merged. So a: ids 0-3, b: 4-7, d: 8-11, and e (exactly on a) reuses a's ids.
  const Eigen::Vector3f origins[] = {{0, 0, 4}, {1.2f, 0, 4}, {0, 1.2f, 4}};
  ASSERT_EQ(scene_.num_vertices(), 12u);
  for (int part = 0; part < 3; ++part) {
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3f expected = kQuad[k] + origins[part];
      EXPECT_LT((scene_.positions[4 * part + k] - expected).norm(), 1e-6f) << part << " " << k;
    }
  }
  ASSERT_EQ(scene_.parts.size(), 4u);
  const char* names[] = {"world/a", "world/b", "world/c/d", "world/e"};
  for (size_t i = 0; i < 4; ++i) EXPECT_EQ(scene_.parts[i].name, names[i]);
  for (int i = 0; i < 3; ++i) {
    const ScenePart& part = scene_.parts[i];
    EXPECT_EQ(part.first_vertex, static_cast<VertexId>(4 * i));
    EXPECT_EQ(part.end_vertex, static_cast<VertexId>(4 * i + 4));
    EXPECT_TRUE(part.extra_ids.empty());
    EXPECT_EQ(part.first_triangle, static_cast<uint32_t>(2 * i));
    EXPECT_EQ(part.num_triangles, 2u);
  }
  const ScenePart& e = scene_.parts[3];
  EXPECT_EQ(e.first_vertex, e.end_vertex);
  EXPECT_EQ(e.extra_ids, (std::vector<VertexId>{0, 1, 2, 3}));
  EXPECT_EQ(e.Ids(), (std::vector<VertexId>{0, 1, 2, 3}));
  ASSERT_EQ(scene_.num_triangles(), 8u);
  // Every part's triangles use only its own ids.
  for (const ScenePart& part : scene_.parts) {
    for (uint32_t t = part.first_triangle; t < part.first_triangle + part.num_triangles; ++t) {
      for (int c = 0; c < 3; ++c) EXPECT_TRUE(part.Uses(scene_.triangles[3 * t + c])) << part.name;
    }
  }
}

TEST_F(ScenePartsTest, TheCacheKeepsTheParts) {
  SceneLoadOptions options;
  options.cache_dir = TempDir("cache").string();
  options.cache_min_bytes = 0;
  const std::string path = (TempDir("gltf") / "instances.gltf").string();
  ASSERT_TRUE(LoadScene(path, options).ok());  // parses and writes the entry
  auto cached = LoadScene(path, options);
  ASSERT_TRUE(cached.ok()) << cached.error();
  ASSERT_EQ(cached->parts.size(), scene_.parts.size());
  for (size_t i = 0; i < scene_.parts.size(); ++i) {
    EXPECT_EQ(cached->parts[i].name, scene_.parts[i].name);
    EXPECT_EQ(cached->parts[i].Ids(), scene_.parts[i].Ids());
    EXPECT_EQ(cached->parts[i].first_triangle, scene_.parts[i].first_triangle);
  }
}

TEST(SceneParts, TheDefaultSceneIsOnePart) {
  const Scene scene = MakeDefaultScene();
  ASSERT_EQ(scene.parts.size(), 1u);
  EXPECT_EQ(scene.parts[0].Ids().size(), scene.num_vertices());
  EXPECT_EQ(scene.parts[0].num_triangles, scene.num_triangles());
}

// The naive reference: every live vertex with near <= Z <= far inside the image, in double.
std::map<VertexId, Eigen::Vector2d> NaiveProject(const Scene& scene, const Pose3& world_from_camera,
                                                 const Camera& camera) {
  std::map<VertexId, Eigen::Vector2d> out;
  const std::set<VertexId> retired(scene.retired_ids.begin(), scene.retired_ids.end());
  const Pose3 camera_from_world = world_from_camera.Inverse();
  for (size_t id = 0; id < scene.num_vertices(); ++id) {
    if (retired.count(static_cast<VertexId>(id))) continue;
    const Eigen::Vector3d q = camera_from_world * scene.positions[id].cast<double>();
    if (q.z() < camera.near || q.z() > camera.far) continue;
    const Eigen::Vector2d uv = camera.Project(q);
    if (camera.InImage(uv.x(), uv.y())) out[static_cast<VertexId>(id)] = uv;
  }
  return out;
}

std::vector<Pose3> Views() {
  std::vector<Pose3> views;
  for (double x : {-0.3, 0.0, 0.4}) {
    const Eigen::Quaterniond turn(Eigen::AngleAxisd(0.1 * x, Eigen::Vector3d::UnitY()));
    views.emplace_back(turn, Eigen::Vector3d(x, 0.1, -0.5));
  }
  return views;
}

// The projector that followed the edits equals the naive projection of the edited scene
// (without occlusion) and a projector made afresh from it (with occlusion, bit for bit).
void ExpectFollows(const SceneEditor& editor, CpuProjector& plain, CpuProjector& occluding) {
  const Camera camera;
  std::vector<ProjectedVertex> got;
  for (const Pose3& view : Views()) {
    ASSERT_TRUE(plain.Project(view, camera, &got).ok());
    const auto expected = NaiveProject(editor.scene(), view, camera);
    ASSERT_EQ(got.size(), expected.size());
    for (const ProjectedVertex& v : got) {
      auto it = expected.find(v.id);
      ASSERT_NE(it, expected.end()) << "vertex " << v.id << " should not be seen";
      EXPECT_NEAR(v.u, it->second.x(), 1e-3);
      EXPECT_NEAR(v.v, it->second.y(), 1e-3);
    }
    auto fresh = CpuProjector::Create(editor.scene(), ProjectorOptions::Occluding());
    ASSERT_TRUE(fresh.ok()) << fresh.error();
    std::vector<ProjectedVertex> reference;
    ASSERT_TRUE((*fresh)->Project(view, camera, &reference).ok());
    ASSERT_TRUE(occluding.Project(view, camera, &got).ok());
    ASSERT_EQ(got.size(), reference.size());
    for (size_t i = 0; i < got.size(); ++i) {
      EXPECT_EQ(got[i].id, reference[i].id);
      EXPECT_EQ(got[i].u, reference[i].u);
      EXPECT_EQ(got[i].depth, reference[i].depth);
    }
  }
}

TEST_F(ScenePartsTest, EditsAreFollowedByTheProjector) {
  SceneEditor editor(scene_);
  ProjectorOptions plain_options;
  plain_options.num_threads = 1;
  ProjectorOptions occluding_options = ProjectorOptions::Occluding();
  occluding_options.num_threads = 1;
  auto plain = CpuProjector::Create(editor.scene(), plain_options);
  auto occluding = CpuProjector::Create(editor.scene(), occluding_options);
  ASSERT_TRUE(plain.ok() && occluding.ok());
  auto apply = [&](const Expected<SceneChange>& change) {
    ASSERT_TRUE(change.ok()) << change.error();
    ASSERT_TRUE((*plain)->ApplyChange(editor.scene(), *change).ok());
    ASSERT_TRUE((*occluding)->ApplyChange(editor.scene(), *change).ok());
    ExpectFollows(editor, **plain, **occluding);
  };
  ExpectFollows(editor, **plain, **occluding);

  // e shares all its vertices with a: moving e leaves a's ids where they were and gives e
  // fresh ids 12-15 (after every id used), in place 0.5 m nearer the camera.
  const Pose3 nearer(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, -0.5));
  apply(editor.MovePart("world/e", nearer));
  EXPECT_EQ(editor.FindPart("world/e")->Ids(), (std::vector<VertexId>{12, 13, 14, 15}));
  EXPECT_EQ(editor.FindPart("world/a")->Ids(), (std::vector<VertexId>{0, 1, 2, 3}));
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(editor.scene().positions[k], scene_.positions[k]);
    EXPECT_LT(
        (editor.scene().positions[12 + k] - (scene_.positions[k] + Eigen::Vector3f(0, 0, -0.5f)))
            .norm(),
        1e-6f);
  }

  // b turns about its own centre and moves in front of a: its ids are kept.
  const Eigen::Vector3d b_centre(1.2, 0, 4);
  const Eigen::Quaterniond quarter(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()));
  const Pose3 turn_b(quarter, b_centre - quarter * b_centre + Eigen::Vector3d(-1.2, 0, -2));
  apply(editor.MovePart("world/b", turn_b));
  EXPECT_EQ(editor.FindPart("world/b")->Ids(), (std::vector<VertexId>{4, 5, 6, 7}));
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d expected = turn_b * scene_.positions[4 + k].cast<double>();
    EXPECT_LT((editor.scene().positions[4 + k].cast<double>() - expected).norm(), 1e-6);
  }

  // Removing d retires its ids; an added part gets ids after every id ever used.
  auto removed = editor.RemovePart("world/c/d");
  ASSERT_TRUE(removed.ok());
  EXPECT_EQ(removed->retired_ids, (std::vector<VertexId>{8, 9, 10, 11}));
  apply(removed);
  EXPECT_EQ(editor.FindPart("world/c/d"), nullptr);
  const Pose3 placed(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-1.2, 0, 3));
  auto added = editor.AddPart("crate", kQuad, kQuadTriangles, placed);
  ASSERT_TRUE(added.ok());
  EXPECT_EQ(added->first_new_id, 16u);
  EXPECT_EQ(added->end_new_id, 20u);
  apply(added);
  // Re-adding a removed name is a new part with new ids; the retired ids stay retired.
  apply(editor.AddPart("world/c/d", kQuad, kQuadTriangles, placed * nearer));
  EXPECT_EQ(editor.FindPart("world/c/d")->Ids(), (std::vector<VertexId>{20, 21, 22, 23}));
  apply(editor.RemovePart("world/a"));  // a no longer shares with e: all retired
  EXPECT_EQ(editor.scene().retired_ids, (std::vector<VertexId>{0, 1, 2, 3, 8, 9, 10, 11}));

  EXPECT_FALSE(editor.MovePart("nothing", nearer).ok());
  EXPECT_FALSE(editor.AddPart("crate", kQuad, kQuadTriangles).ok());
  EXPECT_FALSE(editor.AddPart("bad", kQuad, {0, 1, 7}).ok());
  EXPECT_FALSE((*plain)->ApplyChange(scene_, *added).ok());  // not the projector's scene
}

TEST(SceneEvents, ParsesTheDocumentedLines) {
  auto events = ParseSceneEvents(
      "# a comment\n"
      "\n"
      "1.5 move world/b 0.3 0 0\n"
      "2 move world/b 0 0 0 0 0 0 1   # a half turn about z\n"
      "2 add copy world/b 0 1 0\n"
      "3.25 remove world/a\n");
  ASSERT_TRUE(events.ok()) << events.error();
  ASSERT_EQ(events->size(), 4u);
  const std::vector<SceneEvent>& e = *events;
  EXPECT_EQ(e[0].time_s, 1.5);
  EXPECT_EQ(e[0].action, SceneEvent::Action::kMove);
  EXPECT_EQ(e[0].part, "world/b");
  EXPECT_EQ(e[0].motion.translation(), Eigen::Vector3d(0.3, 0, 0));
  EXPECT_NEAR(std::abs(e[1].motion.rotation().z()), 1.0, 1e-12);
  EXPECT_EQ(e[2].action, SceneEvent::Action::kAdd);
  EXPECT_EQ(e[2].part, "copy");
  EXPECT_EQ(e[2].source, "world/b");
  EXPECT_EQ(e[3].action, SceneEvent::Action::kRemove);
  EXPECT_EQ(e[3].time_s, 3.25);
  for (const char* bad :
       {"1 jump world/b", "1 move world/b 0 0", "2 remove a\n1 remove b", "1 move a 0 0 0 0 0 0 0",
        "1 remove a extra", "x remove a", "1 move a 0 0 nan"}) {
    EXPECT_FALSE(ParseSceneEvents(bad).ok()) << bad;
  }
}

TEST_F(ScenePartsTest, AnAddEventCopiesALivePart) {
  SceneEditor editor(scene_);
  auto events = ParseSceneEvents("0 add copy world/b 0 1 0\n0 add again nothing 0 0 0\n");
  ASSERT_TRUE(events.ok()) << events.error();
  auto added = ApplySceneEvent((*events)[0], &editor);
  ASSERT_TRUE(added.ok()) << added.error();
  const ScenePart* copy = editor.FindPart("copy");
  ASSERT_NE(copy, nullptr);
  EXPECT_EQ(copy->Ids(), (std::vector<VertexId>{12, 13, 14, 15}));
  EXPECT_EQ(copy->num_triangles, 2u);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(editor.scene().positions[12 + k], scene_.positions[4 + k] + Eigen::Vector3f(0, 1, 0));
  }
  auto missing = ApplySceneEvent((*events)[1], &editor);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("world/b"), std::string::npos);  // names the parts
}

}  // namespace
}  // namespace m2s
