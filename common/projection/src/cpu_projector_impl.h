// CpuProjector::Impl: the projector's state, shared by its translation units.
#pragma once

#include <algorithm>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "cpu_projector_internal.h"
#include "m2s/common/cpu_projector.h"

namespace m2s {

using internal::AlignedVector;
using internal::DepthBuffer;
using internal::FrameConstants;
using internal::RasterVertex;
using internal::WorkerPool;

// Constants of the projector (not in an anonymous namespace: two translation units use them).

// Vertices processed per kernel call: the block's outputs stay in L1 before compaction.
inline constexpr size_t kBlockSize = 1024;
// Below this many vertices per worker, waking another thread costs more than it saves.
inline constexpr size_t kMinVerticesPerWorker = 32768;
// Culling groups: vertices (a multiple of kBlockSize, so groups start on cache lines) and
// triangles per group.
inline constexpr size_t kVertexGroupSize = 4 * kBlockSize;
inline constexpr size_t kTriangleGroupSize = 4096;
// The frustum test's margin around the image (pixels): far above the kernel's float rounding.
inline constexpr double kCullMarginPx = 2.0;
inline constexpr int kMaxThreads = 256;

struct CpuProjector::Impl {
  struct WorkerScratch {
    AlignedVector<float> u, v, depth;
    AlignedVector<uint8_t> visible;
    AlignedVector<uint8_t> keep;       // per triangle of a group: may cover a pixel centre
    std::vector<ProjectedVertex> out;  // grows to the chunk size + 1, never shrinks
    size_t count = 0;
    size_t tested = 0;  // vertices of the groups this worker depth-tested in the last frame
  };

  ProjectorOptions options;
  size_t num_vertices = 0;
  AlignedVector<float> x, y, z;
  std::vector<uint32_t> triangles;
  std::unique_ptr<WorkerPool> pool;
  std::vector<WorkerScratch> scratch;

  // Occlusion: per-vertex kernel outputs for the whole scene, and the depth buffer.
  AlignedVector<float> all_u, all_v, all_depth;
  AlignedVector<uint8_t> all_visible;
  AlignedVector<uint32_t> all_cells;  // internal::PixelCells in the depth buffer
  DepthBuffer depth_buffer;
  DepthBuffer dilated;  // Max3x3 of depth_buffer at every pixel: the vertex test's threshold

  // Culling groups (cpu_projector_internal.h) and, per triangle group, the vertex groups its
  // corners belong to (tri_refs[tri_ref_begin[t] .. tri_ref_begin[t + 1]]).
  std::vector<internal::CullGroup> vertex_groups, triangle_groups;
  std::vector<uint32_t> tri_ref_begin, tri_refs;

  // Per-frame state read by the workers.
  FrameConstants constants{};
  Camera camera;
  Eigen::Matrix3d camera_from_world = Eigen::Matrix3d::Identity();
  Eigen::Vector3d camera_centre = Eigen::Vector3d::Zero();
  int active_workers = 1;
  float cell_scale_x = 1.f, cell_scale_y = 1.f;  // image -> buffer pixels, as Band uses them
  // Vertex groups that may be seen, and (with occlusion) those to transform: the seen ones
  // and every group a seen triangle uses; worker w takes list[split[w] .. split[w + 1]).
  std::vector<uint32_t> visible_groups, transform_groups, visible_triangle_groups;
  // With occlusion, the buffer footprints of the visible vertex groups and of the visible
  // triangle groups (the latter ordered nearest first, so that hidden groups are skipped).
  std::vector<internal::ScreenBox> vertex_footprints, triangle_footprints;
  std::vector<std::pair<double, uint32_t>> triangle_order;
  std::vector<size_t> visible_split, transform_split;
  std::vector<uint8_t> group_needed;
  size_t frame_vertices = 0;        // vertices in the visible groups
  size_t transformed_vertices = 0;  // with occlusion: in the groups transformed

  // Fills tri_ref_begin / tri_refs from the triangle groups (marks, not a sort: 12288 corners
  // a group).
  void TriangleGroupRefs() {
    tri_ref_begin.assign(1, 0);
    tri_refs.clear();
    std::vector<uint32_t> last_seen(vertex_groups.size(), ~uint32_t{0});
    for (uint32_t t = 0; t < triangle_groups.size(); ++t) {
      const internal::CullGroup& group = triangle_groups[t];
      for (size_t i = 3 * size_t{group.begin}; i < 3 * size_t{group.end}; ++i) {
        const auto g = static_cast<uint32_t>(triangles[i] / kVertexGroupSize);
        if (last_seen[g] == t) continue;
        last_seen[g] = t;
        tri_refs.push_back(g);
      }
      tri_ref_begin.push_back(static_cast<uint32_t>(tri_refs.size()));
    }
  }
  // Re-boxes the vertex groups holding `ids` (sorted) and the groups of ids [first, end).
  void ReboxVertices(const std::vector<VertexId>& ids, VertexId first, VertexId end);
  // Fills the per-frame lists; returns the number of workers to wake.
  void Cull(const Pose3& world_from_camera, int pool_size);
  // NaN coordinates: the kernel never finds a retired vertex visible, boxes leave it out.
  void Retire(VertexId id) { x[id] = y[id] = z[id] = std::numeric_limits<float>::quiet_NaN(); }
  ProjectedVertex* ReserveOut(WorkerScratch& s, size_t n) {
    if (s.out.size() < n + 1) s.out.resize(n + 1);
    return s.out.data();
  }

  void ProjectChunk(int worker);
  void TransformChunk(int worker);
  void RasterizeBand(int band, int num_bands);
  void DilateBand(int band, int num_bands);
  // One band of depth-buffer rows and the constants of its triangle loop.
  struct Band {
    int row_begin = 0, row_end = 0;
    double scale_x = 1, scale_y = 1;  // image pixels -> buffer pixels
    float near = 0, far = 0;
    double last_row = 0, last_column = 0;  // the last pixel centres of the band
  };
  void RasterizeTriangleAt(size_t t, const Band& band);
  // A triangle whose corners are all at depth >= near.
  void RasterizeInFront(const uint32_t* idx, const Band& band);
  // The triangles of `group` (all corners between near and far) that may cover a pixel centre
  // (found for the whole group at once, in scratch[band].keep).
  void RasterizeGroupInFront(const internal::CullGroup& group, int band, const Band& b);
  void TestChunk(int worker);
  // Appends the vertices of [begin, end) that pass the depth test to out[count...]; returns
  // the new count.
  size_t TestGroup(size_t begin, size_t end, ProjectedVertex* out, size_t count) const;
};

}  // namespace m2s
