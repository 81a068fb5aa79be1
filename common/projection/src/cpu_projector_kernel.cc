// The vectorisable vertex kernel and the persistent worker pool of CpuProjector.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "cpu_projector_internal.h"

namespace m2s::internal {

WorkerPool::WorkerPool(int size) {
  for (int worker = 1; worker < size; ++worker) {
    threads_.emplace_back([this, worker] { WorkerLoop(worker); });
  }
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  start_cv_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void WorkerPool::RunErased(void* task, Thunk thunk) {
  if (threads_.empty()) {
    thunk(task, 0);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    task_ = task;
    thunk_ = thunk;
    pending_ = static_cast<int>(threads_.size());
    ++generation_;
  }
  start_cv_.notify_all();
  thunk(task, 0);
  std::unique_lock<std::mutex> lock(mutex_);
  done_cv_.wait(lock, [this] { return pending_ == 0; });
}

void WorkerPool::WorkerLoop(int worker) {
  uint64_t seen = 0;
  for (;;) {
    void* task;
    Thunk thunk;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      start_cv_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
      task = task_;
      thunk = thunk_;
    }
    thunk(task, worker);
    bool last;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      last = --pending_ == 0;
    }
    if (last) done_cv_.notify_one();
  }
}

FrameConstants MakeFrameConstants(const Pose3& world_from_camera, const Camera& camera) {
  FrameConstants k;
  const Eigen::Matrix3d camera_from_world = world_from_camera.RotationMatrix().transpose();
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col)
      k.r[3 * row + col] = static_cast<float>(camera_from_world(row, col));
  }
  const Eigen::Vector3d& centre = world_from_camera.translation();
  for (int i = 0; i < 3; ++i) {
    k.centre_hi[i] = static_cast<float>(centre[i]);
    k.centre_lo[i] = static_cast<float>(centre[i] - static_cast<double>(k.centre_hi[i]));
  }
  k.fx = static_cast<float>(camera.fx);
  k.fy = static_cast<float>(camera.fy);
  k.cx = static_cast<float>(camera.cx);
  k.cy = static_cast<float>(camera.cy);
  k.near = static_cast<float>(camera.near);
  k.far = static_cast<float>(camera.far);
  k.width = static_cast<float>(camera.width);
  k.height = static_cast<float>(camera.height);
  return k;
}

M2S_KERNEL_CLONES
void TransformVertices(const FrameConstants& k, const float* __restrict x,
                       const float* __restrict y, const float* __restrict z, size_t n,
                       float* __restrict u, float* __restrict v, float* __restrict depth,
                       uint8_t* __restrict visible) {
  const float r0 = k.r[0], r1 = k.r[1], r2 = k.r[2], r3 = k.r[3], r4 = k.r[4], r5 = k.r[5],
              r6 = k.r[6], r7 = k.r[7], r8 = k.r[8];
  const float chx = k.centre_hi[0], chy = k.centre_hi[1], chz = k.centre_hi[2];
  const float clx = k.centre_lo[0], cly = k.centre_lo[1], clz = k.centre_lo[2];
  const float fx = k.fx, fy = k.fy, cx = k.cx, cy = k.cy;
  const float near = k.near, far = k.far, width = k.width, height = k.height;
  for (size_t i = 0; i < n; ++i) {
    const float dx = (x[i] - chx) - clx;
    const float dy = (y[i] - chy) - cly;
    const float dz = (z[i] - chz) - clz;
    const float cam_x = r0 * dx + r1 * dy + r2 * dz;
    const float cam_y = r3 * dx + r4 * dy + r5 * dz;
    const float cam_z = r6 * dx + r7 * dy + r8 * dz;
    const float pu = fx * (cam_x / cam_z) + cx;
    const float pv = fy * (cam_y / cam_z) + cy;
    // Non-short-circuit '&' keeps the loop free of branches; NaN compares false.
    const bool in =
        (cam_z >= near) & (cam_z <= far) & (pu >= 0.f) & (pu < width) & (pv >= 0.f) & (pv < height);
    u[i] = pu;
    v[i] = pv;
    depth[i] = cam_z;
    visible[i] = static_cast<uint8_t>(in);
  }
}

