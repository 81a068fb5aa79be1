// Internals of CpuProjector: aligned storage, the persistent worker pool, the vectorisable
// per-vertex kernel and the software depth buffer. Not part of the public API.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <mutex>
#include <new>
#include <thread>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/frustum_culling.h"
#include "m2s/common/geometry.h"
#include "m2s/common/types.h"

// On x86-64 with GCC, hot loops are compiled twice (baseline SSE2 and x86-64-v3: AVX2 + FMA)
// and the variant is picked at load time; elsewhere the baseline build is used. Not under
// ThreadSanitizer: its instrumented ifunc resolver runs before the TSan runtime and crashes.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__ELF__) && \
    !defined(__SANITIZE_THREAD__)
#define M2S_KERNEL_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define M2S_KERNEL_CLONES
#endif

namespace m2s::internal {

inline constexpr size_t kSimdAlignment = 64;

// Minimal allocator giving 64-byte aligned blocks, so the SoA arrays start on cache lines.
template <typename T>
struct AlignedAllocator {
  using value_type = T;
  AlignedAllocator() = default;
  template <typename U>
  AlignedAllocator(const AlignedAllocator<U>&) {}  // NOLINT: rebinding
  T* allocate(size_t n) {
    const size_t bytes = (n * sizeof(T) + kSimdAlignment - 1) / kSimdAlignment * kSimdAlignment;
    void* p = std::aligned_alloc(kSimdAlignment, bytes == 0 ? kSimdAlignment : bytes);
    if (p == nullptr) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t) { std::free(p); }
  template <typename U>
  bool operator==(const AlignedAllocator<U>&) const {
    return true;
  }
};

template <typename T>
using AlignedVector = std::vector<T, AlignedAllocator<T>>;

// A fixed set of threads that run one task per call to Run(), each with its worker index.
// The calling thread acts as worker 0; workers 1..size()-1 are owned threads that wait on a
// condition variable between calls and are joined on destruction. Run() is not reentrant and
// must be called from one thread at a time (the projector's owner).
class WorkerPool {
 public:
  explicit WorkerPool(int size);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int size() const { return static_cast<int>(threads_.size()) + 1; }

  // Calls task(worker) for worker in [0, size()) concurrently and returns when all are done.
  // No allocation: the task is passed by reference through a type-erased thunk.
  template <typename Task>
  void Run(Task& task) {
    RunErased(&task, [](void* t, int worker) { (*static_cast<Task*>(t))(worker); });
  }

 private:
  using Thunk = void (*)(void*, int);
  void RunErased(void* task, Thunk thunk);
  void WorkerLoop(int worker);

