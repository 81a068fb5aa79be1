// The CPU projector's per-vertex cell kernels (internals) against their definitions, in
// double, over every kind of float: pixel-centre cells (the triangle rejection) and feature
// grid cells (the balanced selection, which must agree with FeatureGrid::CellOf exactly).
#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "cpu_projector_internal.h"
#include "m2s/common/feature_rank.h"

namespace m2s::internal {
namespace {

// Boundary values, values near an image, half-pixel coordinates and their neighbours, and
// arbitrary bit patterns (NaN, infinities, denormals, huge values).
std::vector<float> TestValues() {
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
                               40.f,
                               std::nextafter(40.f, 0.f),
                               600.f,
                               640.f,
                               479.99997f,
                               std::numeric_limits<float>::infinity(),
                               -std::numeric_limits<float>::infinity(),
                               std::numeric_limits<float>::quiet_NaN(),
                               std::numeric_limits<float>::denorm_min()};
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> near_image(-3.f, 700.f);
  std::uniform_int_distribution<uint32_t> bits;
  for (int i = 0; i < 200000; ++i) {
    values.push_back(near_image(rng));
    const float half = std::floor(near_image(rng)) + 0.5f;
    values.push_back(half);
    values.push_back(std::nextafter(half, 0.f));
    values.push_back(std::nextafter(half, 1e9f));
    values.push_back(std::bit_cast<float>(bits(rng)));
  }
  return values;
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
  const std::vector<float> values = TestValues();
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

TEST(GridCellsTest, EveryKindOfFloatGetsFeatureGridCellOfsCellAndBlocksTheirRanges) {
  const std::vector<float> values = TestValues();
  // 640 x 480 and 1000 x 37: cells whose sizes are exact in float (GridCells' float path);
  // 480 x 500: 17 rows of 29.41 px (its double path).
  for (const auto& [width, height] :
       {std::pair{640, 480}, std::pair{1000, 37}, std::pair{480, 500}}) {
    const FeatureGrid grid = FeatureGrid::ForImage(width, height);
    std::mt19937 rng(11);
    std::vector<float> v = values;
    std::shuffle(v.begin(), v.end(), rng);
    std::vector<uint8_t> visible(values.size());
    for (size_t i = 0; i < visible.size(); ++i) visible[i] = static_cast<uint8_t>(i % 7 != 3);
    // A last block of 100, and a block with no vertex in view.
    const size_t n = values.size() - values.size() % kCellBlock - kCellBlock + 100;
    ASSERT_GT(n, 4 * kCellBlock);
    ASSERT_LE(n, visible.size());
    for (size_t i = 3 * kCellBlock; i < 4 * kCellBlock; ++i) visible[i] = 0;
    std::vector<uint16_t> cells(n);
    std::vector<CellRange> blocks((n + kCellBlock - 1) / kCellBlock);
    GridCells(values.data(), v.data(), visible.data(), n, grid, cells.data(), blocks.data());
    for (size_t b = 0; b < blocks.size(); ++b) {
      CellRange expected_range{grid.cols, -1, grid.rows, -1};
      for (size_t i = b * kCellBlock; i < std::min(n, (b + 1) * kCellBlock); ++i) {
        const uint16_t expected =
            visible[i] ? static_cast<uint16_t>(grid.CellOf(values[i], v[i])) : kNotInView;
        ASSERT_EQ(cells[i], expected) << "u = " << values[i] << ", v = " << v[i];
        if (!visible[i]) continue;
        const int col = expected % grid.cols, row = expected / grid.cols;
        expected_range = {std::min(expected_range.x0, col), std::max(expected_range.x1, col),
                          std::min(expected_range.y0, row), std::max(expected_range.y1, row)};
      }
      EXPECT_EQ(blocks[b].empty(), b == 3) << b;
      if (b == 3) continue;
      EXPECT_EQ(blocks[b].x0, expected_range.x0) << b;
      EXPECT_EQ(blocks[b].x1, expected_range.x1) << b;
      EXPECT_EQ(blocks[b].y0, expected_range.y0) << b;
      EXPECT_EQ(blocks[b].y1, expected_range.y1) << b;
    }
  }
}

}  // namespace
}  // namespace m2s::internal
