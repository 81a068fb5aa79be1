// CpuProjector::ApplyChange: follows a SceneEditor's changes (moved, retired, added parts).
#include <algorithm>
#include <limits>
#include <vector>

#include "cpu_projector_impl.h"

namespace m2s {

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
  m.all_cells.resize(n);
  m.triangles.resize(scene.triangles.size());
  std::copy(scene.triangles.begin() + 3 * ptrdiff_t{change.first_triangle},
            scene.triangles.begin() + 3 * ptrdiff_t{change.end_triangle},
            m.triangles.begin() + 3 * ptrdiff_t{change.first_triangle});
  while (m.triangle_groups.size() * kTriangleGroupSize < num_triangles)
    m.triangle_groups.emplace_back();
  for (size_t t = change.first_triangle / kTriangleGroupSize;
       t * kTriangleGroupSize < change.end_triangle; ++t) {
    const auto begin = static_cast<uint32_t>(t * kTriangleGroupSize);
    const auto end = static_cast<uint32_t>(std::min(num_triangles, begin + kTriangleGroupSize));
    m.triangle_groups[t] =
        internal::BoxTriangles(m.triangles, m.x.data(), m.y.data(), m.z.data(), begin, end);
  }
  m.TriangleGroupRefs();
  return Status::Ok();
}

}  // namespace m2s
