// The synthetic scene, camera and poses shared by the bench_projection benchmarks (CPU and
// GPU), so every row of the table projects exactly the same vertices.
//
// A 12 m x 12 m x 3 m room (walls, floor, ceiling) with twelve box-shaped pieces of furniture,
// every surface a triangulated grid; vertices are spread over the surfaces in proportion to
// their area and ordered surface by surface (as a loaded mesh is). The camera stands in the
// middle and turns on the spot: about a quarter of the vertices are in view, and the furniture
// hides part of the walls. World axes equal the camera axes at yaw 0 (y down, z forward).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/scene.h"

namespace m2s::bench {

// The paper's Table 1 vertex counts.
inline const std::vector<int64_t>& TableSizes() {
  static const std::vector<int64_t> sizes = {600, 60000, 240000, 480000, 2000000};
  return sizes;
}

inline Camera BenchCamera() { return Camera::FromHorizontalFov(1280, 960, 90.0, 0.05, 50.0); }

// Frame k of a slow turn on the spot (64 frames per revolution), 1.2 m off the room centre.
inline Pose3 BenchPose(int64_t frame) {
  const double yaw = 2.0 * M_PI * static_cast<double>(frame % 64) / 64.0;
  return Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY())),
               Eigen::Vector3d(1.2, 0.2, -0.7));
}

// Exactly `num_vertices` vertices (triangles referring to cut vertices are dropped).
inline Scene MakeBenchScene(int64_t num_vertices) {
  struct Quad {
    Eigen::Vector3f origin, e1, e2;
  };
  std::vector<Quad> quads;
  auto add_box = [&quads](const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
    const Eigen::Vector3f d = hi - lo;
    const Eigen::Vector3f ex(d.x(), 0, 0), ey(0, d.y(), 0), ez(0, 0, d.z());
    quads.push_back({lo, ex, ey});
    quads.push_back({lo + ez, ex, ey});
    quads.push_back({lo, ey, ez});
    quads.push_back({lo + ex, ey, ez});
    quads.push_back({lo, ex, ez});
    quads.push_back({lo + ey, ex, ez});
  };
  add_box({-6, -1.5f, -6}, {6, 1.5f, 6});  // the room
  for (int i = 0; i < 12; ++i) {           // furniture on the floor (y = 1.5), around the walls
    const float angle = static_cast<float>(2.0 * M_PI * i / 12.0);
    const float cx = 4.2f * std::cos(angle), cz = 4.2f * std::sin(angle);
    const float half = 0.4f + 0.05f * static_cast<float>(i % 4),
                height = 0.6f + 0.15f * static_cast<float>(i % 5);
    add_box({cx - half, 1.5f - height, cz - half}, {cx + half, 1.5f, cz + half});
  }
  double total_area = 0;
  for (const Quad& q : quads) total_area += q.e1.cross(q.e2).norm();
  Scene scene;
  scene.name = "bench";
  scene.positions.reserve(static_cast<size_t>(num_vertices) + 1024);
  for (const Quad& q : quads) {
    const double len1 = q.e1.norm(), len2 = q.e2.norm();
    const double count = static_cast<double>(num_vertices) * len1 * len2 / total_area * 1.02;
    // (n1 + 1)(n2 + 1) ~ count with cells about square.
    const int n1 = std::max(1, static_cast<int>(std::sqrt(count * len1 / len2)) - 1);
    const int n2 = std::max(1, static_cast<int>(std::sqrt(count * len2 / len1)) - 1);
    const uint32_t first = static_cast<uint32_t>(scene.positions.size());
    for (int j = 0; j <= n2; ++j) {
      for (int i = 0; i <= n1; ++i) {
        scene.positions.push_back(q.origin + q.e1 * (static_cast<float>(i) / n1) +
                                  q.e2 * (static_cast<float>(j) / n2));
      }
    }
    for (int j = 0; j < n2; ++j) {
      for (int i = 0; i < n1; ++i) {
        const uint32_t a = first + j * (n1 + 1) + i, b = a + 1, c = a + (n1 + 1), d = c + 1;
        scene.triangles.insert(scene.triangles.end(), {a, b, d, a, d, c});
      }
    }
  }
  // Pad (repeating the last surface's points, slightly shifted) or cut to the exact count.
  const size_t n = static_cast<size_t>(num_vertices);
  for (size_t i = 0; scene.positions.size() < n; ++i) {
    scene.positions.push_back(scene.positions[i] * 0.999f);
  }
  scene.positions.resize(n);
  std::vector<uint32_t> kept;
  kept.reserve(scene.triangles.size());
  for (size_t t = 0; t + 2 < scene.triangles.size(); t += 3) {
    if (scene.triangles[t] < n && scene.triangles[t + 1] < n && scene.triangles[t + 2] < n) {
      kept.insert(kept.end(), scene.triangles.begin() + t, scene.triangles.begin() + t + 3);
    }
  }
  scene.triangles.swap(kept);
  return scene;
}

// MakeBenchScene(n), built once per size (benchmarks run one at a time).
inline const Scene& CachedBenchScene(int64_t num_vertices) {
  static std::map<int64_t, Scene> cache;
  auto it = cache.find(num_vertices);
  if (it == cache.end()) it = cache.emplace(num_vertices, MakeBenchScene(num_vertices)).first;
  return it->second;
}

}  // namespace m2s::bench
