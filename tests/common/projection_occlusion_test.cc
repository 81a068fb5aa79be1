// CpuProjector occlusion on scenes built so the hidden set is known exactly.
#include <algorithm>
#include <numeric>
#include <random>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/cpu_projector.h"

namespace m2s {
namespace {

// A camera at the world origin looking along +z (camera axes == world axes).
const Camera kCamera{1280, 960, 1000.0, 1000.0, 640.0, 480.0, 0.05, 50.0};

struct Range {
  VertexId begin, end;
};

// Adds an (n1 x n2)-cell grid of triangles spanning origin + [0,1] e1 + [0,1] e2.
Range AddGrid(Scene* scene, const Eigen::Vector3f& origin, const Eigen::Vector3f& e1,
              const Eigen::Vector3f& e2, int n1, int n2) {
  const VertexId first = static_cast<VertexId>(scene->positions.size());
  for (int j = 0; j <= n2; ++j) {
    for (int i = 0; i <= n1; ++i) {
      scene->positions.push_back(origin + e1 * (static_cast<float>(i) / n1) +
                                 e2 * (static_cast<float>(j) / n2));
    }
  }
  auto at = [&](int i, int j) { return first + static_cast<VertexId>(j * (n1 + 1) + i); };
  for (int j = 0; j < n2; ++j) {
    for (int i = 0; i < n1; ++i) {
      scene->triangles.insert(scene->triangles.end(), {at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      scene->triangles.insert(scene->triangles.end(), {at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  }
  return {first, static_cast<VertexId>(scene->positions.size())};
}

struct Box {
  Range front, back, left, right, top, bottom;
};

// An axis-aligned box [lo, hi], each face an n x n grid (edge vertices duplicated per face).
Box AddBox(Scene* scene, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, int n) {
  const Eigen::Vector3f d = hi - lo;
  const Eigen::Vector3f ex(d.x(), 0, 0), ey(0, d.y(), 0), ez(0, 0, d.z());
  Box box;
  box.front = AddGrid(scene, lo, ex, ey, n, n);
  box.back = AddGrid(scene, lo + ez, ex, ey, n, n);
  box.left = AddGrid(scene, lo, ey, ez, n, n);
  box.right = AddGrid(scene, lo + ex, ey, ez, n, n);
  box.top = AddGrid(scene, lo, ex, ez, n, n);
  box.bottom = AddGrid(scene, lo + ey, ex, ez, n, n);
  return box;
}

std::set<VertexId> ProjectIds(const Scene& scene, const ProjectorOptions& options) {
  auto projector = CpuProjector::Create(scene, options);
  EXPECT_TRUE(projector.ok()) << projector.error();
  std::vector<ProjectedVertex> features;
  EXPECT_TRUE((*projector)->Project(Pose3(), kCamera, &features).ok());
  std::set<VertexId> ids;
  for (const ProjectedVertex& f : features) ids.insert(f.id);
  return ids;
}

TEST(CpuProjectorOcclusionTest, WallHidesTheBoxBehindItAndBoxesHideTheirBackFaces) {
  Scene scene;
  // Footprints in normalised image coordinates (X/Z, Y/Z): wall [-0.25, 0.25]^2; hidden box
  // +-0.083; tile x in [-0.44, -0.31]; side box x in [0.36, 0.58], |y| <= 0.083.
  const Range wall = AddGrid(&scene, {-1, -1, 4}, {2, 0, 0}, {0, 2, 0}, 10, 10);
  const Box hidden_box = AddBox(&scene, {-0.5f, -0.5f, 6}, {0.5f, 0.5f, 7}, 4);
  const Range tile = AddGrid(&scene, {-3.5f, -0.5f, 8}, {1, 0, 0}, {0, 1, 0}, 4, 4);
  const Box side_box = AddBox(&scene, {2.5f, -0.5f, 6}, {3.5f, 0.5f, 7}, 5);

  for (const double scale : {1.0, 0.5}) {
    for (const int threads : {1, 3}) {
      SCOPED_TRACE(testing::Message() << "scale " << scale << ", threads " << threads);
      ProjectorOptions options;
      options.occlusion = true;
      options.occlusion_resolution_scale = scale;
      options.num_threads = threads;
      const std::set<VertexId> visible = ProjectIds(scene, options);
      auto expect_all = [&](Range r, bool expected, const char* what) {
        for (VertexId id = r.begin; id < r.end; ++id) {
          EXPECT_EQ(visible.count(id) == 1, expected) << what << " vertex " << id;
        }
      };
      expect_all(wall, true, "wall");
      expect_all(tile, true, "tile");
      for (Range r : {hidden_box.front, hidden_box.back, hidden_box.left, hidden_box.right,
                      hidden_box.top, hidden_box.bottom}) {
        expect_all(r, false, "box behind the wall");
      }
      // The side box, seen from its front-left: front and left faces visible; the back face
      // (except its edge shared with the left face) hidden; the right face's inner vertices
      // hidden. The top and bottom faces are seen edge-on and not asserted.
      expect_all(side_box.front, true, "side box front");
      expect_all(side_box.left, true, "side box left");
      for (VertexId id = side_box.back.begin; id < side_box.back.end; ++id) {
        if (scene.positions[id].x() > 2.51f) {
          EXPECT_EQ(visible.count(id), 0u) << "back " << id;
        }
      }
      for (VertexId id = side_box.right.begin; id < side_box.right.end; ++id) {
        const Eigen::Vector3f& p = scene.positions[id];
        if (p.z() > 6.1f && std::abs(p.y()) < 0.31f) {
          EXPECT_EQ(visible.count(id), 0u) << "right " << id;
        }
      }
    }
  }
  // Without occlusion everything in the frustum is returned.
  const std::set<VertexId> all = ProjectIds(scene, ProjectorOptions{});
  EXPECT_EQ(all.size(), scene.num_vertices());
}

TEST(CpuProjectorOcclusionTest, GrazingFloorAndCreasesDoNotHideThemselves) {
  Scene scene;
  // A floor 1 m below the camera running to 20 m, meeting a back wall (a concave crease), and
  // a step on the floor (a convex edge) - no vertex is hidden.
  AddGrid(&scene, {-4, 1, 1}, {8, 0, 0}, {0, 0, 19}, 40, 190);
  AddGrid(&scene, {-4, -3, 20}, {8, 0, 0}, {0, 4, 0}, 40, 20);
  const Box step = AddBox(&scene, {-1, 0.8f, 5}, {1, 1, 6}, 8);
  ProjectorOptions options;
  options.occlusion = true;
  const std::set<VertexId> visible = ProjectIds(scene, options);
  const std::set<VertexId> all = ProjectIds(scene, ProjectorOptions{});
  // Every floor and wall vertex that is not behind the step is kept; the step's front and top
  // faces too.
  size_t missing = 0;
  for (VertexId id : all) {
    const Eigen::Vector3f& p = scene.positions[id];
    // Under or behind the step (generous: a floor strip beside it is excluded too).
    const bool behind_step = p.z() > 5.01f && std::abs(p.x() / p.z()) < 0.21f && p.y() > 0.75f;
    const bool in_step = id >= step.front.begin;
    if (!behind_step && !in_step && visible.count(id) == 0) ++missing;
  }
  EXPECT_EQ(missing, 0u);
  for (Range r : {step.front, step.top}) {
    for (VertexId id = r.begin; id < r.end; ++id) {
      if (all.count(id)) {
        EXPECT_EQ(visible.count(id), 1u) << "step vertex " << id;
      }
    }
  }
}

TEST(CpuProjectorOcclusionTest, ClipsTrianglesCrossingTheNearPlane) {
  Scene scene;
  // A sloping ceiling y = -0.1 z - 0.2 (camera y points down) from z = -5, behind the
  // camera, to z = 20: its two triangles cross the near plane and must be clipped. Grids at
  // z = 8 above it are hidden (their rays meet it at z = 1.3 to 2.3), grids below are seen.
  scene.positions = {{-50, 0.3f, -5}, {50, 0.3f, -5}, {50, -2.2f, 20}, {-50, -2.2f, 20}};
  scene.triangles = {0, 1, 2, 0, 2, 3};
  const Range behind = AddGrid(&scene, {-0.5f, -2.0f, 8}, {1, 0, 0}, {0, 0.5f, 0}, 4, 4);
  const Range below = AddGrid(&scene, {-0.5f, -0.5f, 8}, {1, 0, 0}, {0, 0.5f, 0}, 4, 4);
  ProjectorOptions options;
  options.occlusion = true;
  const std::set<VertexId> visible = ProjectIds(scene, options);
  for (VertexId id = behind.begin; id < behind.end; ++id) EXPECT_EQ(visible.count(id), 0u) << id;
  for (VertexId id = below.begin; id < below.end; ++id) EXPECT_EQ(visible.count(id), 1u) << id;
}

TEST(CpuProjectorOcclusionTest, TessellatedWallIsWatertight) {
  // A tilted wall of 2 x 80 x 80 irregular triangles (jittered interior vertices) in front of
  // a dense grid of points: a crack of a single buffer pixel next to any point's pixel would
  // let it through (the rule takes the maximum over 3 x 3 pixels), so all must be hidden.
  Scene scene;
  const int n = 80;
  const Eigen::Matrix3f tilt = (Eigen::AngleAxisf(0.5f, Eigen::Vector3f::UnitY()) *
                                Eigen::AngleAxisf(0.3f, Eigen::Vector3f::UnitX()))
                                   .toRotationMatrix();
  const Range wall = AddGrid(&scene, {-2, -2, 0}, {4, 0, 0}, {0, 4, 0}, n, n);
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> jitter(-0.4f * 4 / n, 0.4f * 4 / n);
  for (VertexId id = wall.begin; id < wall.end; ++id) {
    Eigen::Vector3f& p = scene.positions[id];
    if (std::abs(p.x()) < 1.99f && std::abs(p.y()) < 1.99f)
      p += Eigen::Vector3f(jitter(rng), jitter(rng), 0);
    p = tilt * p + Eigen::Vector3f(0, 0, 5);
  }
  const Range behind = AddGrid(&scene, {-0.6f, -0.6f, 9}, {1.2f, 0, 0}, {0, 1.2f, 0}, 60, 60);
  const std::set<VertexId> in_view = ProjectIds(scene, ProjectorOptions{});
  size_t wall_in_view = 0;
  for (VertexId id = wall.begin; id < wall.end; ++id) wall_in_view += in_view.count(id);
  EXPECT_GT(wall_in_view, 6000u);
  for (const double scale : {1.0, 0.37}) {
    ProjectorOptions options;
    options.occlusion = true;
    options.occlusion_resolution_scale = scale;
    const std::set<VertexId> visible = ProjectIds(scene, options);
    size_t leaked = 0;
    for (VertexId id = behind.begin; id < behind.end; ++id) leaked += visible.count(id);
    EXPECT_EQ(leaked, 0u) << "scale " << scale;
    size_t wall_visible = 0;
    for (VertexId id = wall.begin; id < wall.end; ++id) wall_visible += visible.count(id);
    EXPECT_EQ(wall_visible, wall_in_view) << "scale " << scale;
  }
}

namespace culling {

// The scene with its ids shuffled and its triangles in random order: no group of consecutive
// ids or triangles is compact any more, so nothing can be culled. Returns old id -> new id.
std::vector<VertexId> Shuffle(const Scene& scene, Scene* shuffled, std::mt19937& rng) {
  std::vector<VertexId> new_id(scene.num_vertices());
  std::iota(new_id.begin(), new_id.end(), 0);
  std::shuffle(new_id.begin(), new_id.end(), rng);
  shuffled->positions.resize(scene.num_vertices());
  for (size_t i = 0; i < scene.num_vertices(); ++i)
    shuffled->positions[new_id[i]] = scene.positions[i];
  std::vector<size_t> order(scene.num_triangles());
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), rng);
  for (size_t t : order)
    for (int k = 0; k < 3; ++k) shuffled->triangles.push_back(new_id[scene.triangles[3 * t + k]]);
  return new_id;
}

// A district of 6 x 6 boxes 4 m apart, each face a 27 x 27 grid (one culling group a box),
// on a ground of two triangles 200 m wide whose corners are never in view.
TEST(CpuProjectorCullingTest, ResultIsExactlyThatOfProjectingEverything) {
  Scene scene;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) {
      const Eigen::Vector3f lo(4.0f * i, 4.0f * j, 0.0f);
      AddBox(&scene, lo, lo + Eigen::Vector3f(1.5f, 1.5f, 2.0f + 0.2f * ((i + j) % 3)), 27);
    }
  const VertexId ground = static_cast<VertexId>(scene.num_vertices());
  for (const Eigen::Vector3f& p :
       {Eigen::Vector3f(-100, -100, -0.01f), Eigen::Vector3f(100, -100, -0.01f),
        Eigen::Vector3f(100, 100, -0.01f), Eigen::Vector3f(-100, 100, -0.01f)})
    scene.positions.push_back(p);
  scene.triangles.insert(scene.triangles.end(),
                         {ground, ground + 1, ground + 2, ground, ground + 2, ground + 3});
  std::mt19937 rng(11);
  Scene shuffled;
  const std::vector<VertexId> new_id = Shuffle(scene, &shuffled, rng);

  for (bool occlusion : {false, true}) {
    ProjectorOptions options = occlusion ? ProjectorOptions::Occluding() : ProjectorOptions{};
    options.num_threads = 2;
    auto culled = CpuProjector::Create(scene, options);
    auto everything = CpuProjector::Create(shuffled, options);
    ASSERT_TRUE(culled.ok() && everything.ok());
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    size_t considered = 0, tested = 0, total = 0, seen = 0;
    for (int trial = 0; trial < 24; ++trial) {
      // Walking among the boxes at eye height, looking anywhere (also straight down and at
      // boxes cut by the near plane).
      const Eigen::Vector3d position(22 * unit(rng) - 1, 22 * unit(rng) - 1, 0.3 + 2 * unit(rng));
      const Eigen::Quaterniond q(
          Eigen::AngleAxisd(2 * M_PI * unit(rng), Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(M_PI / 2 + 1.2 * (unit(rng) - 0.5), Eigen::Vector3d::UnitX()));
      const Pose3 pose(q, position);
      std::vector<ProjectedVertex> a, b;
      ASSERT_TRUE((*culled)->Project(pose, kCamera, &a).ok());
      ASSERT_TRUE((*everything)->Project(pose, kCamera, &b).ok());
      EXPECT_EQ((*everything)->last_vertices_considered(), scene.num_vertices());
      EXPECT_EQ((*everything)->last_vertices_tested(), scene.num_vertices());
      considered += (*culled)->last_vertices_considered();
      tested += (*culled)->last_vertices_tested();
      EXPECT_LE((*culled)->last_vertices_tested(), (*culled)->last_vertices_considered());
      total += scene.num_vertices();
      seen += a.size();
      // Same vertices with bit-identical pixels and depths (the kernel and the depth buffer do
      // not depend on the order of vertices or triangles).
      std::vector<ProjectedVertex> mapped;
      for (const ProjectedVertex& f : a) mapped.push_back({new_id[f.id], f.u, f.v, f.depth});
      auto by_id = [](const ProjectedVertex& l, const ProjectedVertex& r) { return l.id < r.id; };
      std::sort(mapped.begin(), mapped.end(), by_id);
      std::sort(b.begin(), b.end(), by_id);
      ASSERT_EQ(mapped.size(), b.size()) << "trial " << trial << " occlusion " << occlusion;
      for (size_t k = 0; k < b.size(); ++k) {
        ASSERT_EQ(mapped[k].id, b[k].id);
        ASSERT_EQ(mapped[k].u, b[k].u);
        ASSERT_EQ(mapped[k].v, b[k].v);
        ASSERT_EQ(mapped[k].depth, b[k].depth);
      }
    }
    EXPECT_GT(seen, 10000u);
    // Among the boxes a view holds a fraction of the district: the work follows it.
    // Measured 0.30 (0.33 with occlusion, which adds the groups of triangles in view).
    EXPECT_LT(static_cast<double>(considered) / total, 0.45) << "occlusion " << occlusion;
    // With occlusion, boxes hidden behind nearer boxes are not even depth-tested (their
    // triangles are not rasterised either; the identical output above covers both).
    // Measured 0.68 of the vertices considered.
    if (occlusion) {
      EXPECT_LT(static_cast<double>(tested) / considered, 0.8);
    } else {
      EXPECT_EQ(tested, considered);
    }
  }
}

}  // namespace culling

}  // namespace
}  // namespace m2s
