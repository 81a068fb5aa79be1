// CpuProjector against an independent double-precision reference, across threads, and its
// options and errors. Occlusion has its own file (projection_occlusion_test.cc).
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/cpu_projector.h"

namespace m2s {
namespace {

// The reference: one vertex at a time, in double, straight from the camera.h equations.
struct Reference {
  enum Class { kVisible, kInvisible, kAmbiguous };
  Class cls;
  double u, v, z;
};

constexpr double kPixelTolerance = 1e-3;

Reference ProjectReference(const Eigen::Vector3f& p_world, const Pose3& world_from_camera,
                           const Camera& camera) {
  const Eigen::Vector3d p = world_from_camera.Inverse() * p_world.cast<double>();
  Reference r{Reference::kInvisible, 0, 0, p.z()};
  const double z_tol = 1e-6 * std::abs(p.z()) + 1e-7;
  if (p.z() < camera.near - z_tol || p.z() > camera.far + z_tol) return r;
  r.u = camera.fx * p.x() / p.z() + camera.cx;
  r.v = camera.fy * p.y() / p.z() + camera.cy;
  const double t = kPixelTolerance;
  const bool surely_out =
      r.u < -t || r.v < -t || r.u >= camera.width + t || r.v >= camera.height + t;
  const bool surely_in = p.z() >= camera.near + z_tol && p.z() <= camera.far - z_tol && r.u >= t &&
                         r.v >= t && r.u < camera.width - t && r.v < camera.height - t;
  r.cls = surely_in    ? Reference::kVisible
          : surely_out ? Reference::kInvisible
                       : Reference::kAmbiguous;
  return r;
}

// Random camera pose looking roughly at `target` from `distance` away.
Pose3 RandomPose(std::mt19937& rng, const Eigen::Vector3d& target) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const Eigen::Quaterniond q = Eigen::Quaterniond(Eigen::AngleAxisd(
      M_PI * unit(rng), Eigen::Vector3d(unit(rng), unit(rng), unit(rng)).normalized()));
  const Eigen::Vector3d offset = Eigen::Vector3d(unit(rng), unit(rng), unit(rng)) * 2.0;
  // Camera at target + offset - 6 * forward so the target is in view.
  const Eigen::Vector3d forward = q * Eigen::Vector3d::UnitZ();
  return Pose3(q, target + offset - 6.0 * forward);
}

// Points spread around the camera, plus points placed exactly on the image border, on the
// near and far planes, just inside and outside them, behind the camera and beyond far.
Scene MakeTestScene(std::mt19937& rng, const Pose3& world_from_camera, const Camera& camera,
                    int num_random) {
  Scene scene;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const Eigen::Vector3d c = world_from_camera.translation();
  for (int i = 0; i < num_random; ++i) {
    const Eigen::Vector3d d(unit(rng) * 2 - 1, unit(rng) * 2 - 1, unit(rng) * 2 - 1);
    scene.positions.push_back((c + d * 12.0).cast<float>());
  }
  auto add_camera_point = [&](double u, double v, double z) {
    scene.positions.push_back(
        (world_from_camera * camera.Unproject(Eigen::Vector2d(u, v), z)).cast<float>());
  };
  const double w = camera.width, h = camera.height;
  const double zs[] = {camera.near, camera.near * 1.01, 1.0, 3.7, camera.far * 0.99, camera.far};
  for (double z : zs) {
    for (int k = 0; k < 40; ++k) {
      const double s = unit(rng);
      add_camera_point(0.0, s * h, z);       // left border (inside)
      add_camera_point(w, s * h, z);         // right border (outside)
      add_camera_point(s * w, 0.0, z);       // top border (inside)
      add_camera_point(s * w, h, z);         // bottom border (outside)
      add_camera_point(0.01, s * h, z);      // just inside
      add_camera_point(w - 0.01, s * h, z);  // just inside
      add_camera_point(-0.01, s * h, z);     // just outside
      add_camera_point(s * w, h + 0.01, z);  // just outside
      add_camera_point(s * w, s * h, z);     // anywhere inside
    }
  }
  for (int k = 0; k < 200; ++k) {
    const double u = unit(rng) * w, v = unit(rng) * h;
    add_camera_point(u, v, -1.0 - 5 * unit(rng));                     // behind the camera
    add_camera_point(u, v, camera.far * (1.001 + unit(rng)));         // beyond far
    add_camera_point(u, v, camera.near * (0.999 - 0.9 * unit(rng)));  // nearer than near
  }
  return scene;
}

// Checks `features` against the reference: sorted unique ids, every surely-visible vertex
// present, no surely-invisible one, u, v within 1e-3 px, depth within float precision.
void ExpectMatchesReference(const Scene& scene, const Pose3& pose, const Camera& camera,
                            const std::vector<ProjectedVertex>& features) {
  for (size_t i = 1; i < features.size(); ++i) ASSERT_LT(features[i - 1].id, features[i].id);
  size_t next = 0;
  double max_error = 0;
  for (VertexId id = 0; id < scene.num_vertices(); ++id) {
    const Reference r = ProjectReference(scene.positions[id], pose, camera);
    const bool present = next < features.size() && features[next].id == id;
    if (r.cls == Reference::kVisible) {
      EXPECT_TRUE(present) << "missing vertex " << id;
    } else if (r.cls == Reference::kInvisible) {
      EXPECT_FALSE(present) << "extra vertex " << id;
    }
    if (!present) continue;
    const ProjectedVertex& f = features[next++];
    max_error = std::max({max_error, std::abs(f.u - r.u), std::abs(f.v - r.v)});
    EXPECT_NEAR(f.depth, r.z, 1e-6 * std::abs(r.z) + 1e-6);
  }
  EXPECT_LT(max_error, kPixelTolerance);
}

TEST(CpuProjectorTest, MatchesDoublePrecisionReferenceOnRandomScenesAndPoses) {
  std::mt19937 rng(7);
  const Camera cameras[] = {Camera::FromHorizontalFov(640, 480, 90.0),
                            Camera::FromHorizontalFov(2048, 2048, 110.0, 0.1, 30.0),
                            Camera::FromHorizontalFov(2048, 1536, 60.0, 0.02, 100.0)};
  for (const Camera& camera : cameras) {
    for (int trial = 0; trial < 4; ++trial) {
      const Pose3 pose = RandomPose(rng, Eigen::Vector3d(3.0 * trial, -2.0, 1.0));
      const Scene scene = MakeTestScene(rng, pose, camera, 20000);
      auto projector = CpuProjector::Create(scene, ProjectorOptions{});
      ASSERT_TRUE(projector.ok()) << projector.error();
      std::vector<ProjectedVertex> features;
      ASSERT_TRUE((*projector)->Project(pose, camera, &features).ok());
      EXPECT_GT(features.size(), 1000u);
      ExpectMatchesReference(scene, pose, camera, features);
    }
  }
}

TEST(CpuProjectorTest, KeepsSubPixelPrecisionFarFromTheOrigin) {
  std::mt19937 rng(11);
  const Camera camera = Camera::FromHorizontalFov(2048, 2048, 90.0, 0.05, 50.0);
  for (const double offset : {100.0, 1000.0}) {
    const Pose3 pose = RandomPose(rng, Eigen::Vector3d(offset, -offset, 0.5 * offset));
    const Scene scene = MakeTestScene(rng, pose, camera, 5000);
    auto projector = CpuProjector::Create(scene, ProjectorOptions{});
    ASSERT_TRUE(projector.ok());
    std::vector<ProjectedVertex> features;
    ASSERT_TRUE((*projector)->Project(pose, camera, &features).ok());
    ExpectMatchesReference(scene, pose, camera, features);
  }
}

TEST(CpuProjectorTest, ThreadCountDoesNotChangeTheOutput) {
  std::mt19937 rng(3);
  const Camera camera = Camera::FromHorizontalFov(1280, 720, 90.0);
  const Pose3 pose = RandomPose(rng, Eigen::Vector3d::Zero());
  const Scene scene = MakeTestScene(rng, pose, camera, 300000);
  std::vector<ProjectedVertex> reference;
  for (int threads : {1, 2, 3, 8}) {
    ProjectorOptions options;
    options.num_threads = threads;
    auto projector = CpuProjector::Create(scene, options);
    ASSERT_TRUE(projector.ok());
    EXPECT_EQ((*projector)->num_threads(), threads);
    std::vector<ProjectedVertex> features;
    for (int repeat = 0; repeat < 3; ++repeat) {
      ASSERT_TRUE((*projector)->Project(pose, camera, &features).ok());
    }
    if (threads == 1) {
      reference = features;
      ExpectMatchesReference(scene, pose, camera, features);
      continue;
    }
    ASSERT_EQ(features.size(), reference.size());
    for (size_t i = 0; i < features.size(); ++i) {
      ASSERT_EQ(features[i].id, reference[i].id);
      ASSERT_EQ(features[i].u, reference[i].u);
      ASSERT_EQ(features[i].v, reference[i].v);
      ASSERT_EQ(features[i].depth, reference[i].depth);
    }
  }
}

TEST(CpuProjectorTest, ReusesOutputCapacityAndHandlesEmptyScenes) {
  std::mt19937 rng(5);
  const Camera camera;
  const Pose3 pose = RandomPose(rng, Eigen::Vector3d::Zero());
  const Scene scene = MakeTestScene(rng, pose, camera, 1000);
  auto projector = CpuProjector::Create(scene, ProjectorOptions{});
  ASSERT_TRUE(projector.ok());
  std::vector<ProjectedVertex> features;
  ASSERT_TRUE((*projector)->Project(pose, camera, &features).ok());
  const ProjectedVertex* data = features.data();
  ASSERT_TRUE((*projector)->Project(pose, camera, &features).ok());
  EXPECT_EQ(features.data(), data);

  auto empty = CpuProjector::Create(Scene{}, ProjectorOptions{});
  ASSERT_TRUE(empty.ok());
  ASSERT_TRUE((*empty)->Project(pose, camera, &features).ok());
  EXPECT_TRUE(features.empty());
}

TEST(CpuProjectorTest, RejectsBadOptionsScenesCamerasAndPoses) {
  Status why;
  EXPECT_TRUE((why = ProjectorOptions{}.Check()));
  ProjectorOptions bad;
  bad.occlusion_resolution_scale = 0.0;
  EXPECT_FALSE((why = bad.Check()));
  EXPECT_NE(why.message().find("occlusion_resolution_scale"), std::string::npos);
  bad = {};
  bad.occlusion_resolution_scale = 1.5;
  EXPECT_FALSE(bad.Check());
  bad = {};
  bad.occlusion_depth_bias_relative = -0.1;
  EXPECT_FALSE(bad.Check());
  bad = {};
  bad.occlusion_depth_bias_m = std::nan("");
  EXPECT_FALSE(bad.Check());
  bad = {};
  bad.num_threads = -1;
  EXPECT_FALSE(bad.Check());
  EXPECT_FALSE(CpuProjector::Create(Scene{}, bad).ok());

  Scene scene;
  scene.positions = {Eigen::Vector3f(0, 0, 1), Eigen::Vector3f(0.1f, 0, 1),
                     Eigen::Vector3f(0, 0.1f, 1)};
  scene.triangles = {0, 1, 3};
  auto out_of_range = CpuProjector::Create(scene, ProjectorOptions{});
  ASSERT_FALSE(out_of_range.ok());
  EXPECT_NE(out_of_range.error().find("out of range"), std::string::npos);
  scene.triangles = {0, 1};
  EXPECT_FALSE(CpuProjector::Create(scene, ProjectorOptions{}).ok());
  scene.triangles = {0, 1, 2};
  scene.positions[1].x() = std::numeric_limits<float>::infinity();
  EXPECT_FALSE(CpuProjector::Create(scene, ProjectorOptions{}).ok());
  scene.positions[1].x() = 0.1f;

  auto projector = CpuProjector::Create(scene, ProjectorOptions{});
  ASSERT_TRUE(projector.ok());
  std::vector<ProjectedVertex> features;
  Camera camera;
  camera.fx = -1;
  EXPECT_FALSE((*projector)->Project(Pose3(), camera, &features).ok());
  const Pose3 nan_pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(std::nan(""), 0, 0));
  EXPECT_FALSE((*projector)->Project(nan_pose, Camera(), &features).ok());
  EXPECT_FALSE((*projector)->Project(Pose3(), Camera(), nullptr).ok());
  ASSERT_TRUE((*projector)->Project(Pose3(), Camera(), &features).ok());
  EXPECT_EQ(features.size(), 3u);
}

}  // namespace
}  // namespace m2s
