// GpuProjector against the CPU projector and an independent double-precision reference.
#include "m2s/gpu/gpu_projector.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "gpu_test_util.h"
#include "m2s/common/cpu_projector.h"

namespace m2s {
namespace {

using testing::ExpectSameFeatures;
using testing::LookAt;
using testing::ReferenceFeatures;
using testing::SharedContext;

class GpuProjectorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    M2S_SKIP_WITHOUT_EGL();
    context_ = SharedContext();
    ASSERT_NE(context_, nullptr) << GlContext::CreateHeadless().error();
  }

  // Projects with the GPU, the CPU and the double reference and compares all three.
  void CompareAll(const Scene& scene, const std::vector<Pose3>& poses, const Camera& camera) {
    auto gpu = GpuProjector::Create(scene, ProjectorOptions{}, context_);
    ASSERT_TRUE(gpu) << gpu.error();
    auto cpu = CpuProjector::Create(scene, ProjectorOptions{});
    ASSERT_TRUE(cpu) << cpu.error();
    std::vector<ProjectedVertex> gpu_out, cpu_out;
    for (size_t i = 0; i < poses.size(); ++i) {
      SCOPED_TRACE("pose " + std::to_string(i));
      ASSERT_TRUE((*gpu)->Project(poses[i], camera, &gpu_out));
      ASSERT_TRUE((*cpu)->Project(poses[i], camera, &cpu_out));
      EXPECT_FALSE(gpu_out.empty());
      ExpectSameFeatures(gpu_out, cpu_out, scene, poses[i], camera);
      ExpectSameFeatures(gpu_out, ReferenceFeatures(scene, poses[i], camera), scene, poses[i],
                         camera);
    }
  }

  GlContext* context_ = nullptr;
};

TEST_F(GpuProjectorTest, ExactCasesOnBorderBehindAndBeyondFar) {
  // fx = cx = 320, near and far exact in float: these vertices land exactly on the limits.
  Camera camera;
  camera.width = 640;
  camera.height = 480;
  camera.fx = camera.fy = 320;
  camera.cx = 320;
  camera.cy = 240;
  camera.near = 0.125;
  camera.far = 8.0;
  Scene scene;
  scene.positions = {
      {0, 0, 1},            // 0: centre, visible
      {-1, 0, 1},           // 1: u == 0 exactly: visible
      {1, 0, 1},            // 2: u == width exactly: outside
      {0, -0.75, 1},        // 3: v == 0 exactly: visible
      {0, 0.75, 1},         // 4: v == height: outside
      {0, 0, -1},           // 5: behind the camera
      {0.5, 0.5, -2},       // 6: behind, would project inside if the sign were dropped
      {0, 0, 8},            // 7: Z == far: visible
      {0, 0, 8.001f},       // 8: beyond far
      {0, 0, 0.125f},       // 9: Z == near: visible
      {0, 0, 0.124f},       // 10: nearer than near
      {0, 0, 0},            // 11: at the camera centre
      {-0.999f, 0.74f, 1},  // 12: just inside the bottom-left corner
  };
  auto gpu = GpuProjector::Create(scene, ProjectorOptions{}, context_);
  ASSERT_TRUE(gpu) << gpu.error();
  std::vector<ProjectedVertex> out;
  ASSERT_TRUE((*gpu)->Project(Pose3::Identity(), camera, &out));
  auto by_id = testing::ById(out);
  std::set<VertexId> ids;
  for (const auto& [id, f] : by_id) ids.insert(id);
  EXPECT_EQ(ids, (std::set<VertexId>{0, 1, 3, 7, 9, 12}));
  EXPECT_EQ(by_id[1].u, 0.f);
  EXPECT_EQ(by_id[3].v, 0.f);
  EXPECT_FLOAT_EQ(by_id[0].u, 320.f);
  EXPECT_FLOAT_EQ(by_id[0].v, 240.f);
  EXPECT_EQ(by_id[7].depth, 8.f);
  EXPECT_EQ(by_id[9].depth, 0.125f);

  // The same points seen from a translated and rotated camera far from the origin, where a
  // naive float evaluation would lose the sub-pixel precision.
  const Pose3 offset(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(1000.25, -2000.5, 300.125));
  Scene moved = scene;
  for (auto& p : moved.positions) p = (offset * p.cast<double>()).cast<float>();
  auto gpu_moved = GpuProjector::Create(moved, ProjectorOptions{}, context_);
  ASSERT_TRUE(gpu_moved) << gpu_moved.error();
  ASSERT_TRUE((*gpu_moved)->Project(offset, camera, &out));
  ExpectSameFeatures(out, ReferenceFeatures(moved, offset, camera), moved, offset, camera);
}

