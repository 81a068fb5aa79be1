// LoadScene: stable ids (reloads, OBJ vs PLY, written vs in-memory), node transforms against
// an independent computation and against assimp's own pre-transformation, the load-time
// transform, and a clear error for each kind of bad input.
#include "m2s/common/scene.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <gtest/gtest.h>
#include <assimp/Importer.hpp>

#include "m2s/common/scene_io.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;
const std::string kModels = "/usr/share/assimp/models";

class SceneTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("m2s_scene_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  std::string WriteText(const std::string& name, const std::string& text) const {
    std::ofstream(Path(name), std::ios::binary) << text;
    return Path(name);
  }

  fs::path dir_;
};

void ExpectSameScene(const Scene& a, const Scene& b) {
  ASSERT_EQ(a.positions.size(), b.positions.size());
  for (size_t i = 0; i < a.positions.size(); ++i) {
    ASSERT_EQ(a.positions[i], b.positions[i]) << "vertex " << i;
  }
  EXPECT_EQ(a.triangles, b.triangles);
}

// A cube of 6 quads with each corner listed once per face (24 entries, 8 positions), and a
// pentagon sharing two corners: the same faces in OBJ and in ASCII PLY.
const char* kCubeVertices[] = {"0 0 0", "1 0 0", "1 1 0", "0 1 0",      "0 0 1",
                               "1 0 1", "1 1 1", "0 1 1", "0.5 1.5 0.5"};
const std::vector<std::vector<int>> kCubeFaces = {{0, 3, 2, 1},   {4, 5, 6, 7}, {0, 1, 5, 4},
                                                  {1, 2, 6, 5},   {2, 3, 7, 6}, {3, 0, 4, 7},
                                                  {3, 2, 8, 6, 7}};

std::string CubeObj() {
  std::ostringstream s;
  s << "# cube\n";
  for (const auto& face : kCubeFaces) {
    for (int v : face) s << "v " << kCubeVertices[v] << "\n";
  }
  int next = 1;
  for (const auto& face : kCubeFaces) {
    s << "f";
    for (size_t k = 0; k < face.size(); ++k) s << " " << next++;
    s << "\n";
  }
  return s.str();
}

std::string CubePly() {
  size_t corners = 0;
  for (const auto& face : kCubeFaces) corners += face.size();
  std::ostringstream s;
  s << "ply\nformat ascii 1.0\nelement vertex " << corners
    << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << kCubeFaces.size()
    << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& face : kCubeFaces) {
    for (int v : face) s << kCubeVertices[v] << "\n";
  }
  int next = 0;
  for (const auto& face : kCubeFaces) {
    s << face.size();
    for (size_t k = 0; k < face.size(); ++k) s << " " << next++;
    s << "\n";
  }
  return s.str();
}

TEST_F(SceneTest, ObjAndPlyOfTheSameFacesGiveTheSameIds) {
  const Expected<Scene> obj = LoadScene(WriteText("cube.obj", CubeObj()));
  const Expected<Scene> ply = LoadScene(WriteText("cube.ply", CubePly()));
  ASSERT_TRUE(obj.ok()) << obj.error();
  ASSERT_TRUE(ply.ok()) << ply.error();
  EXPECT_EQ(obj->num_vertices(), 9u);  // 28 corners, 9 distinct positions
  EXPECT_EQ(obj->num_triangles(), 6u * 2 + 3);
  ExpectSameScene(*obj, *ply);
  // Ids in first-use order: the first face's corners are 0, 1, 2, 3.
  EXPECT_EQ(obj->positions[0], Eigen::Vector3f(0, 0, 0));
  EXPECT_EQ(obj->positions[1], Eigen::Vector3f(0, 1, 0));
  EXPECT_EQ(obj->positions[2], Eigen::Vector3f(1, 1, 0));
  EXPECT_EQ(obj->positions[3], Eigen::Vector3f(1, 0, 0));
}

