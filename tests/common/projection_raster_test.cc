// The occlusion depth buffer's triangle rasteriser (an internal of CpuProjector) against a
// per-pixel reference: a pixel is covered when its centre is strictly inside the triangle, or
// on a top or left edge; its depth is 1 / (1/Z interpolated linearly in the image).
//
// Corners lie on a 1/8-pixel grid, so every edge function at a pixel centre is exact in double
// and the reference decides ties (centres on edges, shared edges) as the fill rule says.
#include <algorithm>
#include <bit>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <random>
#include <tuple>
#include <vector>

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

// The pixel-centre cell of a coordinate, from its definition: floor(x - 0.5) clamped to
// [-2, 32766], unknown when x - 0.5 is an integer in [-1, 32766] (a centre's coordinate, or
// the one just left of the buffer) or x not finite. In double, x - 0.5 is exact
// for |x| < 2^52; a float of magnitude 2^24 or more is an integer, whose cell is x - 1.
uint32_t ReferenceCell(float scaled) {
  if (std::isfinite(scaled) && std::abs(scaled) >= 0x1p24f) return scaled > 0.f ? 32766u : 0xFFFEu;
  const double x = static_cast<double>(scaled) - 0.5;
  if (!std::isfinite(x) || (x == std::floor(x) && x >= -1.0 && x <= 32766.0)) return kUnknownCell;
  return static_cast<uint32_t>(static_cast<int>(std::clamp(std::floor(x), -2.0, 32766.0)) & 0xFFFF);
}

// A cell as PixelCells may give it: the reference's, or unknown within float rounding
// (2^-23 of the magnitude) of a pixel centre's coordinate on the clamped range.
bool CellMatches(uint16_t cell, float scaled) {
  const uint32_t reference = ReferenceCell(scaled);
  if (cell == reference) return true;
  const double x = static_cast<double>(scaled) - 0.5;
  return cell == kUnknownCell && x > -3.0 && x < 32768.0 &&
         std::abs(x - std::round(x)) <= 0x1p-23 * (std::abs(x) + 2.0);
}

TEST(PixelCellsTest, EveryKindOfFloatGetsItsCellFromTheDefinition) {
  std::vector<float> values = {0.f,
                               -0.f,
                               0.5f,
                               -0.5f,
                               1.f,
                               -1.f,
                               1.5f,
                               -1.5f,
                               319.5f,
                               320.f,
                               32766.5f,
                               32767.5f,
                               1e30f,
                               -1e30f,
                               1e-30f,
                               -1e-30f,
                               std::nextafter(0.5f, 0.f),
                               std::nextafter(0.5f, 1.f),
                               std::nextafter(-0.5f, 0.f),
                               std::nextafter(-0.5f, -1.f),
                               std::nextafter(-1.f, 0.f),
                               std::nextafter(-1.f, -2.f),
                               -0.5f + 0x1p-25f,
                               16777216.f,
                               8388608.5f,
                               -8388608.5f,
                               std::numeric_limits<float>::infinity(),
                               -std::numeric_limits<float>::infinity(),
                               std::numeric_limits<float>::quiet_NaN(),
                               std::numeric_limits<float>::denorm_min()};
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> near_image(-3.f, 700.f);
  std::uniform_int_distribution<uint32_t> bits;
  for (int i = 0; i < 200000; ++i) {
    values.push_back(near_image(rng));
    // Half-pixel coordinates and their neighbours, the cells' boundaries.
    const float half = std::floor(near_image(rng)) + 0.5f;
    values.push_back(half);
    values.push_back(std::nextafter(half, 0.f));
    values.push_back(std::nextafter(half, 1e9f));
    values.push_back(std::bit_cast<float>(bits(rng)));  // any float at all
  }
  std::vector<float> zeros(values.size(), 0.f);
  std::vector<uint32_t> cells(values.size());
  // As u, then as v (scale 1): the low and the high half of each cell word.
  PixelCells(values.data(), zeros.data(), values.size(), 1.f, 1.f, cells.data());
  size_t rounded = 0;
  for (size_t i = 0; i < values.size(); ++i) {
    ASSERT_TRUE(CellMatches(cells[i] & 0xFFFF, values[i])) << "x = " << values[i];
    ASSERT_EQ(cells[i] >> 16, ReferenceCell(0.f));
    rounded += (cells[i] & 0xFFFF) != ReferenceCell(values[i]);
  }
  // Unknown by rounding only next to a centre: a few of the values placed there.
  EXPECT_LT(rounded, values.size() / 100);
  PixelCells(zeros.data(), values.data(), values.size(), 1.f, 1.f, cells.data());
  for (size_t i = 0; i < values.size(); ++i) {
    ASSERT_TRUE(CellMatches(cells[i] >> 16, values[i])) << "y = " << values[i];
    ASSERT_EQ(cells[i] & 0xFFFF, ReferenceCell(0.f));
  }
  // The buffer's scale is applied in float before the cell: 0.5 halves exactly.
  const float u = 201.f, v = 3.f;
  PixelCells(&u, &v, 1, 0.5f, 0.5f, cells.data());
  EXPECT_EQ(cells[0], ReferenceCell(100.5f) | ReferenceCell(1.5f) << 16);
}

}  // namespace
}  // namespace m2s::internal