namespace {

// floor(x - 0.5) in float, 8 lanes at a time: x is clamped to [-1.25, 32767.25] (which
// changes no clamped cell) and t = x + 1.5 = (x - 0.5) + 2 is floored through an int
// conversion. t is x + 1.5 rounded; rounding is monotone and keeps integers, so floor(t) is
// exact unless t rounds onto an integer, which reads as a pixel centre: unknown, the safe
// answer (the triangle is drawn). Branch-free (selects, no early return; this file is
// compiled with -fno-trapping-math, which lets the compiler evaluate both sides of a select).
inline uint32_t PixelCell(float x) {
  const bool finite = std::abs(x) <= std::numeric_limits<float>::max();
  const float t = std::min(std::max(finite ? x : 0.f, -1.25f), 32767.25f) + 1.5f;  // > 0
  const int whole = static_cast<int>(t);  // floor: t is positive
  const bool unknown = !finite | (static_cast<float>(whole) == t);
  return unknown ? uint32_t{kUnknownCell} : static_cast<uint32_t>((whole - 2) & 0xFFFF);
}

}  // namespace

M2S_KERNEL_CLONES
void PixelCells(const float* __restrict u, const float* __restrict v, size_t n, float scale_x,
                float scale_y, uint32_t* __restrict cells) {
  for (size_t i = 0; i < n; ++i)
    cells[i] = PixelCell(u[i] * scale_x) | PixelCell(v[i] * scale_y) << 16;
}

M2S_KERNEL_CLONES
void MayCoverPixelCentres(const uint32_t* __restrict triangles, size_t n,
                          const uint32_t* __restrict cells, uint8_t* __restrict keep) {
  for (size_t t = 0; t < n; ++t) {
    const uint32_t* corner = triangles + 3 * t;
    keep[t] = static_cast<uint8_t>(
        !CoversNoPixelCentre(cells[corner[0]], cells[corner[1]], cells[corner[2]]));
  }
}

M2S_KERNEL_CLONES
void MayCoverPixelCentresOrCrossNear(const uint32_t* __restrict triangles, size_t n,
                                     const uint32_t* __restrict cells,
                                     const float* __restrict depth, float near,
                                     uint8_t* __restrict keep) {
  for (size_t t = 0; t < n; ++t) {
    const uint32_t* corner = triangles + 3 * t;
    const bool in_front =
        (depth[corner[0]] >= near) & (depth[corner[1]] >= near) & (depth[corner[2]] >= near);
    keep[t] = static_cast<uint8_t>(
        !in_front | !CoversNoPixelCentre(cells[corner[0]], cells[corner[1]], cells[corner[2]]));
  }
}

namespace {

// FeatureGrid::Index's steps without its branches: NaN and negatives go to 0.
inline int GridIndex(float x, double step, double last) {
  const double i = std::floor(static_cast<double>(x) / step);
  return static_cast<int>(i >= 0.0 ? std::min(i, last) : 0.0);
}

// The same index in float, for a step of at most 4 binary fractional digits (an image width
// over 16 columns is one) whose multiples up to the image's size are exact in float: then
// floor(x / step) is never rounded across an integer (a float x lies at least 2^-24 of its
// size from the next multiple; the division's rounding is 2^-53), and the reciprocal's guess
// is corrected by exact products. NaN and negatives go to 0, beyond the image to `last`.
inline int GridIndexExact(float x, float step, float inverse, float last, float size) {
  const float clamped = std::min(x >= 0.f ? x : 0.f, size);
  float i = std::floor(clamped * inverse);
  i = (i + 1.f) * step <= clamped ? i + 1.f : i;
  i = i * step > clamped ? i - 1.f : i;
  return static_cast<int>(std::min(i, last));
}

// Whether GridIndexExact holds for this step and number of cells.
bool ExactInFloat(double step, int count) {
  const double scaled = step * 16.0;
  return scaled >= 1.0 && scaled == std::floor(scaled) && scaled * (count + 1) < 0x1p24;
}

// One block's columns and rows (GridIndex or GridIndexExact; inlined into GridCells' variants).
template <typename IndexX, typename IndexY>
[[gnu::always_inline]] inline void BlockIndices(const float* __restrict u,
                                                const float* __restrict v, size_t m, IndexX index_x,
                                                IndexY index_y, int* __restrict col,
                                                int* __restrict row) {
  for (size_t i = 0; i < m; ++i) {
    col[i] = index_x(u[i]);
    row[i] = index_y(v[i]);
  }
}

// The range of a block's cells in view (integer min and max reductions; a vertex out of view
// is moved out of reach by arithmetic, which vectorises where a select of it does not).
[[gnu::always_inline]] inline CellRange BlockRange(const int* __restrict col,
                                                   const int* __restrict row,
                                                   const uint8_t* __restrict in_view, size_t m) {
  constexpr int kFar = 1 << 20;  // beyond any grid's cells
  int col_min = kFar, col_max = -kFar, row_min = kFar, row_max = -kFar;
  for (size_t i = 0; i < m; ++i) {
    const int away = (in_view[i] == 0) * kFar;
    col_min = std::min(col_min, col[i] + away);
    col_max = std::max(col_max, col[i] - away);
    row_min = std::min(row_min, row[i] + away);
    row_max = std::max(row_max, row[i] - away);
  }
  if (col_max < 0) return {};  // nothing in view
  return {col_min, col_max, row_min, row_max};
}

}  // namespace

