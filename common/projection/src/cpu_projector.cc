// CpuProjector: per-frame orchestration over the worker pool (see cpu_projector.h).
#include "m2s/common/cpu_projector.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <thread>

#include "cpu_projector_internal.h"

namespace m2s {

using internal::AlignedVector;
using internal::DepthBuffer;
using internal::FrameConstants;
using internal::RasterVertex;
using internal::WorkerPool;

namespace {

// Vertices processed per kernel call: the block's outputs stay in L1 before compaction.
constexpr size_t kBlockSize = 1024;
// Below this many vertices per worker, waking another thread costs more than it saves.
constexpr size_t kMinVerticesPerWorker = 32768;
// Culling groups: vertices (a multiple of kBlockSize, so groups start on cache lines) and
// triangles per group.
constexpr size_t kVertexGroupSize = 4 * kBlockSize;
constexpr size_t kTriangleGroupSize = 4096;
// The frustum test's margin around the image (pixels): far above the kernel's float rounding.
constexpr double kCullMarginPx = 2.0;
constexpr int kMaxThreads = 256;

}  // namespace

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

struct CpuProjector::Impl {
  struct WorkerScratch {
    AlignedVector<float> u, v, depth;
    AlignedVector<uint8_t> visible;
    std::vector<ProjectedVertex> out;  // grows to the chunk size + 1, never shrinks
    size_t count = 0;
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
  DepthBuffer depth_buffer;

  // Culling groups (cpu_projector_internal.h) and, per triangle group, the vertex groups its
  // corners belong to.
  std::vector<internal::CullGroup> vertex_groups, triangle_groups;
  std::vector<std::vector<uint32_t>> tri_refs;
  std::vector<uint32_t> last_seen;  // scratch of TriangleGroupRefs

  // Per-frame state read by the workers.
  FrameConstants constants{};
  Camera camera;
  Eigen::Matrix3d camera_from_world = Eigen::Matrix3d::Identity();
  Eigen::Vector3d camera_centre = Eigen::Vector3d::Zero();
  int active_workers = 1;
  // Vertex groups that may be seen, and (with occlusion) those to transform: the seen ones
  // and every group a seen triangle uses; worker w takes list[split[w] .. split[w + 1]).
  std::vector<uint32_t> visible_groups, transform_groups, visible_triangle_groups;
  std::vector<size_t> visible_split, transform_split;
  std::vector<uint8_t> group_needed;
  size_t frame_vertices = 0;        // vertices in the visible groups
  size_t transformed_vertices = 0;  // with occlusion: in the groups transformed

