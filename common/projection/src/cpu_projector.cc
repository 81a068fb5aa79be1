// CpuProjector: per-frame orchestration over the worker pool (see cpu_projector.h).
#include "m2s/common/cpu_projector.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <thread>
#include <utility>

#include "cpu_projector_impl.h"

namespace m2s {

Status ProjectorOptions::Check() const {
  if (!std::isfinite(occlusion_resolution_scale) || occlusion_resolution_scale <= 0.0 ||
      occlusion_resolution_scale > 1.0)
    return Status::Error("occlusion_resolution_scale must be in (0, 1]");
  if (!std::isfinite(occlusion_depth_bias_relative) || occlusion_depth_bias_relative < 0.0)
    return Status::Error("occlusion_depth_bias_relative must be finite and >= 0");
  if (!std::isfinite(occlusion_depth_bias_m) || occlusion_depth_bias_m < 0.0)
    return Status::Error("occlusion_depth_bias_m must be finite and >= 0");
  if (num_threads < 0 || num_threads > kMaxThreads)
    return Status::Error("num_threads must be in [0, 256] (0: hardware concurrency)");
  return Status::Ok();
}

void CpuProjector::Impl::Cull(const Pose3& world_from_camera, int pool_size) {
  const internal::FrustumCuller culler(world_from_camera, camera, kCullMarginPx);
  visible_groups.clear();
  frame_vertices = 0;
  for (uint32_t g = 0; g < vertex_groups.size(); ++g) {
    if (!culler.MayBeVisible(vertex_groups[g])) continue;
    visible_groups.push_back(g);
    frame_vertices += vertex_groups[g].end - vertex_groups[g].begin;
  }
  active_workers = static_cast<int>(std::clamp<size_t>(frame_vertices / kMinVerticesPerWorker, 1,
                                                       static_cast<size_t>(pool_size)));
  internal::SplitByCount(vertex_groups, visible_groups, active_workers, &visible_split);
  if (!options.occlusion) return;
  visible_triangle_groups.clear();
  group_needed.assign(vertex_groups.size(), 0);
  for (uint32_t g : visible_groups) group_needed[g] = 1;
  const int bw = depth_buffer.width(), bh = depth_buffer.height();
  vertex_footprints.clear();
  for (uint32_t g : visible_groups)
    vertex_footprints.push_back(culler.Footprint(vertex_groups[g], bw, bh));
  triangle_order.clear();
  for (uint32_t t = 0; t < triangle_groups.size(); ++t) {
    if (!culler.MayBeVisible(triangle_groups[t])) continue;
    const internal::ScreenBox box = culler.Footprint(triangle_groups[t], bw, bh);
    if (box.bounded && box.empty()) continue;  // covers no pixel centre of the buffer
    triangle_order.emplace_back(box.bounded ? box.min_depth : -1.0, t);
    for (uint32_t k = tri_ref_begin[t]; k < tri_ref_begin[t + 1]; ++k)
      group_needed[tri_refs[k]] = 1;
  }
  // Nearest first: the buffer then fills early and hides more of the groups behind. The
  // minimum depth does not depend on the order.
  std::sort(triangle_order.begin(), triangle_order.end());
  triangle_footprints.clear();
  for (const auto& [depth, t] : triangle_order) {
    visible_triangle_groups.push_back(t);
    triangle_footprints.push_back(culler.Footprint(triangle_groups[t], bw, bh));
  }
  transform_groups.clear();
  transformed_vertices = 0;
  for (uint32_t g = 0; g < vertex_groups.size(); ++g) {
    if (!group_needed[g]) continue;
    transform_groups.push_back(g);
    transformed_vertices += vertex_groups[g].end - vertex_groups[g].begin;
  }
  internal::SplitByCount(vertex_groups, transform_groups, active_workers, &transform_split);
}

void CpuProjector::Impl::ProjectChunk(int worker) {
  WorkerScratch& s = scratch[worker];
  size_t count = 0;
  for (size_t k = visible_split[worker]; k < visible_split[worker + 1]; ++k) {
    const internal::CullGroup& group = vertex_groups[visible_groups[k]];
    ProjectedVertex* out = ReserveOut(s, count + (group.end - group.begin));
    for (size_t block = group.begin; block < group.end; block += kBlockSize) {
      const size_t n = std::min<size_t>(kBlockSize, group.end - block);
      internal::TransformVertices(constants, x.data() + block, y.data() + block, z.data() + block,
                                  n, s.u.data(), s.v.data(), s.depth.data(), s.visible.data());
      count += internal::CompactVisible(s.u.data(), s.v.data(), s.depth.data(), s.visible.data(), n,
                                        static_cast<VertexId>(block), out + count);
    }
  }
  s.count = count;
}

void CpuProjector::Impl::TransformChunk(int worker) {
  for (size_t k = transform_split[worker]; k < transform_split[worker + 1]; ++k) {
    const internal::CullGroup& group = vertex_groups[transform_groups[k]];
    const size_t begin = group.begin, n = group.end - group.begin;
    internal::TransformVertices(constants, x.data() + begin, y.data() + begin, z.data() + begin, n,
                                all_u.data() + begin, all_v.data() + begin,
                                all_depth.data() + begin, all_visible.data() + begin);
    internal::PixelCells(all_u.data() + begin, all_v.data() + begin, n, cell_scale_x, cell_scale_y,
                         all_cells.data() + begin);
    if (balanced) {
      internal::GridCells(all_u.data() + begin, all_v.data() + begin, all_visible.data() + begin, n,
                          grid, all_grid_cells.data() + begin,
                          all_blocks.data() + begin / internal::kCellBlock);
    }
  }
}

void CpuProjector::Impl::SelectTriangles(int worker, int num_workers) {
  WorkerScratch& s = scratch[worker];
  s.survivors.clear();
  s.in_front.clear();
  const size_t groups = visible_triangle_groups.size();
  const size_t begin = groups * worker / num_workers, end = groups * (worker + 1) / num_workers;
  for (size_t k = begin; k < end; ++k) {
    const internal::ScreenBox& box = triangle_footprints[k];
    const internal::CullGroup& group = triangle_groups[visible_triangle_groups[k]];
    const size_t n = group.end - group.begin;
    if (s.keep.size() < n) s.keep.resize(n);
    const uint32_t* first = &triangles[3 * size_t{group.begin}];
    const bool in_front = GroupInFront(box);
    if (in_front) {
      internal::MayCoverPixelCentres(first, n, all_cells.data(), s.keep.data());
    } else {
      internal::MayCoverPixelCentresOrCrossNear(first, n, all_cells.data(), all_depth.data(),
                                                constants.near, s.keep.data());
    }
    const auto survivors_begin = static_cast<uint32_t>(s.survivors.size());
    s.survivors.resize(s.survivors.size() + n + 1);
    uint32_t* out = s.survivors.data() + survivors_begin;
    size_t count = 0;
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {  // most of a dense scan's triangles cover no pixel centre
      uint64_t word;
      std::memcpy(&word, s.keep.data() + i, sizeof(word));
      if (word == 0) continue;
      for (size_t j = i; j < i + 8; ++j) {
        out[count] = group.begin + static_cast<uint32_t>(j);
        count += s.keep[j];
      }
    }
    for (; i < n; ++i) {
      out[count] = group.begin + static_cast<uint32_t>(i);
      count += s.keep[i];
    }
    s.survivors.resize(survivors_begin + count);
    SurvivorRange& range = triangle_survivors[k];
    range.worker = worker;
    range.in_front = in_front;
    if (range.in_front) {  // drawn from their screen corners, found here once for all bands
      range.begin = static_cast<uint32_t>(s.in_front.size());
      s.in_front.resize(range.begin + count);
      const size_t kept = PrepareInFront(s.survivors.data() + survivors_begin, count,
                                         s.in_front.data() + range.begin);
      s.in_front.resize(range.begin + kept);
      s.survivors.resize(survivors_begin);
      range.end = static_cast<uint32_t>(s.in_front.size());
    } else {
      range.begin = survivors_begin;
      range.end = survivors_begin + static_cast<uint32_t>(count);
    }
  }
}

void CpuProjector::Impl::RasterizeBand(int band, int num_bands) {
  const int height = depth_buffer.height();
  const int row_begin = static_cast<int>(static_cast<int64_t>(height) * band / num_bands);
  const int row_end = static_cast<int>(static_cast<int64_t>(height) * (band + 1) / num_bands);
  if (row_end <= row_begin) return;
  depth_buffer.Clear(row_begin, row_end);
  Band b;
  b.row_begin = row_begin;
  b.row_end = row_end;
  b.scale_x = static_cast<double>(depth_buffer.width()) / camera.width;
  b.scale_y = static_cast<double>(height) / camera.height;
  b.near = constants.near;
  b.far = constants.far;
  b.last_row = row_end - 1;
  b.last_column = depth_buffer.width() - 1;
  for (size_t k = 0; k < visible_triangle_groups.size(); ++k) {
    const internal::ScreenBox& box = triangle_footprints[k];
    if (box.bounded) {
      // Outside the band, or behind what the band already holds: the group cannot lower
      // any depth here.
      const int y0 = std::max(box.y0, row_begin), y1 = std::min(box.y1, row_end - 1);
      if (y0 > y1 || depth_buffer.AllNearerThan(box.x0, box.x1, y0, y1, 1.f, 0.f,
                                                static_cast<float>(box.min_depth))) {
        continue;
      }
    }
    const SurvivorRange& range = triangle_survivors[k];
    if (range.in_front) {
      const InFrontTriangle* in_front = scratch[range.worker].in_front.data();
      for (uint32_t i = range.begin; i < range.end; ++i) {
        const InFrontTriangle& t = in_front[i];
        // RasterizeInFront's test of the band's rows.
        if (std::max(static_cast<double>(row_begin), t.first_row) <=
            std::min(b.last_row, t.last_row)) {
          internal::RasterizeTriangle(t.a, t.b, t.c, row_begin, row_end, &depth_buffer);
        }
      }
    } else {
      const uint32_t* survivors = scratch[range.worker].survivors.data();
      for (uint32_t i = range.begin; i < range.end; ++i) RasterizeTriangleAt(survivors[i], b);
    }
  }
}

void CpuProjector::Impl::DilateBand(int band, int num_bands) {
  const int height = depth_buffer.height();
  const int row_begin = static_cast<int>(static_cast<int64_t>(height) * band / num_bands);
  const int row_end = static_cast<int>(static_cast<int64_t>(height) * (band + 1) / num_bands);
  depth_buffer.Dilate3x3(row_begin, row_end, &dilated);
}

void CpuProjector::Impl::RasterizeTriangleAt(size_t t, const Band& band) {
  const uint32_t* idx = &triangles[3 * t];
  if (idx[0] == idx[1] && idx[1] == idx[2]) return;  // a removed part's slot
  const float z0 = all_depth[idx[0]], z1 = all_depth[idx[1]], z2 = all_depth[idx[2]];
  const int in_front = (z0 >= band.near) + (z1 >= band.near) + (z2 >= band.near);
  if (in_front == 0 || (z0 > band.far && z1 > band.far && z2 > band.far)) return;
  if (in_front == 3) {
    RasterizeInFront(idx, band);
  } else {
    Eigen::Vector3d p_camera[3];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d p(x[idx[k]], y[idx[k]], z[idx[k]]);
      p_camera[k] = camera_from_world * (p - camera_centre);
    }
    internal::ClipAndRasterizeTriangle(p_camera, camera, band.scale_x, band.scale_y, band.row_begin,
                                       band.row_end, &depth_buffer);
  }
}

