// The software depth buffer of CpuProjector's occlusion test: near-plane clipping and a
// pixel-centre, top-left-rule triangle rasteriser with perspective-correct camera depth.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "cpu_projector_internal.h"

namespace m2s::internal {
namespace {

// True when an edge with direction (dx, dy) is a top or left edge of a triangle whose signed
// area (b - a) x (c - a) is positive in image coordinates (x right, y down).
bool IsTopLeft(double dx, double dy) { return (dy == 0.0 && dx > 0.0) || dy < 0.0; }

// An edge function w(px, py) = step_x * px + step_y * py + offset, positive inside.
struct Edge {
  double step_x;  // change of w per +1 in x
  double step_y;  // change of w per +1 in y
  double offset;
  bool top_left;

  Edge(const RasterVertex& start, const RasterVertex& end)
      : step_x(-(end.y - start.y)),
        step_y(end.x - start.x),
        offset(-(step_x * start.x + step_y * start.y)),
        top_left(IsTopLeft(end.x - start.x, end.y - start.y)) {}
};

// Boxes at most this many pixels wide are rasterised by testing every pixel of a row.
constexpr int kNarrowBox = 8;

// One edge along one row: the pixel-centre coverage test, the only definition of "inside".
struct RowEdge {
  double row_offset;  // w at px = 0 on this row
  double step_x;
  bool top_left;
  bool Inside(int x) const {
    const double w = row_offset + step_x * (x + 0.5);
    return (w > 0.0) | (top_left & (w == 0.0));  // w >= 0 on a top or left edge, w > 0 on others
  }
};

// The pixels of a row inside all three edges, for a narrow box [x0, x0 + width): bit i is set
// when pixel x0 + i is inside. Every pixel is tested without branches (a small triangle's rows
// are one or two pixels wide, and ClipSpan's searches mispredict there). Along a row each edge
// function is monotonic in x, also as rounded, so the set bits are one interval: the span
// ClipSpan finds.
[[gnu::always_inline]] inline uint32_t InsideMask(const RowEdge (&edges)[3], int x0, int width) {
  uint32_t mask = 0;
  for (int i = 0; i < width; ++i) {
    const int x = x0 + i;
    const bool inside = edges[0].Inside(x) & edges[1].Inside(x) & edges[2].Inside(x);
    mask |= static_cast<uint32_t>(inside) << i;
  }
  return mask;
}

// Narrows [*lo, *hi] to the pixels inside `e`. w is linear in x, so the inside pixels of a row
// form one interval; its end is found analytically and then checked with Inside() exactly.
// Always inlined, like InsideMask: compiled inside each variant of RasterizeTriangle (the
// same rounding and instructions as its caller's; out of line it would be the baseline build).
[[gnu::always_inline]] inline void ClipSpan(const RowEdge& e, int* lo, int* hi) {
  if (*lo > *hi) return;
  if (e.step_x == 0.0) {
    if (!e.Inside(*lo)) *hi = *lo - 1;
    return;
  }
  const double crossing = std::clamp(-e.row_offset / e.step_x - 0.5, *lo - 2.0, *hi + 2.0);
  if (e.step_x > 0.0) {  // inside to the right of the crossing
    int x = std::max(*lo, static_cast<int>(std::ceil(crossing)));
    while (x <= *hi && !e.Inside(x)) ++x;
    while (x > *lo && e.Inside(x - 1)) --x;
    *lo = x;
  } else {  // inside to the left
    int x = std::min(*hi, static_cast<int>(std::floor(crossing)));
    while (x >= *lo && !e.Inside(x)) --x;
    while (x < *hi && e.Inside(x + 1)) ++x;
    *hi = x;
  }
}

}  // namespace

void DepthBuffer::Resize(int width, int height) {
  width_ = width;
  height_ = height;
  const size_t size = static_cast<size_t>(width) * static_cast<size_t>(height);
  if (data_.size() < size) data_.resize(size);
}

void DepthBuffer::Clear(int row_begin, int row_end) {
  if (row_end <= row_begin) return;
  std::fill(row(row_begin), row(row_begin) + static_cast<size_t>(row_end - row_begin) * width_,
            std::numeric_limits<float>::infinity());
}

float DepthBuffer::Max3x3(int x, int y) const {
  const int x0 = std::max(x - 1, 0), x1 = std::min(x + 1, width_ - 1);
  const int y0 = std::max(y - 1, 0), y1 = std::min(y + 1, height_ - 1);
  float result = 0.f;
  for (int yy = y0; yy <= y1; ++yy) {
    const float* r = row(yy);
    for (int xx = x0; xx <= x1; ++xx) result = std::max(result, r[xx]);
  }
  return result;
}

void DepthBuffer::Dilate3x3(int row_begin, int row_end, DepthBuffer* out) const {
  // Separable, Max3x3's value at every pixel (depths are positive, max is exact): the maximum
  // over the rows y-1..y+1 per column, then over the columns x-1..x+1.
  std::vector<float> columns(static_cast<size_t>(width_));
  for (int y = row_begin; y < row_end; ++y) {
    const float* above = row(std::max(y - 1, 0));
    const float* here = row(y);
    const float* below = row(std::min(y + 1, height_ - 1));
    for (int x = 0; x < width_; ++x)
      columns[x] = std::max(std::max(above[x], here[x]), std::max(below[x], 0.f));
    float* dilated = out->row(y);
    const int last = width_ - 1;
    for (int x = 0; x < width_; ++x) {
      const float left = columns[std::max(x - 1, 0)], right = columns[std::min(x + 1, last)];
      dilated[x] = std::max(std::max(left, columns[x]), right);
    }
  }
}

bool DepthBuffer::AllNearerThan(int x0, int x1, int y0, int y1, float relative, float absolute,
                                float threshold) const {
  if (x0 > x1 || y0 > y1) return false;
  for (int y = y0; y <= y1; ++y) {
    const float* r = row(y);
    for (int x = x0; x <= x1; ++x) {
      if (!(r[x] * relative + absolute < threshold)) return false;
    }
  }
  return true;
}

M2S_KERNEL_CLONES
void RasterizeTriangle(const RasterVertex& a, const RasterVertex& b_in, const RasterVertex& c_in,
                       int row_begin, int row_end, DepthBuffer* buffer) {
  RasterVertex b = b_in, c = c_in;
  double area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
  if (!std::isfinite(area) || area == 0.0) return;
  if (area < 0.0) {
    std::swap(b, c);
    area = -area;
  }
  // Pixel (i, j) is sampled at its centre (i + 0.5, j + 0.5).
  const double min_x = std::min({a.x, b.x, c.x}), max_x = std::max({a.x, b.x, c.x});
  const double min_y = std::min({a.y, b.y, c.y}), max_y = std::max({a.y, b.y, c.y});
  const double first_x = std::max(0.0, std::ceil(min_x - 0.5));
  const double last_x = std::min(static_cast<double>(buffer->width() - 1), std::floor(max_x - 0.5));
  const double first_y = std::max(static_cast<double>(row_begin), std::ceil(min_y - 0.5));
  const double last_y = std::min(static_cast<double>(row_end - 1), std::floor(max_y - 0.5));
  if (!(first_x <= last_x) || !(first_y <= last_y)) return;
  const int x0 = static_cast<int>(first_x), x1 = static_cast<int>(last_x);
  const int y0 = static_cast<int>(first_y), y1 = static_cast<int>(last_y);

  const Edge edges[3] = {Edge(b, c), Edge(c, a), Edge(a, b)};
  // 1/Z is affine in screen space: inv_z(px, py) = dx * px + dy * py + at_origin.
  const double dx = ((b.inv_z - a.inv_z) * (c.y - a.y) - (c.inv_z - a.inv_z) * (b.y - a.y)) / area;
  const double dy = ((c.inv_z - a.inv_z) * (b.x - a.x) - (b.inv_z - a.inv_z) * (c.x - a.x)) / area;
  const double at_origin = a.inv_z - dx * a.x - dy * a.y;
  // Inside the triangle 1/Z is at least the smallest vertex value; rounding must not go below.
  const float min_inv_z = static_cast<float>(std::min({a.inv_z, b.inv_z, c.inv_z}) * (1.0 - 1e-6));
  const float step = static_cast<float>(dx);
  const int width = x1 - x0 + 1;
  for (int y = y0; y <= y1; ++y) {
    const double py = y + 0.5;
    const RowEdge row_edges[3] = {
        {edges[0].offset + edges[0].step_y * py, edges[0].step_x, edges[0].top_left},
        {edges[1].offset + edges[1].step_y * py, edges[1].step_x, edges[1].top_left},
        {edges[2].offset + edges[2].step_y * py, edges[2].step_x, edges[2].top_left}};
    int lo = x0, hi = x1;
    if (width <= kNarrowBox) {
      const uint32_t mask = InsideMask(row_edges, x0, width);
      if (mask == 0) continue;
      lo = x0 + std::countr_zero(mask);
      hi = x0 + 31 - std::countl_zero(mask);
    } else {
      for (const RowEdge& e : row_edges) ClipSpan(e, &lo, &hi);
      if (lo > hi) continue;
    }
    // In float relative to the span start, so the loop vectorises and stays accurate.
    const float start = static_cast<float>(dx * (lo + 0.5) + dy * py + at_origin);
    float* out = buffer->row(y) + lo;
    const int n = hi - lo + 1;
    for (int i = 0; i < n; ++i) {
      const float inv_z = std::max(start + step * static_cast<float>(i), min_inv_z);
      out[i] = std::min(out[i], 1.f / inv_z);
    }
  }
}

void ClipAndRasterizeTriangle(const Eigen::Vector3d (&p_camera)[3], const Camera& camera,
                              double scale_x, double scale_y, int row_begin, int row_end,
                              DepthBuffer* buffer) {
  // Sutherland-Hodgman against the plane Z = near: a triangle gives at most 4 vertices.
  Eigen::Vector3d clipped[4];
  int count = 0;
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d& p = p_camera[i];
    const Eigen::Vector3d& q = p_camera[(i + 1) % 3];
    const bool p_in = p.z() >= camera.near, q_in = q.z() >= camera.near;
    if (p_in) clipped[count++] = p;
    if (p_in != q_in) {
      const double t = (camera.near - p.z()) / (q.z() - p.z());
      Eigen::Vector3d r = p + t * (q - p);
      r.z() = camera.near;
      clipped[count++] = r;
    }
  }
  if (count < 3) return;
  RasterVertex screen[4];
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector2d uv = camera.Project(clipped[i]);
    screen[i] = {uv.x() * scale_x, uv.y() * scale_y, 1.0 / clipped[i].z()};
  }
  RasterizeTriangle(screen[0], screen[1], screen[2], row_begin, row_end, buffer);
  if (count == 4) RasterizeTriangle(screen[0], screen[2], screen[3], row_begin, row_end, buffer);
}

}  // namespace m2s::internal
