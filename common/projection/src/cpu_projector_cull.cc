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

void Extend(CullGroup* group, const Eigen::Vector3f& p) {
  if (!p.allFinite()) return;
  group->min = group->min.cwiseMin(p);
  group->max = group->max.cwiseMax(p);
}

// The group [begin, end) boxed around the points at(i), i in [first, last).
template <typename PointAt>
CullGroup BoxPoints(uint32_t begin, uint32_t end, size_t first, size_t last, const PointAt& at) {
  CullGroup group = BoxOf(begin, end);
  for (size_t i = first; i < last; ++i) Extend(&group, at(i));
  return group;
}

// [0, count) in runs of group_size, each boxed by box(begin, end).
template <typename BoxRun>
std::vector<CullGroup> SplitIntoGroups(size_t count, size_t group_size, const BoxRun& box) {
  std::vector<CullGroup> groups;
  groups.reserve((count + group_size - 1) / group_size);
  for (size_t begin = 0; begin < count; begin += group_size) {
    const size_t end = std::min(count, begin + group_size);
    groups.push_back(box(static_cast<uint32_t>(begin), static_cast<uint32_t>(end)));
  }
  return groups;
}

}  // namespace

CullGroup BoxVertices(const float* x, const float* y, const float* z, uint32_t begin,
                      uint32_t end) {
  return BoxPoints(begin, end, begin, end,
                   [&](size_t i) { return Eigen::Vector3f(x[i], y[i], z[i]); });
}

CullGroup BoxTriangles(const std::vector<uint32_t>& triangles, const float* x, const float* y,
                       const float* z, uint32_t begin, uint32_t end) {
  return BoxPoints(begin, end, 3 * size_t{begin}, 3 * size_t{end}, [&](size_t i) {
    const uint32_t v = triangles[i];
    return Eigen::Vector3f(x[v], y[v], z[v]);
  });
}

std::vector<CullGroup> MakeVertexGroups(const float* x, const float* y, const float* z, size_t n,
                                        size_t group_size) {
  return SplitIntoGroups(n, group_size, [&](uint32_t begin, uint32_t end) {
    return BoxVertices(x, y, z, begin, end);
  });
}

std::vector<CullGroup> MakeVertexGroups(std::span<const Eigen::Vector3f> positions,
                                        size_t group_size) {
  return SplitIntoGroups(positions.size(), group_size, [&](uint32_t begin, uint32_t end) {
    return BoxPoints(begin, end, begin, end, [&](size_t i) { return positions[i]; });
  });
}

std::vector<CullGroup> MakeTriangleGroups(const std::vector<uint32_t>& triangles, const float* x,
                                          const float* y, const float* z, size_t group_size) {
  return SplitIntoGroups(triangles.size() / 3, group_size, [&](uint32_t begin, uint32_t end) {
    return BoxTriangles(triangles, x, y, z, begin, end);
  });
}

std::vector<CullGroup> MakeTriangleGroups(const std::vector<uint32_t>& triangles,
                                          std::span<const Eigen::Vector3f> positions,
                                          size_t group_size) {
  return SplitIntoGroups(triangles.size() / 3, group_size, [&](uint32_t begin, uint32_t end) {
    return BoxPoints(begin, end, 3 * size_t{begin}, 3 * size_t{end},
                     [&](size_t i) { return positions[triangles[i]]; });
  });
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