TEST_F(GpuProjectorTest, DefaultSceneMatchesCpuAndReference) {
  const Scene scene = MakeDefaultScene();
  ASSERT_GT(scene.num_vertices(), 1000u);
  Camera camera = Camera::FromHorizontalFov(640, 480, 90.0, 0.05, 4.0);  // far cuts the room
  std::vector<Pose3> poses;
  const Eigen::Vector3d eye(0.3, -0.2, 1.6);
  for (int k = 0; k < 8; ++k) {
    const double a = k * M_PI / 4;
    poses.push_back(LookAt(eye, eye + Eigen::Vector3d(std::cos(a), std::sin(a), -0.3 + 0.1 * k)));
  }
  poses.push_back(LookAt({-2.5, -2.0, 2.4}, {2.5, 2.0, 0.2}));  // corner: room diagonal > far
  poses.push_back(LookAt({0, 0, 1.2}, {0, 0, 0}, Eigen::Vector3d::UnitX()));  // floor
  CompareAll(scene, poses, camera);
}

TEST_F(GpuProjectorTest, RealMeshMatchesCpuAndReference) {
  const std::string path = "/usr/share/assimp/models/OBJ/spider.obj";
  auto scene = LoadScene(path);
  if (!scene) GTEST_SKIP() << "assimp-testmodels not installed: " << scene.error();
  ASSERT_GT(scene->num_vertices(), 500u);
  Eigen::AlignedBox3f box;
  for (const auto& p : scene->positions) box.extend(p);
  const Eigen::Vector3d centre = box.center().cast<double>();
  const double radius = 0.5 * box.diagonal().norm();
  Camera camera = Camera::FromHorizontalFov(800, 600, 70.0, 0.01 * radius, 2.2 * radius);
  std::vector<Pose3> poses;
  for (int k = 0; k < 6; ++k) {
    const double a = 0.9 * k;
    const Eigen::Vector3d dir(std::cos(a), std::sin(a), 0.4 * std::sin(2 * a));
    // Far enough to see it whole, near enough for the far plane to cut the back,
    // and inside the mesh (vertices behind the camera).
    const double distance = (k % 3 == 0)   ? 2.0 * radius
                            : (k % 3 == 1) ? 1.2 * radius
                                           : 0.2 * radius;
    poses.push_back(LookAt(centre + distance * dir.normalized(), centre, Eigen::Vector3d::UnitY()));
  }
  CompareAll(*scene, poses, camera);
}

// A 6 x 6 district of patches 4 m apart, each a 64 x 64 vertex grid of 1 m (4096 vertices: one
// cull group). Views along a row see a few patches: only their groups are dispatched, and the
// features are the reference's; a view of the sky dispatches nothing and finds nothing.
TEST_F(GpuProjectorTest, CulledGroupsChangeNothing) {
  Scene scene;
  for (int px = 0; px < 6; ++px) {
    for (int py = 0; py < 6; ++py) {
      for (int i = 0; i < 64; ++i) {
        for (int j = 0; j < 64; ++j) {
          scene.positions.emplace_back(4.0f * px + i / 63.0f, 4.0f * py + j / 63.0f,
                                       0.3f * static_cast<float>((i + j) % 5));
        }
      }
    }
  }
  const Camera camera = Camera::FromHorizontalFov(640, 480, 60.0, 0.05, 10.0);
  auto gpu = GpuProjector::Create(scene, ProjectorOptions{}, context_);
  ASSERT_TRUE(gpu) << gpu.error();
  std::vector<ProjectedVertex> out;
  // Along the first row; up the gap between two columns; down onto one patch.
  const std::vector<Pose3> poses = {
      LookAt({-3, 0.5, 1.5}, {21, 0.5, 0}), LookAt({10.5, -2, 0.5}, {10.5, 20, 0.5}),
      LookAt({12.5, 12.5, 3}, {12.5, 12.5, 0}, Eigen::Vector3d::UnitY())};
  for (size_t k = 0; k < poses.size(); ++k) {
    SCOPED_TRACE("pose " + std::to_string(k));
    ASSERT_TRUE((*gpu)->Project(poses[k], camera, &out));
    EXPECT_GT((*gpu)->last_vertices_considered(), 0u);
    EXPECT_LT((*gpu)->last_vertices_considered(), scene.num_vertices() / 2);
    const std::vector<ProjectedVertex> reference = ReferenceFeatures(scene, poses[k], camera);
    ASSERT_FALSE(reference.empty());
    EXPECT_EQ(ExpectSameFeatures(out, reference, scene, poses[k], camera), reference.size());
  }
  ASSERT_TRUE((*gpu)->Project(LookAt({10, 10, 5}, {10, 10, 50}), camera, &out));
  EXPECT_EQ((*gpu)->last_vertices_considered(), 0u);
  EXPECT_TRUE(out.empty());
}

