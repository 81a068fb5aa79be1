#include "m2s/gpu/projector_factory.h"

#include <gtest/gtest.h>

#include "gpu_test_util.h"

namespace m2s {
namespace {

TEST(ProjectorFactoryTest, ParsesKinds) {
  auto cpu = ParseProjectorKind("cpu");
  ASSERT_TRUE(cpu);
  EXPECT_EQ(*cpu, ProjectorKind::kCpu);
  auto gpu = ParseProjectorKind("gpu");
  ASSERT_TRUE(gpu);
  EXPECT_EQ(*gpu, ProjectorKind::kGpu);
  EXPECT_EQ(ToString(ProjectorKind::kGpu), "gpu");
  EXPECT_EQ(ToString(ProjectorKind::kCpu), "cpu");
  auto bad = ParseProjectorKind("GPU2");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().find("expected cpu or gpu"), std::string::npos);
}

TEST(ProjectorFactoryTest, BothKindsProjectTheSameScene) {
  Scene scene;
  scene.positions = {{0, 0, 2}, {0.5f, 0.25f, 3}, {0, 0, -1}};
  auto cpu = MakeProjector(ProjectorKind::kCpu, scene, ProjectorOptions{}, nullptr);
  ASSERT_TRUE(cpu) << cpu.error();
  EXPECT_EQ((*cpu)->name(), "cpu");
  std::vector<ProjectedVertex> cpu_out, gpu_out;
  ASSERT_TRUE((*cpu)->Project(Pose3::Identity(), Camera{}, &cpu_out));
  EXPECT_EQ(cpu_out.size(), 2u);

  M2S_SKIP_WITHOUT_EGL();
  auto gpu = MakeProjector(ProjectorKind::kGpu, scene, ProjectorOptions{}, nullptr);
  ASSERT_TRUE(gpu) << gpu.error();
  EXPECT_EQ((*gpu)->name(), "gpu");
  ASSERT_TRUE((*gpu)->Project(Pose3::Identity(), Camera{}, &gpu_out));
  testing::ExpectSameFeatures(gpu_out, cpu_out, scene, Pose3::Identity(), Camera{});
}

TEST(ProjectorFactoryTest, ErrorsComeBackByValue) {
  ProjectorOptions bad_options;
  bad_options.occlusion_resolution_scale = 2.0;
  Scene scene;
  scene.positions = {{0, 0, 1}};
  for (ProjectorKind kind : {ProjectorKind::kCpu, ProjectorKind::kGpu}) {
    auto bad = MakeProjector(kind, scene, bad_options, nullptr);
    ASSERT_FALSE(bad) << ToString(kind);
    EXPECT_NE(bad.error().find("occlusion_resolution_scale"), std::string::npos) << bad.error();
  }
  M2S_SKIP_WITHOUT_EGL();
  auto empty = MakeProjector(ProjectorKind::kGpu, Scene{}, ProjectorOptions{}, nullptr);
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.error().find("no vertices"), std::string::npos) << empty.error();
}

}  // namespace
}  // namespace m2s
