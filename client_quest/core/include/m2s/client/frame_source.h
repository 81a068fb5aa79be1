// FrameSource: scene + camera pose -> projector -> optional feature noise -> optional send
// budget (the balanced selection, m2s/common/feature_rank.h) -> a wire frame.
//
// The projector (CPU or GPU, common/projector.h) is borrowed and used from the calling thread
// only. Deterministic: the noise is keyed by (seed, frame index).
//
// Thread-safety: not thread-safe (one per producer thread).
//
//   FrameSource source(projector.get(), camera, noise, scene.num_vertices());
//   Expected<wire::FeatureFrame> frame = source.Make(world_from_camera, capture_time_us, k);
#pragma once

#include <cstdint>
#include <vector>

#include "m2s/common/feature_noise.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/projector.h"
#include "m2s/common/wire_format.h"

namespace m2s::client {

class FrameSource {
 public:
  // send_budget: at most this many features per frame, the balanced selection (0: all). With
  // the server's slam::Options::feature_budget or more, the server keeps what it would keep
  // from the whole view (the selection is nested).
  FrameSource(Projector* projector, const Camera& camera, FeatureNoiseOptions noise,
              uint32_t num_scene_vertices, int send_budget = 0);

  // The frame seen from world_from_camera; the ground truth is attached for evaluation.
  // session_id, seq and send_wall_us are left for the session to fill.
  Expected<wire::FeatureFrame> Make(const Pose3& world_from_camera, int64_t capture_time_us,
                                    uint64_t frame_index);
  // Wall time of the last projection (+ noise), milliseconds.
  double last_projection_ms() const { return last_projection_ms_; }
  const Camera& camera() const { return camera_; }

 private:
  Projector* const projector_;
  const Camera camera_;
  const FeatureNoiseOptions noise_;
  const uint32_t num_scene_vertices_;
  const int send_budget_;
  const FeatureGrid send_grid_;
  // Per-frame buffers kept between frames (no page faults on millions of features).
  std::vector<ProjectedVertex> scratch_;
  BalancedSelector selector_;
  double last_projection_ms_ = 0.0;
};

}  // namespace m2s::client
