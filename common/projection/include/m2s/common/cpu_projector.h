// CpuProjector: the reference projector on the CPU, with optional occlusion.
//
// Projection. Vertices are stored as structure of arrays (x[], y[], z[] floats, 64-byte
// aligned). Per frame, with R = camera_from_world rotation and c = camera centre (both from
// world_from_camera), each vertex p gives, in float:
//   d = (p - c_hi) - c_lo   (c split into a high and a low float, so d is exact to float
//                            precision relative to |p - c| even far from the origin)
//   (X, Y, Z) = R d,  u = fx (X / Z) + cx,  v = fy (Y / Z) + cy
// and is returned when near <= Z <= far, 0 <= u < width and 0 <= v < height (camera.h), as
// (id, u, v, depth = Z). u, v agree with a double-precision evaluation within 1e-3 px for
// images up to 2048 px and fields of view up to 120 degrees; a vertex within that tolerance
// of the image border or of the depth range may fall either way. The loop is branch-free and
// vectorised (SSE2 baseline; an AVX2+FMA clone is picked at load time on x86-64 with GCC);
// scenes of more than 2 x 32768 vertices are split over a persistent worker pool owned by the
// projector (contiguous id ranges, so the output is identical for any thread count and is
// sorted by id). No allocation per frame in steady state.
//
// Scene edits. ApplyChange() follows SceneEditor's add / remove / move of parts: retired
// vertices are never projected, moved ones are projected at their new place with their ids.
//
// Culling. Vertices are grouped in runs of 4096 consecutive ids (ids follow the meshes and
// their faces, so a run is spatially compact) and triangles in runs of 4096, each group with
// its bounding box. A frame first tests the boxes against the view frustum (conservatively,
// in double, with a 2-pixel margin) and transforms, rasterises and tests only the groups that
// may be seen (with occlusion: also the vertex groups of triangles that may be seen). The
// output is exactly that of projecting everything; the work follows what is in view.
//
// Occlusion culling. With occlusion, the triangle groups in view are rasterised nearest box
// first; a group whose box, projected to the buffer (with a pixel of margin), lies entirely
// behind what the buffer already holds there is skipped (it could not lower any depth), and
// so is a vertex group entirely behind the finished buffer (with the depth bias: it could not
// keep a vertex). A triangle whose box holds no pixel centre is rejected before any edge
// setup. None of this changes the output: the minimum depth does not depend on the order,
// and every skip is conservative by a relative depth margin of 1e-4.
//
// Occlusion (ProjectorOptions::occlusion), the rule shared with the GPU projector:
//  1. Depth buffer of bw x bh pixels, bw = max(1, lround(width * s)), bh = max(1,
//     lround(height * s)), s = occlusion_resolution_scale. Image pixel coordinates map to
//     buffer coordinates by (u * bw / width, v * bh / height).
//  2. Every scene triangle is clipped against the plane Z = near (not against far: parts
//     beyond far cannot hide a visible vertex), projected, and rasterised sampling at pixel
//     centres (i + 0.5, j + 0.5) with the top-left fill rule; no face culling. Each buffer
//     pixel holds the minimum camera depth Z (metres, linear, perspective-correct: 1/Z
//     interpolated affinely in screen space) over the triangles covering its centre, or +inf.
//  3. A projected vertex (u, v, Z) samples the buffer at i = clamp(floor(u * bw / width), 0,
//     bw - 1), j = clamp(floor(v * bh / height), 0, bh - 1) and takes M = the maximum over
//     the 3x3 pixels (i-1..i+1) x (j-1..j+1) clipped to the buffer. It is kept when
//        Z <= M * (1 + occlusion_depth_bias_relative) + occlusion_depth_bias_m.
//     Taking the maximum over the neighbourhood means a vertex on a silhouette or a crease
//     never hides itself (some neighbouring pixel shows its own surface or what lies behind
//     it); the price is that occluders thinner than about two buffer pixels do not hide.
//
// Thread-safety: Project() must not be called concurrently on one projector (it owns its
// scratch buffers and worker threads); distinct projectors are independent.
//
//   auto projector = CpuProjector::Create(scene, ProjectorOptions{});
//   std::vector<ProjectedVertex> features;
//   Status s = (*projector)->Project(world_from_camera, camera, &features);
#pragma once

#include <memory>
#include <string_view>
#include <vector>

#include "m2s/common/projector.h"
#include "m2s/common/scene.h"
#include "m2s/common/scene_editor.h"

namespace m2s {

class CpuProjector final : public Projector {
 public:
  // Copies the scene's vertices (and triangles, when occlusion is on). Fails on bad options,
  // triangle indices out of range, non-finite positions or more than 2^32 - 1 vertices.
  static Expected<std::unique_ptr<CpuProjector>> Create(const Scene& scene,
                                                        const ProjectorOptions& options);
  ~CpuProjector() override;

  // Follows an edit of its scene (scene_editor.h): `scene` is the edited scene and `change`
  // what the edit returned; apply every change, in order. Copies the new and moved positions,
  // hides the retired vertices (never projected again) and the changed triangles, and re-boxes
  // only the culling groups they fall in (no full rebuild). The output is then exactly that of
  // a projector created from the edited scene. Fails, changing nothing, when the change does
  // not follow the projector's scene.
  Status ApplyChange(const Scene& scene, const SceneChange& change);

  // Fails (with `out` cleared) on a bad camera, a non-finite pose or a null `out`.
  Status Project(const Pose3& world_from_camera, const Camera& camera,
                 std::vector<ProjectedVertex>* out) override;
  // Project()'s balanced selection (projector.h), found without testing every visible
  // vertex: each vertex group is visited in the rank order of its ids (the order is made once
  // per group) and left as soon as every grid cell its box covers holds enough visible
  // vertices of lower rank that none of the rest can be kept (cpu_projector_balanced.cc).
  // The same vertices and floats as the default, in id order.
  Status ProjectBalanced(const Pose3& world_from_camera, const Camera& camera,
                         const FeatureGrid& grid, int budget,
                         std::vector<ProjectedVertex>* out) override;
  std::string_view name() const override { return "cpu"; }

  size_t num_vertices() const;
  // Vertices of the groups the last Project() could not cull (those it transformed and
  // tested): a measure of the work, in proportion to what is in view.
  size_t last_vertices_considered() const;
  // Vertices of the groups the last Project() tested for visibility: with occlusion, those
  // of the groups in view whose box is not entirely behind the depth buffer (without
  // occlusion, last_vertices_considered()).
  size_t last_vertices_tested() const;
  // Worker threads in the pool, the calling thread included.
  int num_threads() const;

  struct Impl;

 private:
  explicit CpuProjector(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace m2s