// Built twice (M2S_KERNEL_CLONES): the box tests' rounding is one SSE4.1 instruction.
M2S_KERNEL_CLONES
void CpuProjector::Impl::RasterizeInFront(const uint32_t* idx, const Band& band) {
  if (internal::CoversNoPixelCentre(all_cells[idx[0]], all_cells[idx[1]], all_cells[idx[2]]))
    return;
  // A triangle whose box holds no pixel centre of the band writes nothing: rejected before
  // any edge setup, by the test RasterizeTriangle makes (on the same values).
  const float sx = static_cast<float>(band.scale_x), sy = static_cast<float>(band.scale_y);
  const float y0 = all_v[idx[0]] * sy, y1 = all_v[idx[1]] * sy, y2 = all_v[idx[2]] * sy;
  if (!(std::max(static_cast<double>(band.row_begin), std::ceil(std::min({y0, y1, y2}) - 0.5)) <=
        std::min(band.last_row, std::floor(std::max({y0, y1, y2}) - 0.5)))) {
    return;
  }
  const float x0 = all_u[idx[0]] * sx, x1 = all_u[idx[1]] * sx, x2 = all_u[idx[2]] * sx;
  if (!(std::max(0.0, std::ceil(std::min({x0, x1, x2}) - 0.5)) <=
        std::min(band.last_column, std::floor(std::max({x0, x1, x2}) - 0.5)))) {
    return;
  }
  const double z0 = all_depth[idx[0]], z1 = all_depth[idx[1]], z2 = all_depth[idx[2]];
  const RasterVertex a{x0, y0, 1.0 / z0}, b{x1, y1, 1.0 / z1}, c{x2, y2, 1.0 / z2};
  internal::RasterizeTriangle(a, b, c, band.row_begin, band.row_end, &depth_buffer);
}

