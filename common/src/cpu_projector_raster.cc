// The software depth buffer of CpuProjector's occlusion test: near-plane clipping and a
// pixel-centre, top-left-rule triangle rasteriser with perspective-correct camera depth.
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "cpu_projector_internal.h"

namespace m2s::internal {
namespace {

// True when an edge with direction (dx, dy) is a top or left edge of a triangle whose signed
// area (b - a) x (c - a) is positive in image coordinates (x right, y down).
bool IsTopLeft(double dx, double dy) { return (dy == 0.0 && dx > 0.0) || dy < 0.0; }

struct Edge {
  double start_x, start_y;
  double step_x;  // change of the edge function per +1 in x
  double step_y;  // change per +1 in y
  bool top_left;

  Edge(const RasterVertex& start, const RasterVertex& end)
      : start_x(start.x),
        start_y(start.y),
        step_x(-(end.y - start.y)),
        step_y(end.x - start.x),
        top_left(IsTopLeft(end.x - start.x, end.y - start.y)) {}
  double At(double px, double py) const {
    return step_y * (py - start_y) + step_x * (px - start_x);
  }
};

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

  const Edge e0(b, c), e1(c, a), e2(a, b);  // weights of a, b and c
  const double inv_area = 1.0 / area;
  for (int y = y0; y <= y1; ++y) {
    const double py = y + 0.5, px = x0 + 0.5;
    double w0 = e0.At(px, py), w1 = e1.At(px, py), w2 = e2.At(px, py);
    float* out = buffer->row(y);
    for (int x = x0; x <= x1; ++x) {
      const bool inside = (e0.top_left ? w0 >= 0.0 : w0 > 0.0) &&
                          (e1.top_left ? w1 >= 0.0 : w1 > 0.0) &&
                          (e2.top_left ? w2 >= 0.0 : w2 > 0.0);
      if (inside) {
        const double inv_z = (w0 * a.inv_z + w1 * b.inv_z + w2 * c.inv_z) * inv_area;
        const float depth = static_cast<float>(1.0 / inv_z);
        if (depth < out[x]) out[x] = depth;
      }
      w0 += e0.step_x;
      w1 += e1.step_x;
      w2 += e2.step_x;
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