TEST_F(SceneTest, DefaultSceneWrittenAsObjAndPlyReloadsWithIdenticalIds) {
  const Scene scene = MakeDefaultScene();
  ASSERT_TRUE(WriteSceneObj(Path("room.obj"), scene).ok());
  ASSERT_TRUE(WriteScenePly(Path("room.ply"), scene).ok());
  const Expected<Scene> obj = LoadScene(Path("room.obj"));
  const Expected<Scene> ply = LoadScene(Path("room.ply"));
  ASSERT_TRUE(obj.ok()) << obj.error();
  ASSERT_TRUE(ply.ok()) << ply.error();
  ExpectSameScene(*ply, scene);
  ExpectSameScene(*obj, scene);
}

// Thousands of positions, each written three times (one of them as -0 where a coordinate is
// 0), in a binary little-endian PLY: ids follow the rule of scene.h, computed here with a
// std::map over the coordinates' bit patterns.
TEST_F(SceneTest, RepeatedPositionsGetTheIdOfTheirFirstUseInAThousandsOfVertexFile) {
  constexpr int kDistinct = 5000;
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> coordinate(-40, 40);
  std::vector<std::array<float, 3>> distinct;
  std::set<std::array<float, 3>> taken;
  while (static_cast<int>(distinct.size()) < kDistinct) {
    const std::array<float, 3> p = {0.25f * coordinate(rng), 0.25f * coordinate(rng),
                                    0.25f * coordinate(rng)};
    if (taken.insert(p).second) distinct.push_back(p);
  }
  std::vector<std::array<float, 3>> records;  // each distinct position 3 times, shuffled
  for (int copy = 0; copy < 3; ++copy) {
    for (std::array<float, 3> p : distinct) {
      if (copy == 1) {
        for (float& c : p) c = c == 0.f ? -0.f : c;
      }
      records.push_back(p);
    }
  }
  std::shuffle(records.begin(), records.end(), rng);
  std::uniform_int_distribution<int> record(0, static_cast<int>(records.size()) - 1);
  std::vector<std::array<int, 3>> faces(4000);
  for (auto& f : faces) f = {record(rng), record(rng), record(rng)};

  std::ostringstream ply;
  ply << "ply\nformat binary_little_endian 1.0\nelement vertex " << records.size()
      << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << faces.size()
      << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& p : records) ply.write(reinterpret_cast<const char*>(p.data()), 12);
  for (const auto& f : faces) {
    ply.put(3);
    ply.write(reinterpret_cast<const char*>(f.data()), 12);
  }
  const Expected<Scene> scene = LoadScene(WriteText("many.ply", ply.str()));
  ASSERT_TRUE(scene.ok()) << scene.error();

  // The reference: corners in face order, then unused records in file order.
  std::map<std::array<uint32_t, 3>, VertexId> ids;
  std::vector<VertexId> id_of_record(records.size());
  auto assign = [&](int r) {
    std::array<uint32_t, 3> bits;
    for (int k = 0; k < 3; ++k) {
      const float c = records[r][k] == 0.f ? 0.f : records[r][k];
      std::memcpy(&bits[k], &c, 4);
    }
    id_of_record[r] = ids.try_emplace(bits, static_cast<VertexId>(ids.size())).first->second;
  };
  std::vector<uint32_t> triangles;
  for (const auto& f : faces) {
    for (int r : f) assign(r);
    const VertexId a = id_of_record[f[0]], b = id_of_record[f[1]], c = id_of_record[f[2]];
    if (a != b && b != c && a != c) triangles.insert(triangles.end(), {a, b, c});
  }
  for (int r = 0; r < static_cast<int>(records.size()); ++r) assign(r);
  ASSERT_EQ(scene->num_vertices(), static_cast<size_t>(kDistinct));
  for (size_t r = 0; r < records.size(); ++r) {
    const std::array<float, 3>& p = records[r];
    ASSERT_EQ(scene->positions[id_of_record[r]], Eigen::Vector3f(p[0], p[1], p[2])) << r;
  }
  EXPECT_EQ(scene->triangles, triangles);
}

TEST_F(SceneTest, IdsAreStableAcrossReloads) {
  for (const std::string& path :
       {kModels + "/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb",
        kModels + "/FBX/cubes_with_names.fbx", kModels + "/OBJ/spider.obj"}) {
    const Expected<Scene> first = LoadScene(path);
    const Expected<Scene> second = LoadScene(path);
    ASSERT_TRUE(first.ok()) << first.error();
    ASSERT_TRUE(second.ok()) << second.error();
    EXPECT_GT(first->num_vertices(), 0u);
    ExpectSameScene(*first, *second);
  }
}

