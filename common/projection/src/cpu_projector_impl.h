// CpuProjector::Impl: the projector's state, shared by its translation units.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "cpu_projector_internal.h"
#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_rank.h"

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
  // Balanced projection (cpu_projector_balanced.cc): a visible vertex with its rank, and per
  // worker, for each grid cell, a max-heap of the lowest-ranked ones and the number seen.
  struct RankedVertex {
    uint64_t rank = 0;
    ProjectedVertex vertex;
    bool operator<(const RankedVertex& o) const { return rank < o.rank; }
  };
  struct CellHeaps {
    int cols = 1;
    std::vector<RankedVertex> entries;  // cell c's heap at [c * capacity, + filled[c])
    std::vector<uint32_t> filled, count;
    // Per cell: the largest rank in its heap once full, UINT64_MAX before.
    std::vector<uint64_t> top;
    size_t visited = 0;
    // The largest rank in the heaps of the box's cells, or UINT64_MAX when one is not full.
    uint64_t Bound(const internal::CellRange& box) const;
    void Add(size_t c, uint32_t capacity, uint64_t rank, const ProjectedVertex& vertex);
  };

  // A triangle with every corner between near and far that may cover a pixel centre of the
  // buffer: its buffer-space corners and the rows of pixel centres its box spans.
  struct InFrontTriangle {
    RasterVertex a, b, c;
    double first_row, last_row;
  };

  struct WorkerScratch {
    AlignedVector<float> u, v, depth;
    AlignedVector<uint8_t> visible;
    AlignedVector<uint8_t> keep;      // per triangle of a group: may cover a pixel centre
    std::vector<uint32_t> survivors;  // the triangles kept, of the groups this worker selected
    std::vector<InFrontTriangle> in_front;  // the same, of groups wholly between near and far
    std::vector<ProjectedVertex> out;       // grows to the chunk size + 1, never shrinks
    size_t count = 0;
    size_t tested = 0;  // vertices of the groups this worker depth-tested in the last frame
    CellHeaps heaps;
    AlignedVector<float> group_u, group_v, group_depth;  // one group, without occlusion
    AlignedVector<uint8_t> group_visible;
    AlignedVector<uint16_t> group_grid_cells;
    std::vector<internal::CellRange> group_blocks;
    std::vector<std::pair<uint64_t, uint8_t>> ranked;  // PrepareRankOrder's buffer
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
  // Balanced projection with occlusion: internal::GridCells of the transformed vertices, and
  // the ranges of cells of their blocks of kCellBlock.
  AlignedVector<uint16_t> all_grid_cells;
  std::vector<internal::CellRange> all_blocks;
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
  // Per visible triangle group (as visible_triangle_groups): its triangles that may cover a
  // pixel centre, at scratch[worker].in_front[begin .. end) when the group lies between near
  // and far, else scratch[worker].survivors[begin .. end).
  struct SurvivorRange {
    int worker = 0;
    bool in_front = false;
    uint32_t begin = 0, end = 0;
  };
  std::vector<SurvivorRange> triangle_survivors;
  std::vector<size_t> visible_split, transform_split;
  std::vector<uint8_t> group_needed;
  // Balanced projection: the grid, the heaps' capacity, and per block of internal::kCellBlock
  // vertices the offsets of its vertices in the rank order of their ids (rank_offsets[begin ..
  // end), made for rank_order_size[g] vertices of vertex group g).
  FeatureGrid grid;
  bool balanced = false;  // the last frame was ProjectBalanced's
  uint32_t heap_capacity = 0;
  uint32_t last_levels = 0;          // SelectBalanced's levels in the last balanced frame
  std::vector<RankedVertex> merged;  // SelectFromHeaps' buffers, kept between frames
  std::vector<uint32_t> merged_count;
  std::vector<uint64_t> next_rank;
  std::vector<uint8_t> rank_offsets;
  std::vector<uint32_t> rank_order_size;
  // InFront's constants, set by Prepare for each frame with occlusion.
  struct DepthRule {
    float scale_x = 1.f, scale_y = 1.f;  // image pixels to depth-buffer pixels
    float relative = 1.f, absolute = 0.f;
  } depth_rule;
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
  // Fills the per-frame lists.
  void Cull(const Pose3& world_from_camera, int pool_size);
  // Everything before the vertex test: frame constants, culling and, with occlusion, the
  // transform, the depth buffer and its 3x3 maximum.
  void Prepare(const Pose3& world_from_camera, const Camera& frame_camera, bool balanced);
  // The vertex test's depth rule (cpu_projector.h, occlusion 3) for an in-view vertex.
  bool InFront(float u, float v, float depth) const {
    const int bx = std::clamp(static_cast<int>(std::floor(u * depth_rule.scale_x)), 0,
                              depth_buffer.width() - 1);
    const int by = std::clamp(static_cast<int>(std::floor(v * depth_rule.scale_y)), 0,
                              depth_buffer.height() - 1);
    return depth <= dilated.row(by)[bx] * depth_rule.relative + depth_rule.absolute;
  }
  // Visible vertex group k (as visible_groups) lies wholly behind the 3x3 maximum of the
  // depth buffer, with the bias: none of its vertices passes InFront.
  bool GroupHidden(size_t k) const {
    const internal::ScreenBox& box = vertex_footprints[k];
    return box.bounded &&
           (box.empty() ||
            dilated.AllNearerThan(box.x0, box.x1, box.y0, box.y1, depth_rule.relative,
                                  depth_rule.absolute, static_cast<float>(box.min_depth)));
  }
  // The checks every frame starts with: a non-null `out` (cleared), a valid camera, a finite
  // pose.
  static Status CheckFrame(const char* caller, const Pose3& world_from_camera, const Camera& camera,
                           std::vector<ProjectedVertex>* out);
  // Makes vertex group g's rank order unless it is made (a worker's own groups only).
  void PrepareRankOrder(size_t g, WorkerScratch& s);
  void BalancedChunk(int worker);
  // Visits visible group k's blocks of kCellBlock vertices, each in rank order until none of
  // its other vertices can enter a heap (u, v, depth, grid cells indexed by offset in the
  // group; blocks: the groups' GridCells ranges).
  void VisitByRank(size_t k, const float* u, const float* v, const float* depth,
                   const uint16_t* grid_cells, const internal::CellRange* blocks, CellHeaps& h);
  // The balanced selection from the workers' heaps, sorted by id; false when the heaps are
  // too small for it (more whole levels than their capacity).
  bool SelectFromHeaps(int budget, std::vector<ProjectedVertex>* out);
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
  // For the in-front triangles survivors[0 .. n) (indices): RasterizeInFront's tests that do not
  // depend on the band, and the corners it draws; returns the number written to `out`.
  size_t PrepareInFront(const uint32_t* survivors, size_t n, InFrontTriangle* out) const;
  // Every corner of the group with this footprint lies between near and far: no triangle
  // needs clipping or depth checks.
  bool GroupInFront(const internal::ScreenBox& box) const {
    return box.bounded && box.min_depth >= camera.near && box.max_depth <= camera.far;
  }
  // Fills triangle_survivors for this worker's share of the visible triangle groups (found for
  // a whole group at once: MayCoverPixelCentres).
  void SelectTriangles(int worker, int num_workers);
  void TestChunk(int worker);
  // Appends the vertices of [begin, end) that pass the depth test to out[count...]; returns
  // the new count.
  size_t TestGroup(size_t begin, size_t end, ProjectedVertex* out, size_t count) const;
};

}  // namespace m2s
