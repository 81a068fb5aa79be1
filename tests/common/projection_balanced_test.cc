// CpuProjector::ProjectBalanced against its definition: every visible vertex projected, the
// in-image ones kept, then SelectBalanced (the Projector base's default, which
// feature_rank_test checks against the selection's own definition).
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/numeric.h"

namespace m2s {
namespace {

const Camera kCamera = Camera::FromHorizontalFov(640, 480, 90.0, 0.05, 60.0);

// A wavy sheet of n x n vertices over [x0, x0 + size] x [y0, y0 + size] at height z0 (two
// triangles a cell): dense where n is large for its size.
void AddSheet(Scene* scene, float x0, float y0, float z0, float size, int n) {
  const auto first = static_cast<uint32_t>(scene->positions.size());
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const float x = x0 + size * static_cast<float>(i) / static_cast<float>(n - 1);
      const float y = y0 + size * static_cast<float>(j) / static_cast<float>(n - 1);
      scene->positions.emplace_back(x, y,
                                    z0 + 0.1f * size * std::sin(7.0f * x) * std::cos(5.0f * y));
    }
  }
  for (uint32_t i = 0; i + 1 < static_cast<uint32_t>(n); ++i) {
    for (uint32_t j = 0; j + 1 < static_cast<uint32_t>(n); ++j) {
      const uint32_t a = first + i * static_cast<uint32_t>(n) + j, b = a + 1,
                     c = a + static_cast<uint32_t>(n), d = c + 1;
      scene->triangles.insert(scene->triangles.end(), {a, b, d, a, d, c});
    }
  }
}

// Dense scanned-like sheets next to sparse ones (the balanced selection's reason to exist),
// at several depths, so that sheets hide parts of others.
Scene MixedDensityScene() {
  Scene scene;
  AddSheet(&scene, -4.0f, -4.0f, 0.0f, 8.0f, 12);   // a sparse floor, 144 vertices
  AddSheet(&scene, -1.0f, -1.0f, 0.5f, 1.5f, 220);  // a dense patch, 48,400 vertices
  AddSheet(&scene, 1.0f, 0.5f, 1.0f, 1.0f, 160);    // another, higher
  AddSheet(&scene, -2.5f, 1.0f, 0.3f, 1.2f, 40);    // a medium one
  AddSheet(&scene, 2.0f, -2.5f, 0.2f, 0.3f, 120);   // small and very dense
  return scene;
}

void ExpectSameVertices(const std::vector<ProjectedVertex>& got,
                        const std::vector<ProjectedVertex>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i) {
    ASSERT_EQ(got[i].id, want[i].id) << "at " << i;
    ASSERT_EQ(got[i].u, want[i].u) << "at " << i;
    ASSERT_EQ(got[i].v, want[i].v) << "at " << i;
    ASSERT_EQ(got[i].depth, want[i].depth) << "at " << i;
  }
}

TEST(CpuProjectorBalancedTest, SameSelectionAsProjectingEverythingWithLessWork) {
  const Scene scene = MixedDensityScene();
  const FeatureGrid grid = FeatureGrid::ForImage(kCamera.width, kCamera.height);
  const std::vector<Pose3> poses = {
      LookAt({0, -6, 4}, {0, 0, 0.5}),               // the whole scene, oblique
      LookAt({-0.2, -0.2, 3}, {-0.2, -0.2, 0}),      // straight down onto the dense patch
      LookAt({3, 3, 2}, {-1, -1, 0}),                // across, sheets hiding sheets
      LookAt({2.15, -2.35, 0.8}, {2.15, -2.35, 0}),  // the small dense patch fills the view
      LookAt({8, 8, 1}, {20, 20, 1}),                // nothing in view
  };
  for (const bool occlusion : {false, true}) {
    ProjectorOptions options;
    options.occlusion = occlusion;
    options.num_threads = 2;
    auto projector = CpuProjector::Create(scene, options);
    ASSERT_TRUE(projector) << projector.error();
    CpuProjector& p = **projector;
    size_t tested_balanced = 0, tested_all = 0;
    for (size_t k = 0; k < poses.size(); ++k) {
      for (const int budget : {1, 7, 150, 2000, 1000000}) {
        SCOPED_TRACE("occlusion " + std::to_string(occlusion) + ", pose " + std::to_string(k) +
                     ", budget " + std::to_string(budget));
        std::vector<ProjectedVertex> balanced, reference;
        ASSERT_TRUE(p.ProjectBalanced(poses[k], kCamera, grid, budget, &balanced));
        const size_t tested = p.last_vertices_tested();
        ASSERT_TRUE(p.Projector::ProjectBalanced(poses[k], kCamera, grid, budget, &reference));
        if (budget <= 2000) {  // a larger budget keeps every visible vertex here
          tested_balanced += tested;
          tested_all += p.last_vertices_tested();
        }
        ASSERT_LE(reference.size(), static_cast<size_t>(budget));
        if (k + 1 < poses.size()) {
          ASSERT_FALSE(reference.empty());
        }
        ExpectSameVertices(balanced, reference);
      }
    }
    // Most of the dense patches' vertices are passed over (measured: 6 % of what the full
    // test visits without occlusion, 10 % with it).
    EXPECT_LT(tested_balanced, tested_all / 3) << tested_balanced << " of " << tested_all;
  }
}

// Features bunched in a few cells need more levels than the first heaps hold: the frame is
// tested again with larger ones and the result is still the definition's.
TEST(CpuProjectorBalancedTest, FeaturesInAFewCellsNeedLargerHeaps) {
  Scene scene;
  AddSheet(&scene, 0.0f, 0.0f, 0.0f, 0.05f, 100);  // 10,000 vertices, a few pixels across
  const FeatureGrid grid = FeatureGrid::ForImage(kCamera.width, kCamera.height);
  auto projector = CpuProjector::Create(scene, ProjectorOptions{});
  ASSERT_TRUE(projector) << projector.error();
  const Pose3 pose = LookAt({0.025, 0.025, 3}, {0.025, 0.025, 0});
  std::vector<ProjectedVertex> all;
  ASSERT_TRUE((*projector)->Project(pose, kCamera, &all));
  ASSERT_GT(all.size(), 5000u);
  for (const int budget : {50, 500, 4000}) {
    SCOPED_TRACE("budget " + std::to_string(budget));
    std::vector<ProjectedVertex> balanced, reference;
    ASSERT_TRUE((*projector)->ProjectBalanced(pose, kCamera, grid, budget, &balanced));
    ASSERT_TRUE((*projector)->Projector::ProjectBalanced(pose, kCamera, grid, budget, &reference));
    ASSERT_EQ(reference.size(), static_cast<size_t>(budget));
    ExpectSameVertices(balanced, reference);
  }
}

}  // namespace
}  // namespace m2s