// A glTF file with a two-level hierarchy, both nodes instancing one triangle.
TEST_F(SceneTest, NodeTransformsAreAccumulatedDepthFirst) {
  const float positions[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const uint16_t indices[4] = {0, 1, 2, 0};
  {
    std::ofstream bin(Path("tri.bin"), std::ios::binary);
    bin.write(reinterpret_cast<const char*>(positions), sizeof(positions));
    bin.write(reinterpret_cast<const char*>(indices), sizeof(indices));
  }
  const std::string gltf = R"({
    "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
    "nodes": [
      {"name": "parent", "translation": [1, 2, 3], "children": [1], "mesh": 0},
      {"name": "child", "translation": [0, 0, 1], "rotation": [0, 0, 0.70710678, 0.70710678],
       "scale": [2, 2, 2], "mesh": 0}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
    "buffers": [{"uri": "tri.bin", "byteLength": 44}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                    {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
    "accessors": [
      {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
       "min": [0, 0, 0], "max": [1, 1, 0]},
      {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}]})";
  const Expected<Scene> scene = LoadScene(WriteText("tree.gltf", gltf));
  ASSERT_TRUE(scene.ok()) << scene.error();
  ASSERT_EQ(scene->num_vertices(), 6u);
  ASSERT_EQ(scene->num_triangles(), 2u);
  const Eigen::Affine3d parent(Eigen::Translation3d(1, 2, 3));
  const Eigen::Affine3d child = parent * Eigen::Translation3d(0, 0, 1) *
                                Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()) *
                                Eigen::Scaling(2.0);
  for (int v = 0; v < 3; ++v) {
    const Eigen::Vector3d p(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]);
    EXPECT_LT((scene->positions[v].cast<double>() - parent * p).norm(), 1e-6) << v;
    EXPECT_LT((scene->positions[3 + v].cast<double>() - child * p).norm(), 1e-6) << v;
  }
}

// Independent reference: assimp's own aiProcess_PreTransformVertices on a real model.
TEST_F(SceneTest, NodeTransformsMatchAssimpPreTransformOnRealModels) {
  for (const std::string& path :
       {kModels + "/FBX/cubes_with_names.fbx",
        kModels + "/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb"}) {
    const Expected<Scene> scene = LoadScene(path);
    ASSERT_TRUE(scene.ok()) << scene.error();
    Assimp::Importer importer;
    const aiScene* ai = importer.ReadFile(path, aiProcess_PreTransformVertices);
    ASSERT_NE(ai, nullptr);
    std::vector<Eigen::Vector3f> reference;
    for (unsigned m = 0; m < ai->mNumMeshes; ++m) {
      for (unsigned v = 0; v < ai->mMeshes[m]->mNumVertices; ++v) {
        const aiVector3D& p = ai->mMeshes[m]->mVertices[v];
        reference.emplace_back(p.x, p.y, p.z);
      }
    }
    // Every reference position is one of ours and vice versa (to float rounding).
    Eigen::AlignedBox3f box;
    for (const auto& p : reference) box.extend(p);
    const float tolerance = 1e-5f * box.diagonal().norm();
    auto key = [&](const Eigen::Vector3f& p) {
      const Eigen::Vector3f q = (p - box.min()) / (4 * tolerance);
      return std::array<long, 3>{std::lround(q.x()), std::lround(q.y()), std::lround(q.z())};
    };
    std::set<std::array<long, 3>> ours, theirs;
    for (const auto& p : scene->positions) ours.insert(key(p));
    for (const auto& p : reference) theirs.insert(key(p));
    size_t missing = 0;
    for (const auto& k : theirs) missing += ours.count(k) == 0;
    for (const auto& k : ours) missing += theirs.count(k) == 0;
    // Cell-boundary rounding may split a few; a wrong transform would miss most.
    EXPECT_LE(missing, theirs.size() / 100) << path;
    // The model really has node transforms: its raw mesh vertices are mostly elsewhere.
    Assimp::Importer raw_importer;
    const aiScene* raw = raw_importer.ReadFile(path, 0);
    ASSERT_NE(raw, nullptr);
    std::set<std::array<long, 3>> untransformed;
    for (unsigned m = 0; m < raw->mNumMeshes; ++m) {
      for (unsigned v = 0; v < raw->mMeshes[m]->mNumVertices; ++v) {
        const aiVector3D& p = raw->mMeshes[m]->mVertices[v];
        untransformed.insert(key(Eigen::Vector3f(p.x, p.y, p.z)));
      }
    }
    size_t moved = 0;
    for (const auto& k : ours) moved += untransformed.count(k) == 0;
    EXPECT_GT(moved, ours.size() / 2) << path;
    EXPECT_GT(scene->num_triangles(), 0u);
  }
}

