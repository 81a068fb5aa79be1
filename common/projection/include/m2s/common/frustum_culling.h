// Frustum culling of vertex and triangle groups, shared by the CPU and GPU projectors.
//
// Vertices are grouped in contiguous id ranges (ids follow the meshes and their faces, so a
// range is spatially compact) and triangles in contiguous ranges, each group with its bounding
// box. A frame touches only the groups whose box may be seen:
//
//   const std::vector<CullGroup> groups = MakeVertexGroups(scene.positions, 4096);
//   const FrustumCuller culler(world_from_camera, camera, /*margin_px=*/2.0);
//   for (const CullGroup& g : groups) if (culler.MayBeVisible(g)) { /* ids [g.begin, g.end) */ }
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"

namespace m2s {

// A group: an id range and the box of its vertices (or of its triangles' corners).
struct CullGroup {
  uint32_t begin = 0;  // first vertex id (or triangle) of the group
  uint32_t end = 0;    // one past the last
  Eigen::Vector3f min = Eigen::Vector3f::Zero();
  Eigen::Vector3f max = Eigen::Vector3f::Zero();
};

// The box of vertices [begin, end) (non-finite ones, retired vertices, left out; no finite
// vertex gives an empty box: min > max).
CullGroup BoxVertices(const float* x, const float* y, const float* z, uint32_t begin, uint32_t end);
// The box of the corners of triangles [begin, end).
CullGroup BoxTriangles(const std::vector<uint32_t>& triangles, const float* x, const float* y,
                       const float* z, uint32_t begin, uint32_t end);
// Groups of group_size consecutive vertices (the last one shorter).
std::vector<CullGroup> MakeVertexGroups(const float* x, const float* y, const float* z, size_t n,
                                        size_t group_size);
std::vector<CullGroup> MakeVertexGroups(std::span<const Eigen::Vector3f> positions,
                                        size_t group_size);
// Groups of group_size consecutive triangles, boxes over their corners.
std::vector<CullGroup> MakeTriangleGroups(const std::vector<uint32_t>& triangles, const float* x,
                                          const float* y, const float* z, size_t group_size);
std::vector<CullGroup> MakeTriangleGroups(const std::vector<uint32_t>& triangles,
                                          std::span<const Eigen::Vector3f> positions,
                                          size_t group_size);

// Where a group's box can appear in a depth buffer: the buffer pixels [x0, x1] x [y0, y1]
// (clipped to the buffer, widened by a pixel on each side beyond what pixel-centre sampling
// and the kernel's float rounding can reach) and a lower bound on the camera depth of every
// point of the box (and an upper bound), with a relative margin far above the kernel's rounding.
// `bounded` is false when part of the box lies near or behind the camera plane (then nothing is
// known).
struct ScreenBox {
  bool bounded = false;
  int x0 = 0, x1 = -1, y0 = 0, y1 = -1;
  double min_depth = 0.0;
  double max_depth = 0.0;  // an upper bound, with the same margin
  bool empty() const { return x0 > x1 || y0 > y1; }
};

// A conservative frustum test: MayBeVisible() is false only when no point of the box lies at
// near <= Z <= far with (u, v) within margin_px of the image (checked against the box's
// corners, in double, so the float kernel's rounding can never make a culled vertex visible).
// An empty box (min > max) is never visible.
class FrustumCuller {
 public:
  FrustumCuller(const Pose3& world_from_camera, const Camera& camera, double margin_px);
  bool MayBeVisible(const CullGroup& group) const;
  // The box's footprint in a depth buffer of buffer_width x buffer_height pixels (image
  // pixels scaled by buffer_width / camera.width, buffer_height / camera.height).
  ScreenBox Footprint(const CullGroup& group, int buffer_width, int buffer_height) const;

 private:
  void Corners(const CullGroup& group, Eigen::Vector3d (&corners)[8]) const;

  Camera camera_;
  Eigen::Matrix3d camera_from_world_;
  Eigen::Vector3d centre_;
  // Each plane n . q >= 0 (q in camera coordinates) holds for every visible point.
  Eigen::Vector4d planes_[6];
};

}  // namespace m2s
