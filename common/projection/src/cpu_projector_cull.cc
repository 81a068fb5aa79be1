// CpuProjector culling: vertex and triangle groups with bounding boxes, the frustum test.
#include <algorithm>
#include <cmath>

#include "cpu_projector_internal.h"

namespace m2s::internal {
namespace {

CullGroup BoxOf(uint32_t begin, uint32_t end) {
  CullGroup group;
  group.begin = begin;
  group.end = end;
  group.min.setConstant(std::numeric_limits<float>::infinity());
  group.max.setConstant(-std::numeric_limits<float>::infinity());
  return group;
}

void Extend(CullGroup* group, float x, float y, float z) {
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) return;
  group->min = group->min.cwiseMin(Eigen::Vector3f(x, y, z));
  group->max = group->max.cwiseMax(Eigen::Vector3f(x, y, z));
}

}  // namespace

CullGroup BoxVertices(const float* x, const float* y, const float* z, uint32_t begin,
                      uint32_t end) {
  CullGroup group = BoxOf(begin, end);
  for (size_t i = begin; i < end; ++i) Extend(&group, x[i], y[i], z[i]);
  return group;
}

CullGroup BoxTriangles(const std::vector<uint32_t>& triangles, const float* x, const float* y,
                       const float* z, uint32_t begin, uint32_t end) {
  CullGroup group = BoxOf(begin, end);
  for (size_t i = 3 * size_t{begin}; i < 3 * size_t{end}; ++i) {
    const uint32_t v = triangles[i];
    Extend(&group, x[v], y[v], z[v]);
  }
  return group;
}

std::vector<CullGroup> MakeVertexGroups(const float* x, const float* y, const float* z, size_t n,
                                        size_t group_size) {
  std::vector<CullGroup> groups;
  for (size_t begin = 0; begin < n; begin += group_size) {
    const size_t end = std::min(n, begin + group_size);
    groups.push_back(
        BoxVertices(x, y, z, static_cast<uint32_t>(begin), static_cast<uint32_t>(end)));
  }
  return groups;
}

std::vector<CullGroup> MakeTriangleGroups(const std::vector<uint32_t>& triangles, const float* x,
                                          const float* y, const float* z, size_t group_size) {
  std::vector<CullGroup> groups;
  const size_t n = triangles.size() / 3;
  for (size_t begin = 0; begin < n; begin += group_size) {
    const size_t end = std::min(n, begin + group_size);
    groups.push_back(
        BoxTriangles(triangles, x, y, z, static_cast<uint32_t>(begin), static_cast<uint32_t>(end)));
  }
  return groups;
}

FrustumCuller::FrustumCuller(const Pose3& world_from_camera, const Camera& camera, double margin_px)
    : camera_from_world_(world_from_camera.RotationMatrix().transpose()),
      centre_(world_from_camera.translation()) {
  // u >= -m  <=>  fx X + (cx + m) Z >= 0 for Z > 0; likewise the other sides. Near and far
  // with a relative margin.
  const double m = margin_px;
  planes_[0] = {camera.fx, 0, camera.cx + m, 0};
  planes_[1] = {-camera.fx, 0, camera.width + m - camera.cx, 0};
  planes_[2] = {0, camera.fy, camera.cy + m, 0};
  planes_[3] = {0, -camera.fy, camera.height + m - camera.cy, 0};
  planes_[4] = {0, 0, 1, -camera.near * (1 - 1e-4)};
  planes_[5] = {0, 0, -1, camera.far * (1 + 1e-4)};
}

bool FrustumCuller::MayBeVisible(const CullGroup& group) const {
  if (!(group.min.array() <= group.max.array()).all()) return false;  // empty
  Eigen::Vector3d corners[8];
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d p((k & 1) ? group.max.x() : group.min.x(),
                            (k & 2) ? group.max.y() : group.min.y(),
                            (k & 4) ? group.max.z() : group.min.z());
    corners[k] = camera_from_world_ * (p - centre_);
  }
  for (const Eigen::Vector4d& plane : planes_) {
    bool all_outside = true;
    for (const Eigen::Vector3d& q : corners) {
      if (plane.head<3>().dot(q) + plane.w() >= 0) {
        all_outside = false;
        break;
      }
    }
    if (all_outside) return false;
  }
  return true;
}

void SplitByCount(const std::vector<CullGroup>& groups, const std::vector<uint32_t>& list,
                  int parts, std::vector<size_t>* split) {
  split->assign(static_cast<size_t>(parts) + 1, list.size());
  (*split)[0] = 0;
  size_t total = 0;
  for (uint32_t g : list) total += groups[g].end - groups[g].begin;
  size_t seen = 0, next_part = 1;
  for (size_t i = 0; i < list.size() && next_part < static_cast<size_t>(parts); ++i) {
    seen += groups[list[i]].end - groups[list[i]].begin;
    while (next_part < static_cast<size_t>(parts) && seen * parts >= total * next_part) {
      (*split)[next_part++] = i + 1;
    }
  }
}

}  // namespace m2s::internal