TEST_F(SceneTest, LoadTransformIsAppliedToEveryVertex) {
  const std::string path = WriteText("cube.obj", CubeObj());
  SceneLoadOptions options;
  options.scale = 2.5;
  options.rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, -2, 0.5).normalized()));
  options.translation = Eigen::Vector3d(-1.0, 4.0, 0.25);
  const Expected<Scene> plain = LoadScene(path);
  const Expected<Scene> moved = LoadScene(path, options);
  ASSERT_TRUE(plain.ok() && moved.ok());
  ASSERT_EQ(plain->num_vertices(), moved->num_vertices());
  EXPECT_EQ(plain->triangles, moved->triangles);
  for (size_t i = 0; i < plain->num_vertices(); ++i) {
    const Eigen::Vector3d expected =
        options.scale * (options.rotation * plain->positions[i].cast<double>()) +
        options.translation;
    EXPECT_LT((moved->positions[i].cast<double>() - expected).norm(), 1e-5) << i;
  }
}

void ExpectError(const Expected<Scene>& scene, const std::string& fragment) {
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.error().find(fragment), std::string::npos) << scene.error();
  EXPECT_EQ(scene.error().find('\n'), std::string::npos) << "one line: " << scene.error();
}

TEST_F(SceneTest, BadInputGivesAClearError) {
  ExpectError(LoadScene(Path("missing.obj")), "no such file");
  ExpectError(LoadScene(dir_.string()), "not a regular file");
  ExpectError(LoadScene(WriteText("empty.obj", "")), "empty file");
  ExpectError(LoadScene(kModels + "/invalid/empty.ply"), "empty file");
  std::string garbage;
  for (int i = 0; i < 4096; ++i) garbage += static_cast<char>((i * 7919 + 13) % 251);
  ExpectError(LoadScene(WriteText("garbage.ply", garbage)), "cannot be parsed");
  ExpectError(LoadScene(WriteText("mesh.xyz123", CubeObj())), "unsupported format '.xyz123'");
  ExpectError(LoadScene(WriteText("comments.obj", "# no geometry at all\n")), "no vertices");
  ExpectError(LoadScene(kModels + "/invalid/malformed.obj"), "cannot be parsed");
  ExpectError(LoadScene(kModels + "/glTF2/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb"),
              "non-finite");
  SceneLoadOptions huge;
  huge.scale = 1e300;  // finite, but the positions overflow float
  ExpectError(LoadScene(WriteText("cube.obj", CubeObj()), huge), "non-finite");
  SceneLoadOptions zero;
  zero.scale = 0.0;
  ExpectError(LoadScene(Path("cube.obj"), zero), "invalid load options");
}

TEST_F(SceneTest, PointCloudsGiveVerticesWithoutTriangles) {
  const Expected<Scene> scene = LoadScene(kModels + "/OBJ/point_cloud.obj");
  ASSERT_TRUE(scene.ok()) << scene.error();
  EXPECT_EQ(scene->num_vertices(), 3u);
  EXPECT_EQ(scene->num_triangles(), 0u);
}

TEST(SceneLoadOptions, Check) {
  Status why;
  EXPECT_TRUE((why = SceneLoadOptions{}.Check()));
  SceneLoadOptions o;
  o.scale = std::nan("");
  EXPECT_FALSE((why = o.Check()));
  EXPECT_NE(why.message().find("scale"), std::string::npos);
  o = {};
  o.rotation = Eigen::Quaterniond(2, 0, 0, 0);
  EXPECT_FALSE((why = o.Check()));
  o = {};
  o.translation.x() = INFINITY;
  EXPECT_FALSE((why = o.Check()));
}

}  // namespace
}  // namespace m2s