  // The vertex groups triangle group t uses (marks, not a sort: 12288 corners a group).
  void TriangleGroupRefs(uint32_t t) {
    last_seen.resize(vertex_groups.size(), ~uint32_t{0});
    const internal::CullGroup& group = triangle_groups[t];
    std::vector<uint32_t>& refs = tri_refs[t];
    refs.clear();
    for (size_t i = 3 * size_t{group.begin}; i < 3 * size_t{group.end}; ++i) {
      const auto g = static_cast<uint32_t>(triangles[i] / kVertexGroupSize);
      if (last_seen[g] == t) continue;
      last_seen[g] = t;
      refs.push_back(g);
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
  // One band of depth-buffer rows and the constants of its triangle loop.
  struct Band {
    int row_begin = 0, row_end = 0;
    double scale_x = 1, scale_y = 1;  // image pixels -> buffer pixels
    float near = 0, far = 0;
    float top = 0, bottom = 0, right = 0;  // float rejection limits, a pixel of margin
  };
  void RasterizeTriangleAt(size_t t, const Band& band);
  void TestChunk(int worker);
  // Appends the vertices of [begin, end) that pass the depth test to out[count...]; returns
  // the new count.
  size_t TestGroup(size_t begin, size_t end, ProjectedVertex* out, size_t count) const;
};

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
  for (uint32_t t = 0; t < triangle_groups.size(); ++t) {
    if (!culler.MayBeVisible(triangle_groups[t])) continue;
    visible_triangle_groups.push_back(t);
    for (uint32_t g : tri_refs[t]) group_needed[g] = 1;
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
  b.top = static_cast<float>(row_begin) - 1.f;
  b.bottom = static_cast<float>(row_end) + 1.f;
  b.right = static_cast<float>(depth_buffer.width()) + 1.f;
  for (uint32_t group : visible_triangle_groups) {
    for (size_t t = triangle_groups[group].begin; t < triangle_groups[group].end; ++t) {
      RasterizeTriangleAt(t, b);
    }
  }
}

void CpuProjector::Impl::RasterizeTriangleAt(size_t t, const Band& band) {
  const uint32_t* idx = &triangles[3 * t];
  if (idx[0] == idx[1] && idx[1] == idx[2]) return;  // a removed part's slot
  const float z0 = all_depth[idx[0]], z1 = all_depth[idx[1]], z2 = all_depth[idx[2]];
  const int in_front = (z0 >= band.near) + (z1 >= band.near) + (z2 >= band.near);
  if (in_front == 0 || (z0 > band.far && z1 > band.far && z2 > band.far)) return;
  if (in_front == 3) {
    // Cheap rejection in float against the band, with a pixel of margin.
    const float sx = static_cast<float>(band.scale_x), sy = static_cast<float>(band.scale_y);
    const float y0 = all_v[idx[0]] * sy, y1 = all_v[idx[1]] * sy, y2 = all_v[idx[2]] * sy;
    if (std::max({y0, y1, y2}) < band.top || std::min({y0, y1, y2}) > band.bottom) return;
    const float x0 = all_u[idx[0]] * sx, x1 = all_u[idx[1]] * sx, x2 = all_u[idx[2]] * sx;
    if (std::max({x0, x1, x2}) < -1.f || std::min({x0, x1, x2}) > band.right) return;
    const RasterVertex a{x0, y0, 1.0 / z0}, b{x1, y1, 1.0 / z1}, c{x2, y2, 1.0 / z2};
    internal::RasterizeTriangle(a, b, c, band.row_begin, band.row_end, &depth_buffer);
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

void CpuProjector::Impl::TestChunk(int worker) {
  WorkerScratch& s = scratch[worker];
  size_t count = 0;
  for (size_t k = visible_split[worker]; k < visible_split[worker + 1]; ++k) {
    const internal::CullGroup& group = vertex_groups[visible_groups[k]];
    ProjectedVertex* out = ReserveOut(s, count + (group.end - group.begin));
    count = TestGroup(group.begin, group.end, out, count);
  }
  s.count = count;
}

size_t CpuProjector::Impl::TestGroup(size_t begin, size_t end, ProjectedVertex* out,
                                     size_t count) const {
  const float scale_x = static_cast<float>(depth_buffer.width()) / static_cast<float>(camera.width);
  const float scale_y =
      static_cast<float>(depth_buffer.height()) / static_cast<float>(camera.height);
  const float relative = 1.f + static_cast<float>(options.occlusion_depth_bias_relative);
  const float absolute = static_cast<float>(options.occlusion_depth_bias_m);
  const int max_x = depth_buffer.width() - 1, max_y = depth_buffer.height() - 1;
  for (size_t i = begin; i < end; ++i) {
    if (!all_visible[i]) continue;
    const int bx = std::clamp(static_cast<int>(std::floor(all_u[i] * scale_x)), 0, max_x);
    const int by = std::clamp(static_cast<int>(std::floor(all_v[i] * scale_y)), 0, max_y);
    const float nearest = depth_buffer.Max3x3(bx, by);
    if (all_depth[i] <= nearest * relative + absolute) {
      out[count++] = ProjectedVertex{static_cast<VertexId>(i), all_u[i], all_v[i], all_depth[i]};
    }
  }
  return count;
}

CpuProjector::CpuProjector(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
CpuProjector::~CpuProjector() = default;

size_t CpuProjector::num_vertices() const { return impl_->num_vertices; }
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
    impl->tri_refs.resize(impl->triangle_groups.size());
    for (uint32_t t = 0; t < impl->triangle_groups.size(); ++t) impl->TriangleGroupRefs(t);
    impl->all_u.resize(n);
    impl->all_v.resize(n);
    impl->all_depth.resize(n);
    impl->all_visible.resize(n);
  }
  return std::unique_ptr<CpuProjector>(new CpuProjector(std::move(impl)));
}

void CpuProjector::Impl::ReboxVertices(const std::vector<VertexId>& ids, VertexId first,
                                       VertexId end) {
  std::vector<uint32_t> touched;
  for (VertexId id : ids) touched.push_back(static_cast<uint32_t>(id / kVertexGroupSize));
  for (size_t g = first / kVertexGroupSize; g * kVertexGroupSize < end; ++g)
    touched.push_back(static_cast<uint32_t>(g));
  std::sort(touched.begin(), touched.end());
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  while (vertex_groups.size() * kVertexGroupSize < num_vertices) vertex_groups.emplace_back();
  for (uint32_t g : touched) {
    const auto begin = static_cast<uint32_t>(g * kVertexGroupSize);
    const auto group_end = static_cast<uint32_t>(std::min(num_vertices, begin + kVertexGroupSize));
    vertex_groups[g] = internal::BoxVertices(x.data(), y.data(), z.data(), begin, group_end);
  }
}

Status CpuProjector::ApplyChange(const Scene& scene, const SceneChange& change) {
  Impl& m = *impl_;
  const size_t n = scene.positions.size();
  const size_t num_triangles = scene.triangles.size() / 3;
  auto out_of_range = [n](const std::vector<VertexId>& ids) {
    return std::any_of(ids.begin(), ids.end(), [n](VertexId id) { return id >= n; });
  };
  if (n < m.num_vertices || n >= std::numeric_limits<VertexId>::max() ||
      (change.first_new_id < change.end_new_id
           ? change.first_new_id != m.num_vertices || change.end_new_id != n
           : n != m.num_vertices) ||
      out_of_range(change.moved_ids) || out_of_range(change.retired_ids) ||
      scene.triangles.size() % 3 != 0 || change.end_triangle > num_triangles ||
      change.first_triangle > change.end_triangle) {
    return Status::Error(
        "CpuProjector::ApplyChange: the change does not follow the projector's scene (apply "
        "every change, in order, with the edited scene)");
  }
  const size_t old_n = m.num_vertices;
  m.num_vertices = n;
  m.x.resize(n);
  m.y.resize(n);
  m.z.resize(n);
  auto copy = [&m, &scene](size_t id) {
    const Eigen::Vector3f& p = scene.positions[id];
    m.x[id] = p.x();
    m.y[id] = p.y();
    m.z[id] = p.z();
  };
  for (size_t id = old_n; id < n; ++id) copy(id);
  for (VertexId id : change.moved_ids) copy(id);
  for (VertexId id : change.retired_ids) m.Retire(id);
  std::vector<VertexId> touched = change.moved_ids;
  touched.insert(touched.end(), change.retired_ids.begin(), change.retired_ids.end());
  m.ReboxVertices(touched, static_cast<VertexId>(old_n), static_cast<VertexId>(n));
  if (!m.options.occlusion) return Status::Ok();

  m.all_u.resize(n);
  m.all_v.resize(n);
  m.all_depth.resize(n);
  m.all_visible.resize(n);
  m.triangles.resize(scene.triangles.size());
  std::copy(scene.triangles.begin() + 3 * ptrdiff_t{change.first_triangle},
            scene.triangles.begin() + 3 * ptrdiff_t{change.end_triangle},
            m.triangles.begin() + 3 * ptrdiff_t{change.first_triangle});
  while (m.triangle_groups.size() * kTriangleGroupSize < num_triangles) {
    m.triangle_groups.emplace_back();
    m.tri_refs.emplace_back();
  }
  m.last_seen.assign(m.vertex_groups.size(), ~uint32_t{0});
  for (size_t t = change.first_triangle / kTriangleGroupSize;
       t * kTriangleGroupSize < change.end_triangle; ++t) {
    const auto begin = static_cast<uint32_t>(t * kTriangleGroupSize);
    const auto end = static_cast<uint32_t>(std::min(num_triangles, begin + kTriangleGroupSize));
    m.triangle_groups[t] =
        internal::BoxTriangles(m.triangles, m.x.data(), m.y.data(), m.z.data(), begin, end);
    m.TriangleGroupRefs(static_cast<uint32_t>(t));
  }
  return Status::Ok();
}

Status CpuProjector::Project(const Pose3& world_from_camera, const Camera& camera,
                             std::vector<ProjectedVertex>* out) {
  if (out == nullptr) return Status::Error("CpuProjector::Project: null output");
  out->clear();
  if (Status s = camera.Check(); !s) return s;
  if (!world_from_camera.AllFinite()) return Status::Error("camera pose is not finite");

  Impl& m = *impl_;
  m.constants = internal::MakeFrameConstants(world_from_camera, camera);
  m.camera = camera;
  m.camera_from_world = world_from_camera.RotationMatrix().transpose();
  m.camera_centre = world_from_camera.translation();
  const int pool_size = m.pool->size();
  m.Cull(world_from_camera, pool_size);

  if (!m.options.occlusion) {
    auto project = [&m](int worker) {
      if (worker < m.active_workers) m.ProjectChunk(worker);
    };
    m.pool->Run(project);
  } else {
    const double s = m.options.occlusion_resolution_scale;
    m.depth_buffer.Resize(std::max(1, static_cast<int>(std::lround(camera.width * s))),
                          std::max(1, static_cast<int>(std::lround(camera.height * s))));
    auto transform = [&m](int worker) {
      if (worker < m.active_workers) m.TransformChunk(worker);
    };
    m.pool->Run(transform);
    auto rasterize = [&m, pool_size](int worker) { m.RasterizeBand(worker, pool_size); };
    m.pool->Run(rasterize);
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