// Built twice (M2S_KERNEL_CLONES), as RasterizeInFront, with the same tests on the same values.
M2S_KERNEL_CLONES
size_t CpuProjector::Impl::PrepareInFront(const uint32_t* survivors, size_t n,
                                          InFrontTriangle* out) const {
  const float sx = cell_scale_x, sy = cell_scale_y;
  const double last_row = depth_buffer.height() - 1, last_column = depth_buffer.width() - 1;
  size_t count = 0;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t* idx = &triangles[3 * size_t{survivors[i]}];
    const float y0 = all_v[idx[0]] * sy, y1 = all_v[idx[1]] * sy, y2 = all_v[idx[2]] * sy;
    const double first_row = std::ceil(std::min({y0, y1, y2}) - 0.5);
    const double end_row = std::floor(std::max({y0, y1, y2}) - 0.5);
    if (!(std::max(0.0, first_row) <= std::min(last_row, end_row))) continue;
    const float x0 = all_u[idx[0]] * sx, x1 = all_u[idx[1]] * sx, x2 = all_u[idx[2]] * sx;
    if (!(std::max(0.0, std::ceil(std::min({x0, x1, x2}) - 0.5)) <=
          std::min(last_column, std::floor(std::max({x0, x1, x2}) - 0.5)))) {
      continue;
    }
    const double z0 = all_depth[idx[0]], z1 = all_depth[idx[1]], z2 = all_depth[idx[2]];
    out[count++] = {{x0, y0, 1.0 / z0}, {x1, y1, 1.0 / z1}, {x2, y2, 1.0 / z2}, first_row, end_row};
  }
  return count;
}

