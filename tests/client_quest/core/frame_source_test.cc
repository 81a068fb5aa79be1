#include "m2s/client/frame_source.h"

#include <algorithm>

#include <gtest/gtest.h>

#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"

namespace m2s::client {
namespace {

std::vector<VertexId> SortedIds(const wire::FeatureFrame& frame) {
  std::vector<VertexId> ids;
  for (const VertexFeature& f : frame.features) ids.push_back(f.id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

TEST(FrameSourceTest, SendBudgetSendsTheBalancedSelectionOfTheVisibleVertices) {
  const Scene scene = MakeDefaultScene();
  const Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  auto projector = CpuProjector::Create(scene, ProjectorOptions{});
  ASSERT_TRUE(projector.ok()) << projector.error();
  const Pose3 world_from_camera = DefaultTrajectory().poses().front().world_from_camera;
  const auto n = static_cast<uint32_t>(scene.num_vertices());
  FrameSource all(projector->get(), camera, FeatureNoiseOptions{}, n);
  FrameSource budgeted(projector->get(), camera, FeatureNoiseOptions{}, n, 1500);
  auto full = all.Make(world_from_camera, 0, 0);
  auto cut = budgeted.Make(world_from_camera, 0, 0);
  ASSERT_TRUE(full.ok() && cut.ok());
  ASSERT_GT(full->features.size(), 3000u);  // the default room is dense
  ASSERT_EQ(cut->features.size(), 1500u);
  // Reference: the balanced selection of the whole view (feature_rank_test checks it).
  std::vector<VertexFeature> selected = full->features;
  KeepBalanced(1500, FeatureGrid::ForImage(camera.width, camera.height), &selected);
  std::vector<VertexId> expected;
  for (const VertexFeature& f : selected) expected.push_back(f.id);
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(SortedIds(*cut), expected);
  // Each kept feature carries its own projection.
  for (const VertexFeature& f : cut->features) {
    const auto it = std::find_if(full->features.begin(), full->features.end(),
                                 [&](const VertexFeature& g) { return g.id == f.id; });
    ASSERT_NE(it, full->features.end());
    EXPECT_EQ(it->uv, f.uv);
  }
}

}  // namespace
}  // namespace m2s::client