  std::vector<std::thread> threads_;
  std::mutex mutex_;
  std::condition_variable start_cv_;
  std::condition_variable done_cv_;
  uint64_t generation_ = 0;
  int pending_ = 0;
  bool stop_ = false;
  void* task_ = nullptr;
  Thunk thunk_ = nullptr;
};

// Per-frame constants of the vertex kernel, in float. The camera centre is split into a high
// and a low float part so that (x - centre) keeps full float precision relative to the
// vertex-camera distance, even far from the world origin.
struct FrameConstants {
  float r[9];  // camera_from_world rotation, row major
  float centre_hi[3];
  float centre_lo[3];
  float fx, fy, cx, cy;
  float near, far;
  float width, height;
};

FrameConstants MakeFrameConstants(const Pose3& world_from_camera, const Camera& camera);

// For vertices [0, n) of the given SoA arrays: u, v (pixels), depth (camera Z) and visible
// (1 when near <= Z <= far and (u, v) is inside the image, else 0). Branch-free and
// vectorised; the same code computes every output of the projector.
void TransformVertices(const FrameConstants& k, const float* x, const float* y, const float* z,
                       size_t n, float* u, float* v, float* depth, uint8_t* visible);

// Pixel-centre cells of vertices in a depth buffer, for rejecting triangles that cover no
// pixel centre with integer compares. For x = u[i] * scale_x (float, as the rasteriser
// computes it), the cell is floor(x - 0.5) clamped to [-2, 32766], or kUnknownCell when x is
// not finite or x - 0.5 is an integer in [-1, 32766], or within float rounding of one (about
// 2^-24 |x|: an unknown cell only keeps a triangle for the rasteriser); likewise y. cells[i] =
// cell_x | cell_y << 16 (16-bit two's complement). Three corners with one known x cell (or one
// known y cell) lie strictly between two neighbouring pixel centres (or all off the buffer on one
// side): the triangle covers no pixel centre.
inline constexpr uint16_t kUnknownCell = 0x8000;
void PixelCells(const float* u, const float* v, size_t n, float scale_x, float scale_y,
                uint32_t* cells);
// True when the triangle with these corner cells certainly covers no pixel centre.
// Branch-free (non-short-circuit '&', '|'): MayCoverPixelCentres vectorises it.
inline bool CoversNoPixelCentre(uint32_t c0, uint32_t c1, uint32_t c2) {
  const uint32_t differ = (c0 ^ c1) | (c0 ^ c2);
  return (((differ & 0xFFFFu) == 0) & ((c0 & 0xFFFFu) != kUnknownCell)) |
         (((differ >> 16) == 0) & ((c0 >> 16) != kUnknownCell));
}
// keep[t] = 1 unless triangle t (corners triangles[3t], [3t + 1], [3t + 2]) certainly covers
// no pixel centre (CoversNoPixelCentre), for t < n. A dense scan's triangles are mostly far
// below a pixel: this one loop rejects them without a branch per triangle.
void MayCoverPixelCentres(const uint32_t* triangles, size_t n, const uint32_t* cells,
                          uint8_t* keep);
// The same for triangles that may cross the near plane: keep[t] = 1 also when a corner of
// triangle t has depth < near or NaN (its cells say nothing before clipping).
void MayCoverPixelCentresOrCrossNear(const uint32_t* triangles, size_t n, const uint32_t* cells,
                                     const float* depth, float near, uint8_t* keep);

// Grid cells [x0, x1] x [y0, y1] (inclusive; empty when x0 > x1).
struct CellRange {
  int x0 = 0, x1 = -1, y0 = 0, y1 = -1;
  bool empty() const { return x0 > x1; }
};
// Vertices per block of GridCells' ranges (and of the balanced visit's rank order).
inline constexpr size_t kCellBlock = 256;
// cells[i] = FeatureGrid::CellOf(u[i], v[i]) (the same double operations) when visible[i],
// else kNotInView; blocks[b] = the range of the cells of the visible vertices among
// [b * kCellBlock, (b + 1) * kCellBlock) (empty when none is). Vectorised. The grid has fewer
// than kNotInView cells.
inline constexpr uint16_t kNotInView = 0xFFFF;
void GridCells(const float* u, const float* v, const uint8_t* visible, size_t n,
               const FeatureGrid& grid, uint16_t* cells, CellRange* blocks);

// Appends (first_id + i, u[i], v[i], depth[i]) for every i < n with visible[i] to `out`,
// which must have room for n + 1 entries; returns the number written.
size_t CompactVisible(const float* u, const float* v, const float* depth, const uint8_t* visible,
                      size_t n, VertexId first_id, ProjectedVertex* out);

// The software depth buffer used for occlusion (see cpu_projector.h for the exact rule).
class DepthBuffer {
 public:
  // Sets the size for this frame (allocates only when the size grows).
  void Resize(int width, int height);
  int width() const { return width_; }
  int height() const { return height_; }
  // Fills rows [row_begin, row_end) with +infinity.
  void Clear(int row_begin, int row_end);
  float* row(int y) { return data_.data() + static_cast<size_t>(y) * width_; }
  const float* row(int y) const { return data_.data() + static_cast<size_t>(y) * width_; }
  // Largest depth over the 3x3 pixels around (x, y), clipped to the buffer.
  float Max3x3(int x, int y) const;
  // Writes Max3x3(x, y) for every pixel of rows [row_begin, row_end) to the same rows of
  // `out` (sized like this buffer first, by the caller).
  void Dilate3x3(int row_begin, int row_end, DepthBuffer* out) const;
  // True when every pixel of [x0, x1] x [y0, y1] (inside the buffer) holds a depth d with
  // d * relative + absolute < threshold: nothing at depth >= threshold there is in front of
  // the buffer. False for an empty rectangle.
  bool AllNearerThan(int x0, int x1, int y0, int y1, float relative, float absolute,
                     float threshold) const;

 private:
  int width_ = 0;
  int height_ = 0;
  AlignedVector<float> data_;
};

// A vertex of a triangle in depth-buffer pixel coordinates with its inverse camera depth.
struct RasterVertex {
  double x, y, inv_z;
};

// Rasterises one triangle into rows [row_begin, row_end) of the buffer, keeping the minimum
// camera depth. Samples at pixel centres with the top-left fill rule; depth interpolated
// perspective-correctly (1/Z is affine in screen space).
void RasterizeTriangle(const RasterVertex& a, const RasterVertex& b, const RasterVertex& c,
                       int row_begin, int row_end, DepthBuffer* buffer);

// Clips the camera-frame triangle against Z >= near and rasterises the result (0 to 2
// triangles). scale_x/scale_y map image pixels to buffer pixels.
void ClipAndRasterizeTriangle(const Eigen::Vector3d (&p_camera)[3], const Camera& camera,
                              double scale_x, double scale_y, int row_begin, int row_end,
                              DepthBuffer* buffer);

// Culling (public: m2s/common/frustum_culling.h, shared with the GPU projector).
using ::m2s::BoxTriangles;
using ::m2s::BoxVertices;
using ::m2s::CullGroup;
using ::m2s::FrustumCuller;
using ::m2s::MakeTriangleGroups;
using ::m2s::MakeVertexGroups;
using ::m2s::ScreenBox;

// Splits a list of groups into `parts` consecutive runs of about equal vertex (or triangle)
// counts: run k is list[split[k] .. split[k + 1]).
void SplitByCount(const std::vector<CullGroup>& groups, const std::vector<uint32_t>& list,
                  int parts, std::vector<size_t>* split);

}  // namespace m2s::internal