void CpuProjector::Impl::TestChunk(int worker) {
  WorkerScratch& s = scratch[worker];
  size_t count = 0;
  s.tested = 0;
  for (size_t k = visible_split[worker]; k < visible_split[worker + 1]; ++k) {
    if (GroupHidden(k)) continue;
    const internal::CullGroup& group = vertex_groups[visible_groups[k]];
    ProjectedVertex* out = ReserveOut(s, count + (group.end - group.begin));
    count = TestGroup(group.begin, group.end, out, count);
    s.tested += group.end - group.begin;
  }
  s.count = count;
}

size_t CpuProjector::Impl::TestGroup(size_t begin, size_t end, ProjectedVertex* out,
                                     size_t count) const {
  // Branch-free inside (along the ids of a dense scan the test passes and fails at random):
  // each vertex is written at out[count] and counted only when in view and in front; `out`
  // has room for every vertex of the group. Eight vertices out of view are skipped at a time.
  auto test = [&](size_t i) {
    const bool in_view = all_visible[i] != 0;
    const float u = in_view ? all_u[i] : 0.f, v = in_view ? all_v[i] : 0.f;
    const bool in_front = InFront(u, v, all_depth[i]);
    out[count] = ProjectedVertex{static_cast<VertexId>(i), all_u[i], all_v[i], all_depth[i]};
    count += static_cast<size_t>(in_view & in_front);
  };
  size_t i = begin;
  for (; i + 8 <= end; i += 8) {
    uint64_t word;
    std::memcpy(&word, all_visible.data() + i, sizeof(word));
    if (word == 0) continue;
    for (size_t j = i; j < i + 8; ++j) test(j);
  }
  for (; i < end; ++i) test(i);
  return count;
}

