// CpuProjector culling: vertex and triangle groups with bounding boxes, the frustum test.
#include <algorithm>
#include <cmath>
#include <limits>

#include "cpu_projector_internal.h"

namespace m2s {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Footprint(): boxes reaching closer than this fraction of the near plane are not bounded;
// depths get this relative margin (the float kernel is within ~1e-6 of double).
constexpr double kMinBoundedDepth = 0.5;
constexpr double kDepthMargin = 1e-4;

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

std::vector<CullGroup> MakeVertexGroups(std::span<const Eigen::Vector3f> positions,
                                        size_t group_size) {
  std::vector<CullGroup> groups;
  for (size_t begin = 0; begin < positions.size(); begin += group_size) {
    const size_t end = std::min(positions.size(), begin + group_size);
    CullGroup group = BoxOf(static_cast<uint32_t>(begin), static_cast<uint32_t>(end));
    for (size_t i = begin; i < end; ++i) {
      Extend(&group, positions[i].x(), positions[i].y(), positions[i].z());
    }
    groups.push_back(group);
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

std::vector<CullGroup> MakeTriangleGroups(const std::vector<uint32_t>& triangles,
                                          std::span<const Eigen::Vector3f> positions,
                                          size_t group_size) {
  std::vector<CullGroup> groups;
  const size_t n = triangles.size() / 3;
  for (size_t begin = 0; begin < n; begin += group_size) {
    const size_t end = std::min(n, begin + group_size);
    CullGroup group = BoxOf(static_cast<uint32_t>(begin), static_cast<uint32_t>(end));
    for (size_t i = 3 * begin; i < 3 * end; ++i) {
      const Eigen::Vector3f& p = positions[triangles[i]];
      Extend(&group, p.x(), p.y(), p.z());
    }
    groups.push_back(group);
  }
  return groups;
}

FrustumCuller::FrustumCuller(const Pose3& world_from_camera, const Camera& camera, double margin_px)
    : camera_(camera),
      camera_from_world_(world_from_camera.RotationMatrix().transpose()),
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

void FrustumCuller::Corners(const CullGroup& group, Eigen::Vector3d (&corners)[8]) const {
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d p((k & 1) ? group.max.x() : group.min.x(),
                            (k & 2) ? group.max.y() : group.min.y(),
                            (k & 4) ? group.max.z() : group.min.z());
    corners[k] = camera_from_world_ * (p - centre_);
  }
}

ScreenBox FrustumCuller::Footprint(const CullGroup& group, int buffer_width,
                                   int buffer_height) const {
  Eigen::Vector3d corners[8];
  Corners(group, corners);
  ScreenBox box;
  double min_x = kInf, max_x = -kInf, min_y = kInf, max_y = -kInf, min_z = kInf, max_z = -kInf;
  for (const Eigen::Vector3d& q : corners) {
    min_z = std::min(min_z, q.z());
    max_z = std::max(max_z, q.z());
    const double x = camera_.fx * (q.x() / q.z()) + camera_.cx;
    const double y = camera_.fy * (q.y() / q.z()) + camera_.cy;
    min_x = std::min(min_x, x);
    max_x = std::max(max_x, x);
    min_y = std::min(min_y, y);
    max_y = std::max(max_y, y);
  }
  // Near the camera plane the projection is unbounded (and the kernel's rounding large).
  if (!(min_z >= kMinBoundedDepth * camera_.near)) return box;
  const double sx = static_cast<double>(buffer_width) / camera_.width;
  const double sy = static_cast<double>(buffer_height) / camera_.height;
  // A pixel of margin on each side, clamped before the conversion to int.
  auto lower = [](double value, int size) {
    return static_cast<int>(std::clamp(std::floor(value) - 1.0, 0.0, size + 1.0));
  };
  auto upper = [](double value, int size) {
    return static_cast<int>(std::clamp(std::ceil(value) + 1.0, -2.0, size - 1.0));
  };
  box.bounded = true;
  box.x0 = lower(min_x * sx, buffer_width);
  box.x1 = upper(max_x * sx, buffer_width);
  box.y0 = lower(min_y * sy, buffer_height);
  box.y1 = upper(max_y * sy, buffer_height);
  box.min_depth = min_z * (1.0 - kDepthMargin);
  box.max_depth = max_z * (1.0 + kDepthMargin);
  return box;
}

bool FrustumCuller::MayBeVisible(const CullGroup& group) const {
  if (!(group.min.array() <= group.max.array()).all()) return false;  // empty
  Eigen::Vector3d corners[8];
  Corners(group, corners);
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

namespace internal {

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

}  // namespace internal
}  // namespace m2s
