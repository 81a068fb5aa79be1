// CpuProjector::ProjectBalanced: the balanced selection of a frame without testing every
// visible vertex.
//
// SelectBalanced keeps, per grid cell, the `levels` lowest-ranked features (and the next one
// of some cells). Here every worker keeps, per cell, a max-heap of the `capacity` lowest-ranked
// visible vertices it found and the number it found. A vertex group is visited by blocks of
// kCellBlock consecutive ids (a compact piece of surface), each in the rank order of its ids,
// so the heaps soon hold low ranks: an in-view vertex whose cell's heap is full with lower
// ranks is passed over before its depth test, and once every cell the block's visible
// vertices fall in (GridCells' range) holds such a heap, with ranks below the next vertex's,
// the rest of the block is left. Neither skip can change a heap, and both happen only in full
// cells, so a cell whose heap is not full has an exact count; a full one has at least
// `capacity` visible vertices. That is all the selection needs when levels < capacity;
// otherwise the frame is tested again with a larger capacity (a view whose features gather in
// a few cells).
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "cpu_projector_impl.h"

namespace m2s {
namespace {

constexpr uint64_t kNoBound = std::numeric_limits<uint64_t>::max();
// The heaps' largest ranks over a group's box are read at its start and after 32, 64, 128,
// ... of its vertices (a stale bound only visits more vertices, at most twice as many).
constexpr size_t kFirstBoundCheck = 32;

}  // namespace

void CpuProjector::Impl::PrepareRankOrder(size_t g, WorkerScratch& s) {
  const uint32_t begin = static_cast<uint32_t>(g * kVertexGroupSize);
  const uint32_t end = static_cast<uint32_t>(std::min(num_vertices, begin + kVertexGroupSize));
  if (rank_order_size[g] == end - begin) return;
  for (uint32_t block = begin; block < end; block += internal::kCellBlock) {
    const uint32_t block_end = std::min<uint32_t>(end, block + internal::kCellBlock);
    s.ranked.clear();
    for (uint32_t i = block; i < block_end; ++i)
      s.ranked.emplace_back(FeatureRank(i), static_cast<uint8_t>(i - block));
    std::sort(s.ranked.begin(), s.ranked.end());
    for (size_t k = 0; k < s.ranked.size(); ++k) rank_offsets[block + k] = s.ranked[k].second;
  }
  rank_order_size[g] = end - begin;
}

uint64_t CpuProjector::Impl::CellHeaps::Bound(const internal::CellRange& box) const {
  uint64_t bound = 0;
  for (int cy = box.y0; cy <= box.y1; ++cy) {
    for (int cx = box.x0; cx <= box.x1; ++cx)
      bound = std::max(bound, top[static_cast<size_t>(cy) * static_cast<size_t>(cols) + cx]);
  }
  return bound;
}

void CpuProjector::Impl::CellHeaps::Add(size_t c, uint32_t capacity, uint64_t rank,
                                        const ProjectedVertex& vertex) {
  ++count[c];
  RankedVertex* heap = entries.data() + c * capacity;
  if (filled[c] < capacity) {
    heap[filled[c]++] = {rank, vertex};
    std::push_heap(heap, heap + filled[c]);
    if (filled[c] == capacity) top[c] = heap[0].rank;
  } else if (rank < heap[0].rank) {
    std::pop_heap(heap, heap + capacity);
    heap[capacity - 1] = {rank, vertex};
    std::push_heap(heap, heap + capacity);
    top[c] = heap[0].rank;
  }
}

// Built twice (M2S_KERNEL_CLONES): InFront's floors are SSE4.1 instructions.
M2S_KERNEL_CLONES
void CpuProjector::Impl::VisitByRank(size_t k, const float* u, const float* v, const float* depth,
                                     const uint16_t* grid_cells, const internal::CellRange* blocks,
                                     CellHeaps& h) {
  const internal::CullGroup& group = vertex_groups[visible_groups[k]];
  const size_t n = group.end - group.begin;
  for (size_t block = 0; block < n; block += internal::kCellBlock) {
    const internal::CellRange& cells = blocks[block / internal::kCellBlock];
    if (cells.empty()) continue;  // nothing of the block in view
    const uint8_t* order = rank_offsets.data() + group.begin + block;
    const size_t m = std::min(internal::kCellBlock, n - block);
    uint64_t bound = h.Bound(cells);
    size_t next_check = kFirstBoundCheck;
    for (size_t j = 0; j < m; ++j) {
      if (j == next_check) {  // at doubling intervals: the heaps fill as the block is visited
        bound = h.Bound(cells);
        next_check *= 2;
      }
      const size_t offset = block + order[j];
      const auto id = static_cast<VertexId>(group.begin + offset);
      const uint64_t rank = FeatureRank(id);
      if (rank > bound) break;  // ranks ascend: no later vertex can enter a heap of its cells
      const uint16_t c = grid_cells[offset];
      // Out of view, or a full heap it cannot enter (the cell's count is already capped,
      // nothing to record).
      if (c == internal::kNotInView || rank > h.top[c]) continue;
      ++h.visited;
      if (options.occlusion && !InFront(u[offset], v[offset], depth[offset])) continue;
      h.Add(c, heap_capacity, rank, ProjectedVertex{id, u[offset], v[offset], depth[offset]});
    }
  }
}

void CpuProjector::Impl::BalancedChunk(int worker) {
  WorkerScratch& s = scratch[worker];
  CellHeaps& h = s.heaps;
  const auto cells = static_cast<size_t>(grid.num_cells());
  h.cols = grid.cols;
  h.entries.resize(cells * heap_capacity);
  h.filled.assign(cells, 0);
  h.count.assign(cells, 0);
  h.top.assign(cells, kNoBound);
  h.visited = 0;
  s.tested = 0;
  for (size_t k = visible_split[worker]; k < visible_split[worker + 1]; ++k) {
    const internal::CullGroup& group = vertex_groups[visible_groups[k]];
    const size_t begin = group.begin, n = group.end - group.begin;
    if (options.occlusion && GroupHidden(k)) continue;
    PrepareRankOrder(visible_groups[k], s);
    if (options.occlusion) {
      const size_t before = h.visited;
      VisitByRank(k, all_u.data() + begin, all_v.data() + begin, all_depth.data() + begin,
                  all_grid_cells.data() + begin, all_blocks.data() + begin / internal::kCellBlock,
                  h);
      s.tested += h.visited - before;
    } else {
      if (s.group_u.size() < kVertexGroupSize) {
        s.group_u.resize(kVertexGroupSize);
        s.group_v.resize(kVertexGroupSize);
        s.group_depth.resize(kVertexGroupSize);
        s.group_visible.resize(kVertexGroupSize);
        s.group_grid_cells.resize(kVertexGroupSize);
        s.group_blocks.resize(kVertexGroupSize / internal::kCellBlock);
      }
      internal::TransformVertices(constants, x.data() + begin, y.data() + begin, z.data() + begin,
                                  n, s.group_u.data(), s.group_v.data(), s.group_depth.data(),
                                  s.group_visible.data());
      internal::GridCells(s.group_u.data(), s.group_v.data(), s.group_visible.data(), n, grid,
                          s.group_grid_cells.data(), s.group_blocks.data());
      const size_t before = h.visited;
      VisitByRank(k, s.group_u.data(), s.group_v.data(), s.group_depth.data(),
                  s.group_grid_cells.data(), s.group_blocks.data(), h);
      s.tested += h.visited - before;
    }
  }
}

bool CpuProjector::Impl::SelectFromHeaps(int budget, std::vector<ProjectedVertex>* out) {
  const auto cells = static_cast<size_t>(grid.num_cells());
  // Per cell: the workers' heaps merged and sorted by rank, the lowest `capacity` of them
  // kept (at merged[c * stride ...]), and the count (capped at `capacity` where some worker
  // may have left groups early).
  const size_t stride = static_cast<size_t>(active_workers) * heap_capacity;
  merged.resize(cells * stride);
  merged_count.assign(cells, 0);
  bool all_exact = true;
  size_t total = 0;
  for (size_t c = 0; c < cells; ++c) {
    RankedVertex* lowest = merged.data() + c * stride;
    size_t size = 0, sum = 0;
    bool capped = false;
    for (int w = 0; w < active_workers; ++w) {
      const CellHeaps& h = scratch[w].heaps;
      const RankedVertex* heap = h.entries.data() + c * heap_capacity;
      std::copy(heap, heap + h.filled[c], lowest + size);
      size += h.filled[c];
      sum += h.count[c];
      capped = capped || h.filled[c] == heap_capacity;
    }
    std::sort(lowest, lowest + size);
    capped = capped || sum >= heap_capacity;
    all_exact = all_exact && !capped;
    merged_count[c] = capped ? heap_capacity : static_cast<uint32_t>(sum);
    total += merged_count[c];
  }
  out->clear();
  if (all_exact && total <= static_cast<size_t>(budget)) {  // SelectBalanced keeps everything
    last_levels = 0;
    for (size_t c = 0; c < cells; ++c) {
      for (uint32_t k = 0; k < merged_count[c]; ++k) out->push_back(merged[c * stride + k].vertex);
    }
  } else {
    // Exact while the levels stay below the heaps' capacity.
    const uint32_t levels = BalancedLevels(merged_count, budget);
    if (levels >= heap_capacity) return false;  // more levels than the heaps hold
    last_levels = levels;
    next_rank.assign(cells, 0);
    for (size_t c = 0; c < cells; ++c) {
      if (merged_count[c] > levels) next_rank[c] = merged[c * stride + levels].rank;
    }
    const std::vector<uint32_t> take = BalancedTakes(merged_count, levels, budget, next_rank);
    for (size_t c = 0; c < cells; ++c) {
      for (uint32_t k = 0; k < take[c]; ++k) out->push_back(merged[c * stride + k].vertex);
    }
  }
  std::sort(out->begin(), out->end(),
            [](const ProjectedVertex& a, const ProjectedVertex& b) { return a.id < b.id; });
  return true;
}

Status CpuProjector::ProjectBalanced(const Pose3& world_from_camera, const Camera& camera,
                                     const FeatureGrid& grid, int budget,
                                     std::vector<ProjectedVertex>* out) {
  if (budget <= 0) return Projector::ProjectBalanced(world_from_camera, camera, grid, budget, out);
  if (Status s = Impl::CheckFrame("CpuProjector::ProjectBalanced", world_from_camera, camera, out);
      !s) {
    return s;
  }
  // Grid cells are 16-bit, one value kept for "not in view".
  if (grid.num_cells() >= internal::kNotInView)
    return Projector::ProjectBalanced(world_from_camera, camera, grid, budget, out);
  Impl& m = *impl_;
  m.grid = grid;
  m.balanced = true;
  if (m.options.occlusion && m.all_grid_cells.size() < m.num_vertices) {
    m.all_grid_cells.resize(m.num_vertices);
    m.all_blocks.resize((m.num_vertices + internal::kCellBlock - 1) / internal::kCellBlock);
  }
  // The rank order of each group is made when the group is first visited.
  if (m.rank_offsets.size() < m.num_vertices) m.rank_offsets.resize(m.num_vertices);
  m.rank_order_size.resize(m.vertex_groups.size(), 0);
  m.Prepare(world_from_camera, camera, /*balanced=*/true);
  // Twice the cells' share of the budget (a view that fills half the image fits at once), or
  // half as much again as the last frame's levels: consecutive views need about as many, and
  // a capacity that is too small costs the frame a second visit.
  const uint32_t share = static_cast<uint32_t>(std::max(4, 2 * budget / grid.num_cells() + 2));
  m.heap_capacity = std::max(share, std::min<uint32_t>(m.last_levels + m.last_levels / 2 + 2,
                                                       static_cast<uint32_t>(budget) + 1));
  for (;;) {
    auto visit = [&m](int worker) {
      if (worker < m.active_workers) m.BalancedChunk(worker);
    };
    m.pool->Run(visit);
    if (m.SelectFromHeaps(budget, out)) return Status::Ok();
    m.heap_capacity = std::min<uint32_t>(4 * m.heap_capacity, static_cast<uint32_t>(budget) + 1);
  }
}

}  // namespace m2s
