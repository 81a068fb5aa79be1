// Benchmark sequences: the default scene with a head-motion trajectory, resampled at a frame
// rate, turned into SLAM frames on demand by the CPU projector (occlusion on) and the feature
// degradations of feature_noise.h.
//
//   auto source = FrameSource::Create(scene, camera, gt_at_rate, FrameSourceOptions{});
//   slam::Frame frame;
//   source->MakeFrame(i, &frame);  // frame i: seq i, timestamp and ground truth of gt_at_rate[i]
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_noise.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/status.h"
#include "m2s/common/trajectory.h"
#include "m2s/slam/system.h"

namespace m2s::bench {

struct Sequence {
  std::string name;
  Trajectory trajectory;  // ground truth at its native rate (world_from_camera)
};

// "default" (DefaultTrajectory()) and "room-s<seed>" (GenerateHeadMotion in the default
// room with that seed), each `duration_s` long (0: the default trajectory's own length).
Expected<std::vector<Sequence>> MakeSequences(const std::vector<uint64_t>& room_seeds,
                                              double duration_s);

// The benchmark camera: 640 x 480, 90 degrees horizontal field of view.
Camera BenchCamera();

struct FrameSourceOptions {
  FeatureNoiseOptions noise;  // applied per frame (frame index = seq)
  bool occlusion = true;
  // Depth-buffer resolution for occlusion as a fraction of the image (projector.h).
  double occlusion_resolution_scale = 0.5;
  // Keep only vertices whose id is a multiple of this (a consistent subsample of the scene, so
  // that successive frames see the same points; 1: every vertex).
  int vertex_stride = 1;
  int projector_threads = 1;
  // As a client sends them: the balanced selection of this many features (KeepBalanced on the
  // camera's grid), after the noise. 0: every visible vertex (SLAM's feature_budget selects
  // the same subset; a large world's millions would exceed max_features_per_frame).
  int send_budget = 0;
};

class FrameSource {
 public:
  static Expected<std::unique_ptr<FrameSource>> Create(const Scene& scene, const Camera& camera,
                                                       Trajectory ground_truth,
                                                       const FrameSourceOptions& options);
  size_t size() const { return ground_truth_.size(); }
  const Trajectory& ground_truth() const { return ground_truth_; }
  Status MakeFrame(size_t index, slam::Frame* frame);
  // The vertices the last MakeFrame saw (before the send budget).
  size_t last_visible() const { return last_visible_; }

 private:
  FrameSource() = default;
  Camera camera_;
  Trajectory ground_truth_;
  FrameSourceOptions options_;
  uint32_t num_vertices_ = 0;
  std::unique_ptr<CpuProjector> projector_;
  std::vector<ProjectedVertex> projected_;
  BalancedSelector selector_;
  size_t last_visible_ = 0;
};

}  // namespace m2s::bench