M2S_KERNEL_CLONES
void GridCells(const float* __restrict u, const float* __restrict v,
               const uint8_t* __restrict visible, size_t n, const FeatureGrid& grid,
               uint16_t* __restrict cells, CellRange* __restrict blocks) {
  const double last_col = grid.cols - 1, last_row = grid.rows - 1;
  const double cell_width = grid.cell_width, cell_height = grid.cell_height;
  const bool exact = ExactInFloat(cell_width, grid.cols) && ExactInFloat(cell_height, grid.rows);
  const auto width = static_cast<float>(cell_width), height = static_cast<float>(cell_height);
  const float inverse_width = 1.f / width, inverse_height = 1.f / height;
  const auto last_colf = static_cast<float>(last_col), last_rowf = static_cast<float>(last_row);
  const float image_width = width * static_cast<float>(grid.cols);
  const float image_height = height * static_cast<float>(grid.rows);
  const int cols = grid.cols;
  int col[kCellBlock], row[kCellBlock];
  for (size_t begin = 0; begin < n; begin += kCellBlock) {
    const size_t m = std::min(n - begin, kCellBlock);
    const uint8_t* in_view = visible + begin;
    if (exact) {
      BlockIndices(
          u + begin, v + begin, m,
          [&](float x) { return GridIndexExact(x, width, inverse_width, last_colf, image_width); },
          [&](float y) {
            return GridIndexExact(y, height, inverse_height, last_rowf, image_height);
          },
          col, row);
    } else {
      BlockIndices(
          u + begin, v + begin, m, [&](float x) { return GridIndex(x, cell_width, last_col); },
          [&](float y) { return GridIndex(y, cell_height, last_row); }, col, row);
    }
    for (size_t i = 0; i < m; ++i) {
      cells[begin + i] =
          in_view[i] != 0 ? static_cast<uint16_t>(row[i] * cols + col[i]) : kNotInView;
    }
    blocks[begin / kCellBlock] = BlockRange(col, row, in_view, m);
  }
}

size_t CompactVisible(const float* __restrict u, const float* __restrict v,
                      const float* __restrict depth, const uint8_t* __restrict visible, size_t n,
                      VertexId first_id, ProjectedVertex* __restrict out) {
  size_t count = 0;
  size_t i = 0;
  // Visibility comes in runs (neighbouring ids are neighbouring surface points): skip eight
  // invisible vertices at a time, and write branch-free inside mixed groups.
  for (; i + 8 <= n; i += 8) {
    uint64_t word;
    std::memcpy(&word, visible + i, sizeof(word));
    if (word == 0) continue;
    for (size_t j = i; j < i + 8; ++j) {
      out[count] = ProjectedVertex{first_id + static_cast<VertexId>(j), u[j], v[j], depth[j]};
      count += visible[j];
    }
  }
  for (; i < n; ++i) {
    out[count] = ProjectedVertex{first_id + static_cast<VertexId>(i), u[i], v[i], depth[i]};
    count += visible[i];
  }
  return count;
}

}  // namespace m2s::internal
