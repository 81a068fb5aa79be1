// MakeDefaultScene: size, determinism, one id per position, LoadScene id order, varied
// density, and enough vertices in view from every pose of DefaultTrajectory().
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "m2s/common/camera.h"
#include "m2s/common/cpu_projector.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"

namespace m2s {
namespace {

TEST(DefaultScene, SizeAndDeterminism) {
  const Scene a = MakeDefaultScene();
  const Scene b = MakeDefaultScene();
  EXPECT_GE(a.num_vertices(), 20000u);
  EXPECT_LE(a.num_vertices(), 100000u);
  EXPECT_GT(a.num_triangles(), a.num_vertices());
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.triangles, b.triangles);
}

TEST(DefaultScene, OneIdPerPositionAndValidTriangles) {
  const Scene scene = MakeDefaultScene();
  std::set<std::tuple<float, float, float>> unique;
  for (const auto& p : scene.positions) unique.insert({p.x(), p.y(), p.z()});
  EXPECT_EQ(unique.size(), scene.num_vertices());
  // Ids first appear in increasing order along the triangle list (LoadScene order).
  uint32_t next = 0;
  for (size_t t = 0; t < scene.triangles.size(); t += 3) {
    const uint32_t a = scene.triangles[t], b = scene.triangles[t + 1], c = scene.triangles[t + 2];
    ASSERT_TRUE(a != b && b != c && a != c) << "degenerate triangle " << t / 3;
    for (uint32_t id : {a, b, c}) {
      ASSERT_LE(id, next) << "triangle " << t / 3;
      if (id == next) ++next;
    }
  }
  EXPECT_EQ(next, scene.num_vertices()) << "every vertex belongs to a triangle";
}

TEST(DefaultScene, FitsTheDocumentedRoomWithVariedDensity) {
  const Scene scene = MakeDefaultScene();
  const RoomLayout layout = DefaultRoomLayout();
  Eigen::AlignedBox3d bounds;
  size_t floor = 0, north_wall = 0;
  for (const auto& p : scene.positions) {
    bounds.extend(p.cast<double>());
    // A furniture-free patch of floor, 1.9 m x 2.8 m.
    if (p.z() == 0.f && p.x() > -2.9f && p.x() < -1.0f && p.y() > -1.8f && p.y() < 1.0f) ++floor;
    if (p.y() == static_cast<float>(layout.room.max().y())) ++north_wall;
  }
  EXPECT_LT((bounds.min() - layout.room.min()).norm(), 1e-6);
  EXPECT_LT((bounds.max() - layout.room.max()).norm(), 1e-6);
  // Vertices per square metre: the floor is sparse, the north wall (16.2 m^2 less a window)
  // dense.
  const double floor_density = floor / (1.9 * 2.8), wall_density = north_wall / 16.2;
  EXPECT_GT(floor_density, 1.0);
  EXPECT_LT(floor_density, 40.0);
  EXPECT_GT(wall_density, 10.0 * floor_density);
}

TEST(DefaultScene, EveryPoseOfTheDefaultTrajectorySeesHundredsOfVertices) {
  const Scene scene = MakeDefaultScene();
  const Trajectory trajectory = DefaultTrajectory();
  const Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  for (size_t i = 0; i < trajectory.size(); i += 45) {
    const Pose3 camera_from_world = trajectory[i].world_from_camera.Inverse();
    int visible = 0;
    for (const auto& p : scene.positions) {
      const Eigen::Vector3d x = camera_from_world * p.cast<double>();
      if (x.z() < camera.near || x.z() > camera.far) continue;
      const Eigen::Vector2d uv = camera.Project(x);
      visible += camera.InImage(uv.x(), uv.y());
    }
    EXPECT_GE(visible, 300) << "pose " << i << " at t = " << trajectory[i].timestamp;
  }
}

// The same with occlusion (walls and furniture hide what is behind them): still hundreds.
TEST(DefaultScene, OccludedViewsAlongTheDefaultTrajectoryKeepHundredsOfVertices) {
  const Scene scene = MakeDefaultScene();
  const Trajectory trajectory = DefaultTrajectory();
  const Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  ProjectorOptions options;
  options.occlusion = true;
  Expected<std::unique_ptr<CpuProjector>> projector = CpuProjector::Create(scene, options);
  ASSERT_TRUE(projector.ok()) << projector.error();
  std::vector<ProjectedVertex> features;
  for (size_t i = 0; i < trajectory.size(); i += 30) {
    ASSERT_TRUE((*projector)->Project(trajectory[i].world_from_camera, camera, &features).ok());
    EXPECT_GE(features.size(), 200u) << "pose " << i << " at t = " << trajectory[i].timestamp;
  }
}

}  // namespace
}  // namespace m2s
