// The projector interface: scene vertices -> visible vertex features for one camera pose.
//
// Implementations: CpuProjector (common/cpu_projector.h) and GpuProjector
// (client_quest/gpu, GLES 3.1 compute). Both return every vertex with near <= Z <= far whose
// (u, v) lies in the image (u in [0, width), v in [0, height)), sub-pixel, with depth = Z.
// With occlusion enabled, vertices hidden behind nearer triangles (beyond a depth bias) are
// removed as well. Output order is unspecified; compare as sets of ids.
//
// A projector is bound to one scene at construction and is not thread-safe: use one per thread.
//
//   auto projector = CpuProjector::Create(scene, options);
//   std::vector<ProjectedVertex> features;
//   projector->Project(world_from_camera, camera, &features);
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/geometry.h"
#include "m2s/common/status.h"
#include "m2s/common/types.h"

namespace m2s {

struct ProjectorOptions {
  // What a real camera sees: occlusion on (the apps' default; the paper's setting projects
  // every vertex in view, `occlusion = false`).
  static ProjectorOptions Occluding() {
    ProjectorOptions options;
    options.occlusion = true;
    options.occlusion_resolution_scale = 0.5;  // a quarter of the depth-buffer pixels
    return options;
  }

  // Remove vertices hidden behind nearer surfaces using a depth buffer of the scene triangles.
  bool occlusion = false;
  // Depth buffer resolution as a fraction of the image resolution, in (0, 1].
  double occlusion_resolution_scale = 1.0;
  // A vertex is kept when its depth <= buffer depth * (1 + relative bias) + absolute bias.
  double occlusion_depth_bias_relative = 0.01;
  double occlusion_depth_bias_m = 0.01;
  // Worker threads for the CPU projector (0: hardware concurrency).
  int num_threads = 0;

  Status Check() const;
};

class Projector {
 public:
  virtual ~Projector() = default;
  // Fills `out` (cleared first; its capacity is reused, no per-frame allocation in steady state).
  virtual Status Project(const Pose3& world_from_camera, const Camera& camera,
                         std::vector<ProjectedVertex>* out) = 0;
  // The balanced selection (feature_rank.h: SelectBalanced on `grid`, at most `budget`) of the
  // in-image vertices Project() returns, in their order; everything in the image when
  // budget <= 0. This default projects everything and selects; a projector may find the same
  // vertices with less work (CpuProjector).
  virtual Status ProjectBalanced(const Pose3& world_from_camera, const Camera& camera,
                                 const FeatureGrid& grid, int budget,
                                 std::vector<ProjectedVertex>* out);
  virtual std::string_view name() const = 0;

 private:
  BalancedSelector selector_;  // the default ProjectBalanced's buffers
};

}  // namespace m2s