void CpuProjector::Impl::Prepare(const Pose3& world_from_camera, const Camera& frame_camera,
                                 bool balanced) {
  constants = internal::MakeFrameConstants(world_from_camera, frame_camera);
  camera = frame_camera;
  camera_from_world = world_from_camera.RotationMatrix().transpose();
  camera_centre = world_from_camera.translation();
  const int pool_size = pool->size();
  if (options.occlusion) {
    const double s = options.occlusion_resolution_scale;
    const int bw = std::max(1, static_cast<int>(std::lround(camera.width * s)));
    const int bh = std::max(1, static_cast<int>(std::lround(camera.height * s)));
    depth_buffer.Resize(bw, bh);
    cell_scale_x = static_cast<float>(static_cast<double>(bw) / camera.width);
    cell_scale_y = static_cast<float>(static_cast<double>(bh) / camera.height);
    dilated.Resize(bw, bh);
    depth_rule.scale_x = static_cast<float>(bw) / static_cast<float>(camera.width);
    depth_rule.scale_y = static_cast<float>(bh) / static_cast<float>(camera.height);
    depth_rule.relative = 1.f + static_cast<float>(options.occlusion_depth_bias_relative);
    depth_rule.absolute = static_cast<float>(options.occlusion_depth_bias_m);
  }
  Cull(world_from_camera, pool_size);
  if (!options.occlusion) return;
  auto transform = [this](int worker) {
    if (worker < active_workers) TransformChunk(worker);
  };
  pool->Run(transform);
  // The triangles that may cover a pixel centre, found once per group (groups split among the
  // workers), then drawn by bands of rows (each pixel written by one worker).
  triangle_survivors.resize(visible_triangle_groups.size());
  auto select = [this, pool_size](int worker) { SelectTriangles(worker, pool_size); };
  pool->Run(select);
  auto rasterize = [this, pool_size](int worker) { RasterizeBand(worker, pool_size); };
  pool->Run(rasterize);
  auto dilate = [this, pool_size](int worker) { DilateBand(worker, pool_size); };
  pool->Run(dilate);
}