TEST_F(GpuProjectorTest, AsyncDispatchCollectMatchesSync) {
  const Scene scene = MakeDefaultScene();
  const Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  auto gpu = GpuProjector::Create(scene, ProjectorOptions{}, context_);
  ASSERT_TRUE(gpu) << gpu.error();
  GpuProjector& p = **gpu;
  std::vector<Pose3> poses;
  for (int k = 0; k < 5; ++k) poses.push_back(LookAt({0, 0, 1.5}, {std::cos(k), std::sin(k), 1.2}));
  std::vector<std::vector<ProjectedVertex>> sync(poses.size());
  for (size_t k = 0; k < poses.size(); ++k) ASSERT_TRUE(p.Project(poses[k], camera, &sync[k]));

  auto sorted = [](std::vector<ProjectedVertex> v) {
    std::sort(v.begin(), v.end(), [](auto& a, auto& b) { return a.id < b.id; });
    return v;
  };
  std::vector<ProjectedVertex> out;
  int64_t tag = -1;
  // Render-loop pattern: dispatch frame k, collect frame k - 1.
  ASSERT_TRUE(p.Dispatch(poses[0], camera, 0));
  for (size_t k = 1; k < poses.size(); ++k) {
    ASSERT_TRUE(p.Dispatch(poses[k], camera, static_cast<int64_t>(k)));
    EXPECT_EQ(p.frames_in_flight(), 2);
    EXPECT_FALSE(p.Dispatch(poses[k], camera, 99)) << "a third frame in flight must be refused";
    EXPECT_FALSE(p.Project(poses[k], camera, &out)) << "sync use with frames in flight";
    ASSERT_TRUE(p.Collect(&out, &tag));
    EXPECT_EQ(tag, static_cast<int64_t>(k - 1));
    const auto a = sorted(out), b = sorted(sync[k - 1]);
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) {
      ASSERT_EQ(a[i].id, b[i].id);
      ASSERT_EQ(a[i].u, b[i].u);
      ASSERT_EQ(a[i].v, b[i].v);
      ASSERT_EQ(a[i].depth, b[i].depth);
    }
  }
  ASSERT_TRUE(p.Collect(&out, &tag));
  EXPECT_EQ(tag, static_cast<int64_t>(poses.size() - 1));
  EXPECT_EQ(sorted(out).size(), sync.back().size());
  EXPECT_EQ(p.frames_in_flight(), 0);
  EXPECT_FALSE(p.Collect(&out, &tag)) << "nothing in flight";
}

TEST_F(GpuProjectorTest, RejectsBadInput) {
  ProjectorOptions options;
  auto empty = GpuProjector::Create(Scene{}, options, context_);
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.error().find("no vertices"), std::string::npos) << empty.error();

  Scene bad_triangles;
  bad_triangles.positions = {{0, 0, 1}, {0.1f, 0, 1}, {0, 0.1f, 1}};
  bad_triangles.triangles = {0, 1, 7};
  options.occlusion = true;
  auto out_of_range = GpuProjector::Create(bad_triangles, options, context_);
  ASSERT_FALSE(out_of_range);
  EXPECT_NE(out_of_range.error().find("out of range"), std::string::npos) << out_of_range.error();

  options.occlusion_resolution_scale = 0.0;
  EXPECT_FALSE(GpuProjector::Create(bad_triangles, options, context_));

  Scene nan_scene = bad_triangles;
  nan_scene.triangles.clear();
  nan_scene.positions.push_back({std::nanf(""), 0, 1});
  EXPECT_FALSE(GpuProjector::Create(nan_scene, ProjectorOptions{}, context_));
  bad_triangles.triangles = {0, 1, 2};
  auto gpu = GpuProjector::Create(bad_triangles, ProjectorOptions{}, context_);
  ASSERT_TRUE(gpu) << gpu.error();
  std::vector<ProjectedVertex> out;
  Camera bad_camera;
  bad_camera.fx = -1;
  EXPECT_FALSE((*gpu)->Project(Pose3::Identity(), bad_camera, &out));
  const Pose3 nan_pose(Eigen::Quaterniond::Identity(),
                       Eigen::Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 0));
  EXPECT_FALSE((*gpu)->Project(nan_pose, Camera{}, &out));
  EXPECT_FALSE((*gpu)->Project(Pose3::Identity(), Camera{}, nullptr));
  // Still usable after refused frames.
  ASSERT_TRUE((*gpu)->Project(Pose3::Identity(), Camera{}, &out));
  EXPECT_EQ(out.size(), 3u);
}

TEST_F(GpuProjectorTest, CreatesItsOwnContextWhenGivenNone) {
  Scene scene;
  scene.positions = {{0, 0, 2}, {0, 0, -2}};
  auto gpu = GpuProjector::Create(scene, ProjectorOptions{}, nullptr);
  ASSERT_TRUE(gpu) << gpu.error();
  std::vector<ProjectedVertex> out;
  ASSERT_TRUE((*gpu)->Project(Pose3::Identity(), Camera{}, &out));
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].id, 0u);
  EXPECT_FLOAT_EQ(out[0].u, 320.f);
  EXPECT_FLOAT_EQ(out[0].depth, 2.f);
}

}  // namespace
}  // namespace m2s
