// Helpers shared by the GPU projector tests: camera poses, an independent double-precision
// reference projection, and set/position comparison of projector outputs.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/numeric.h"
#include "m2s/common/scene.h"
#include "m2s/common/types.h"
#include "m2s/gpu/gl_context.h"

namespace m2s::testing {

// Skips the current test with one line when this machine has no EGL display at all.
#define M2S_SKIP_WITHOUT_EGL()                                             \
  if (!::m2s::GlContext::AnyEglDisplayAvailable()) {                       \
    GTEST_SKIP() << "no EGL display on this machine (install Mesa's EGL)"; \
  }

// world_from_camera of a camera at `eye` looking at `target` (x right, y down, z forward),
// with `up` roughly up in the image.
using ::m2s::LookAt;

struct Reference {
  Eigen::Vector3d camera;  // camera-frame position
  double u, v;
};

inline Reference ProjectDouble(const Pose3& world_from_camera, const Camera& camera,
                               const Eigen::Vector3f& p) {
  Reference r;
  r.camera = world_from_camera.Inverse() * p.cast<double>();
  r.u = camera.fx * r.camera.x() / r.camera.z() + camera.cx;
  r.v = camera.fy * r.camera.y() / r.camera.z() + camera.cy;
  return r;
}

// Visible by the contract of projector.h, evaluated in double.
inline bool VisibleDouble(const Reference& r, const Camera& camera) {
  const double z = r.camera.z();
  return z >= camera.near && z <= camera.far && camera.InImage(r.u, r.v);
}

// True when float rounding may legitimately decide visibility either way: within 1e-3 px of
// the image border or within 1e-5 relative of the depth range.
inline bool Ambiguous(const Reference& r, const Camera& camera) {
  constexpr double kPx = 1e-3, kRel = 1e-5;
  const double z = r.camera.z();
  if (std::abs(z - camera.near) <= kRel * camera.near ||
      std::abs(z - camera.far) <= kRel * camera.far)
    return true;
  if (!(z > 0)) return false;
  return std::abs(r.u) <= kPx || std::abs(r.v) <= kPx || std::abs(r.u - camera.width) <= kPx ||
         std::abs(r.v - camera.height) <= kPx;
}

inline std::map<VertexId, ProjectedVertex> ById(const std::vector<ProjectedVertex>& features) {
  std::map<VertexId, ProjectedVertex> out;
  for (const ProjectedVertex& f : features) {
    EXPECT_TRUE(out.emplace(f.id, f).second) << "duplicated id " << f.id;
  }
  return out;
}

// Expects `a` and `b` to hold the same ids except ambiguous ones (see Ambiguous()), with u, v
// within `max_px` and depth within 1e-5 relative. Returns the number of common ids.
inline size_t ExpectSameFeatures(const std::vector<ProjectedVertex>& a,
                                 const std::vector<ProjectedVertex>& b, const Scene& scene,
                                 const Pose3& world_from_camera, const Camera& camera,
                                 double max_px = 1e-3) {
  const auto map_a = ById(a), map_b = ById(b);
  size_t common = 0, mismatched_sets = 0;
  double worst_px = 0.0, worst_depth = 0.0;
  for (const auto& [id, fa] : map_a) {
    auto it = map_b.find(id);
    if (it == map_b.end()) {
      const Reference r = ProjectDouble(world_from_camera, camera, scene.positions[id]);
      if (!Ambiguous(r, camera)) ++mismatched_sets;
      continue;
    }
    ++common;
    const ProjectedVertex& fb = it->second;
    worst_px = std::max({worst_px, std::abs(double(fa.u) - fb.u), std::abs(double(fa.v) - fb.v)});
    worst_depth = std::max(worst_depth, std::abs(double(fa.depth) - fb.depth) / fa.depth);
  }
  for (const auto& [id, fb] : map_b) {
    if (map_a.count(id)) continue;
    const Reference r = ProjectDouble(world_from_camera, camera, scene.positions[id]);
    if (!Ambiguous(r, camera)) ++mismatched_sets;
  }
  EXPECT_EQ(mismatched_sets, 0u) << "ids seen by one projector only (" << a.size() << " vs "
                                 << b.size() << ")";
  EXPECT_LT(worst_px, max_px);
  EXPECT_LT(worst_depth, 1e-5);
  return common;
}

// The double-precision reference as projector output.
inline std::vector<ProjectedVertex> ReferenceFeatures(const Scene& scene,
                                                      const Pose3& world_from_camera,
                                                      const Camera& camera) {
  std::vector<ProjectedVertex> out;
  for (size_t i = 0; i < scene.positions.size(); ++i) {
    const Reference r = ProjectDouble(world_from_camera, camera, scene.positions[i]);
    if (!VisibleDouble(r, camera)) continue;
    out.push_back({static_cast<VertexId>(i), static_cast<float>(r.u), static_cast<float>(r.v),
                   static_cast<float>(r.camera.z())});
  }
  return out;
}

// One headless context shared by all tests of an executable (creating one per test is slow
// on llvmpipe). Null when none could be made.
inline GlContext* SharedContext() {
  static Expected<std::unique_ptr<GlContext>> context = GlContext::CreateHeadless();
  return context ? context->get() : nullptr;
}

}  // namespace m2s::testing