CpuProjector::CpuProjector(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
CpuProjector::~CpuProjector() = default;

size_t CpuProjector::num_vertices() const { return impl_->num_vertices; }
size_t CpuProjector::last_vertices_tested() const {
  if (!impl_->options.occlusion && !impl_->balanced) return impl_->frame_vertices;
  size_t tested = 0;
  for (int w = 0; w < impl_->active_workers; ++w) tested += impl_->scratch[w].tested;
  return tested;
}
int CpuProjector::num_threads() const { return impl_->pool->size(); }
size_t CpuProjector::last_vertices_considered() const {
  return impl_->options.occlusion ? impl_->transformed_vertices : impl_->frame_vertices;
}

Expected<std::unique_ptr<CpuProjector>> CpuProjector::Create(const Scene& scene,
                                                             const ProjectorOptions& options) {
  if (Status s = options.Check(); !s) return s;
  const size_t n = scene.positions.size();
  if (n >= std::numeric_limits<VertexId>::max()) {
    return Expected<std::unique_ptr<CpuProjector>>::Error(
        "scene has too many vertices for 32-bit ids");
  }
  if (scene.triangles.size() % 3 != 0) {
    return Expected<std::unique_ptr<CpuProjector>>::Error(
        "scene triangle index count is not a multiple of 3");
  }
  for (uint32_t index : scene.triangles) {
    if (index >= n) {
      return Expected<std::unique_ptr<CpuProjector>>::Error(
          "scene triangle index " + std::to_string(index) + " out of range (" + std::to_string(n) +
          " vertices)");
    }
  }
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->num_vertices = n;
  impl->x.resize(n);
  impl->y.resize(n);
  impl->z.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f& p = scene.positions[i];
    if (!p.allFinite()) {
      return Expected<std::unique_ptr<CpuProjector>>::Error("scene vertex " + std::to_string(i) +
                                                            " has a non-finite position");
    }
    impl->x[i] = p.x();
    impl->y[i] = p.y();
    impl->z[i] = p.z();
  }
  for (VertexId id : scene.retired_ids) {
    if (id >= n) {
      return Expected<std::unique_ptr<CpuProjector>>::Error("scene retired id " +
                                                            std::to_string(id) + " out of range");
    }
    impl->Retire(id);
  }
  int threads = options.num_threads;
  if (threads == 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  impl->pool = std::make_unique<WorkerPool>(threads);
  impl->scratch.resize(threads);
  for (Impl::WorkerScratch& s : impl->scratch) {
    s.u.resize(kBlockSize);
    s.v.resize(kBlockSize);
    s.depth.resize(kBlockSize);
    s.visible.resize(kBlockSize);
  }
  impl->vertex_groups = internal::MakeVertexGroups(impl->x.data(), impl->y.data(), impl->z.data(),
                                                   n, kVertexGroupSize);
  if (options.occlusion) {
    impl->triangles = scene.triangles;
    impl->triangle_groups = internal::MakeTriangleGroups(
        impl->triangles, impl->x.data(), impl->y.data(), impl->z.data(), kTriangleGroupSize);
    impl->TriangleGroupRefs();
    impl->all_u.resize(n);
    impl->all_v.resize(n);
    impl->all_depth.resize(n);
    impl->all_visible.resize(n);
    impl->all_cells.resize(n);
  }
  return std::unique_ptr<CpuProjector>(new CpuProjector(std::move(impl)));
}

Status CpuProjector::Impl::CheckFrame(const char* caller, const Pose3& world_from_camera,
                                      const Camera& camera, std::vector<ProjectedVertex>* out) {
  if (out == nullptr) return Status::Error(std::string(caller) + ": null output");
  out->clear();
  if (Status s = camera.Check(); !s) return s;
  if (!world_from_camera.AllFinite()) return Status::Error("camera pose is not finite");
  return Status::Ok();
}

Status CpuProjector::Project(const Pose3& world_from_camera, const Camera& camera,
                             std::vector<ProjectedVertex>* out) {
  if (Status s = Impl::CheckFrame("CpuProjector::Project", world_from_camera, camera, out); !s)
    return s;

  Impl& m = *impl_;
  m.balanced = false;
  m.Prepare(world_from_camera, camera, /*balanced=*/false);
  if (!m.options.occlusion) {
    auto project = [&m](int worker) {
      if (worker < m.active_workers) m.ProjectChunk(worker);
    };
    m.pool->Run(project);
  } else {
    auto test = [&m](int worker) {
      if (worker < m.active_workers) m.TestChunk(worker);
    };
    m.pool->Run(test);
  }
  size_t total = 0;
  for (int w = 0; w < m.active_workers; ++w) total += m.scratch[w].count;
  if (out->capacity() < total) out->reserve(total);
  for (int w = 0; w < m.active_workers; ++w) {
    const std::vector<ProjectedVertex>& part = m.scratch[w].out;
    out->insert(out->end(), part.begin(),
                part.begin() + static_cast<ptrdiff_t>(m.scratch[w].count));
  }
  return Status::Ok();
}

}  // namespace m2s
