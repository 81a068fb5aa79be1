// The occlusion depth buffer's triangle rasteriser (an internal of CpuProjector) against a
// per-pixel reference: a pixel is covered when its centre is strictly inside the triangle, or
// on a top or left edge; its depth is 1 / (1/Z interpolated linearly in the image).
//
// Corners lie on a 1/8-pixel grid, so every edge function at a pixel centre is exact in double
// and the reference decides ties (centres on edges, shared edges) as the fill rule says.
#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <random>
#include <tuple>

#include <gtest/gtest.h>

#include "cpu_projector_internal.h"

namespace m2s::internal {
namespace {

constexpr int kWidth = 48, kHeight = 36;

// Twice the signed area of (a, b, p): positive when p is left of a -> b in image coordinates
// (x right, y down) for a triangle of positive area.
double Orient(const RasterVertex& a, const RasterVertex& b, double px, double py) {
  return (b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x);
}

// An edge a -> b of a triangle of positive area is a top edge (horizontal, the inside below)
// or a left edge (going up the image).
bool TopOrLeft(const RasterVertex& a, const RasterVertex& b) {
  return (a.y == b.y && b.x > a.x) || b.y < a.y;
}

// The reference depth of pixel (x, y), or +infinity where the triangle does not cover it.
float ReferenceDepth(RasterVertex a, RasterVertex b, RasterVertex c, int x, int y) {
  double area = Orient(a, b, c.x, c.y);
  if (area == 0.0) return std::numeric_limits<float>::infinity();
  if (area < 0.0) {
    std::swap(b, c);
    area = -area;
  }
  const double px = x + 0.5, py = y + 0.5;
  const RasterVertex* corners[3] = {&a, &b, &c};
  double weight[3];
  for (int i = 0; i < 3; ++i) {
    const RasterVertex& from = *corners[(i + 1) % 3];
    const RasterVertex& to = *corners[(i + 2) % 3];
    weight[i] = Orient(from, to, px, py);
    const bool covered = weight[i] > 0.0 || (weight[i] == 0.0 && TopOrLeft(from, to));
    if (!covered) return std::numeric_limits<float>::infinity();
  }
  const double inv_z = (weight[0] * a.inv_z + weight[1] * b.inv_z + weight[2] * c.inv_z) / area;
  return static_cast<float>(1.0 / inv_z);
}

RasterVertex RandomCorner(std::mt19937* rng, double centre_x, double centre_y, double size) {
  std::uniform_real_distribution<double> offset(-size, size), inv_z(0.1, 2.0);
  auto snap = [](double v) { return std::round(v * 8.0) / 8.0; };
  return {snap(centre_x + offset(*rng)), snap(centre_y + offset(*rng)), inv_z(*rng)};
}

// Rasterises into a cleared buffer and compares every pixel with the reference; returns the
// number of covered pixels.
int ExpectMatchesReference(const RasterVertex& a, const RasterVertex& b, const RasterVertex& c,
                           int row_split) {
  DepthBuffer buffer;
  buffer.Resize(kWidth, kHeight);
  buffer.Clear(0, kHeight);
  // Two bands, as the projector's workers draw them.
  RasterizeTriangle(a, b, c, 0, row_split, &buffer);
  RasterizeTriangle(a, b, c, row_split, kHeight, &buffer);
  int covered = 0;
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const float expected = ReferenceDepth(a, b, c, x, y);
      const float got = buffer.row(y)[x];
      if (std::isinf(expected)) {
        EXPECT_TRUE(std::isinf(got)) << "pixel " << x << "," << y << " covered: " << got;
      } else {
        ++covered;
        EXPECT_NEAR(got, expected, 1e-5 * expected) << "pixel " << x << "," << y;
      }
    }
  }
  return covered;
}

TEST(DepthBufferRasterTest, SmallAndLargeTrianglesCoverExactlyThePixelCentresTheRuleSays) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> centre_x(-4.0, kWidth + 4.0),
      centre_y(-4.0, kHeight + 4.0);
  std::uniform_int_distribution<int> split(0, kHeight);
  // Sizes from below a pixel (most of a dense scan's triangles) to wider than the narrow-box
  // path; some triangles reach past the buffer's edges.
  int covered = 0;
  for (const double size : {0.6, 1.5, 3.0, 6.0, 12.0, 30.0}) {
    for (int i = 0; i < 300; ++i) {
      const double cx = centre_x(rng), cy = centre_y(rng);
      covered +=
          ExpectMatchesReference(RandomCorner(&rng, cx, cy, size), RandomCorner(&rng, cx, cy, size),
                                 RandomCorner(&rng, cx, cy, size), split(rng));
      if (HasFailure()) return;
    }
  }
  EXPECT_GT(covered, 10000);  // the triangles did cover pixels
}

TEST(DepthBufferRasterTest, EdgesThroughPixelCentresFollowTheTopLeftRule) {
  // Corners on pixel centres: every edge passes through centres. Two triangles sharing the
  // diagonal of a square cover each centre of the square exactly once.
  const RasterVertex a{2.5, 2.5, 1.0}, b{12.5, 2.5, 1.0}, c{12.5, 9.5, 1.0}, d{2.5, 9.5, 1.0};
  for (const auto& [p, q, r] :
       {std::tuple(a, b, c), std::tuple(a, c, d), std::tuple(c, b, a), std::tuple(d, c, a)}) {
    ExpectMatchesReference(p, q, r, 5);
  }
  auto coverage =
      [](std::initializer_list<std::tuple<RasterVertex, RasterVertex, RasterVertex>> triangles) {
        DepthBuffer buffer;
        buffer.Resize(kWidth, kHeight);
        buffer.Clear(0, kHeight);
        for (const auto& [p, q, r] : triangles) RasterizeTriangle(p, q, r, 0, kHeight, &buffer);
        int covered = 0;
        for (int y = 0; y < kHeight; ++y)
          for (int x = 0; x < kWidth; ++x) covered += std::isfinite(buffer.row(y)[x]);
        return covered;
      };
  // The square's 11 x 8 centres less its right column and bottom row (neither edge is top or
  // left), each covered by exactly one of the two triangles.
  const int upper = coverage({{a, b, c}}), lower = coverage({{a, c, d}});
  EXPECT_EQ(upper + lower, 70);
  EXPECT_EQ(coverage({{a, b, c}, {a, c, d}}), 70);
}

}  // namespace
}  // namespace m2s::internal
