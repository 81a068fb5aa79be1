// LoadRenderMesh: the same positions as LoadScene under a transform, and the materials,
// textures, normals, texture coordinates and vertex colours of generated OBJ files.
#include "m2s/common/render_mesh.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <tuple>

namespace m2s {
namespace {

namespace fs = std::filesystem;

class RenderMeshTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("m2s_render_mesh_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

using Key = std::tuple<float, float, float>;

TEST_F(RenderMeshTest, PositionsAreExactlyTheScenesUnderTheLoadTransform) {
  const std::string path = "/usr/share/assimp/models/OBJ/spider.obj";
  SceneLoadOptions options;
  options.scale = 0.037;
  options.rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()));
  options.translation = Eigen::Vector3d(100.25, -3.5, 1.75);
  auto scene = LoadScene(path, options);
  if (!scene) GTEST_SKIP() << "assimp-testmodels not installed: " << scene.error();
  auto mesh = LoadRenderMesh(path, options);
  ASSERT_TRUE(mesh) << mesh.error();
  std::set<Key> from_scene, from_mesh;
  for (const uint32_t i : scene->triangles) {
    const Eigen::Vector3f& p = scene->positions[i];
    from_scene.insert({p.x(), p.y(), p.z()});
  }
  for (const RenderBatch& batch : mesh->batches) {
    for (const uint32_t i : batch.triangles) {
      const Eigen::Vector3f& p = batch.positions[i];
      from_mesh.insert({p.x(), p.y(), p.z()});
    }
  }
  EXPECT_EQ(from_mesh, from_scene);     // bitwise equal floats
  EXPECT_EQ(mesh->batches.size(), 4u);  // spider.mtl's four textured materials in use
  for (const RenderBatch& batch : mesh->batches) {
    EXPECT_FALSE(batch.texture.path.empty()) << batch.material;
    EXPECT_TRUE(fs::exists(batch.texture.path)) << batch.texture.path;  // '.\x.jpg' resolved
    EXPECT_EQ(batch.uvs.size(), batch.positions.size());
  }
}

TEST_F(RenderMeshTest, KeepsMaterialsTexturesNormalsAndVertexColours) {
  fs::create_directories(dir_ / "tex");
  std::ofstream(dir_ / "m.mtl") << "newmtl red\nKd 0.9 0.1 0.2\n"
                                << "newmtl wood\nKd 1 1 1\nmap_Kd tex/wood.png\n";
  std::ofstream(dir_ / "m.obj") << "mtllib m.mtl\n"
                                << "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\n"
                                << "vt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
                                << "usemtl red\nf 1/1/1 2/2/1 3/3/1\n"
                                << "usemtl wood\nf 1/1/1 3/3/1 2/2/1\n";
  SceneLoadOptions options;  // 90 degrees about x: normal (0, 0, 1) -> (0, -1, 0)
  options.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()));
  options.scale = 2.0;
  auto mesh = LoadRenderMesh((dir_ / "m.obj").string(), options);
  ASSERT_TRUE(mesh) << mesh.error();
  ASSERT_EQ(mesh->batches.size(), 2u);
  EXPECT_EQ(mesh->num_triangles(), 2u);
  for (const RenderBatch& batch : mesh->batches) {
    ASSERT_EQ(batch.positions.size(), 3u) << batch.material;
    ASSERT_EQ(batch.normals.size(), 3u);
    ASSERT_EQ(batch.uvs.size(), 3u);
    ASSERT_EQ(batch.colors.size(), 3u);
    for (const Eigen::Vector3f& n : batch.normals) {
      EXPECT_LT((n - Eigen::Vector3f(0, -1, 0)).norm(), 1e-6) << n.transpose();
    }
    for (size_t k = 0; k < 3; ++k) {
      // Vertex (0, 1, 0) scaled by 2 and turned: (0, 0, 2).
      if (batch.uvs[k] == Eigen::Vector2f(0, 1)) {
        EXPECT_LT((batch.positions[k] - Eigen::Vector3f(0, 0, 2)).norm(), 1e-6);
        EXPECT_EQ(batch.colors[k], Eigen::Vector4f(0, 0, 1, 1));
      }
    }
    if (batch.material == "red") {
      EXPECT_TRUE(batch.texture.empty());
      EXPECT_LT((batch.diffuse - Eigen::Vector3f(0.9f, 0.1f, 0.2f)).norm(), 1e-6);
    } else {
      EXPECT_EQ(batch.material, "wood");
      EXPECT_EQ(fs::path(batch.texture.path), (dir_ / "tex" / "wood.png").lexically_normal());
    }
  }
}

TEST_F(RenderMeshTest, DefaultSceneIsOneUntexturedBatchAndErrorsAreLoadScenes) {
  const Scene scene = MakeDefaultScene();
  const RenderMesh mesh = MakeRenderMesh(scene);
  ASSERT_EQ(mesh.batches.size(), 1u);
  EXPECT_EQ(mesh.batches[0].positions, scene.positions);
  EXPECT_EQ(mesh.batches[0].triangles, scene.triangles);
  EXPECT_TRUE(mesh.batches[0].texture.empty());
  EXPECT_TRUE(mesh.batches[0].normals.empty());

  const std::string missing = (dir_ / "missing.obj").string();
  auto loaded = LoadRenderMesh(missing);
  ASSERT_FALSE(loaded);
  EXPECT_EQ(loaded.error(), LoadScene(missing).error());
}

}  // namespace
}  // namespace m2s
