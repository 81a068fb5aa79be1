#include "m2s/client/frame_source.h"

#include <chrono>
#include <utility>
#include <vector>

#include "m2s/common/feature_rank.h"

namespace m2s::client {

FrameSource::FrameSource(Projector* projector, const Camera& camera, FeatureNoiseOptions noise,
                         uint32_t num_scene_vertices, int send_budget)
    : projector_(projector),
      camera_(camera),
      noise_(noise),
      num_scene_vertices_(num_scene_vertices),
      send_budget_(send_budget),
      send_grid_(FeatureGrid::ForImage(camera.width, camera.height)) {}

Expected<wire::FeatureFrame> FrameSource::Make(const Pose3& world_from_camera,
                                               int64_t capture_time_us, uint64_t frame_index) {
  const auto start = std::chrono::steady_clock::now();
  wire::FeatureFrame frame;
  frame.capture_time_us = capture_time_us;
  frame.camera = camera_;
  frame.ground_truth_world_from_camera = world_from_camera;
  auto add = [&frame](const ProjectedVertex& p) {
    VertexFeature f;
    f.id = p.id;
    f.uv = {p.u, p.v};
    frame.features.push_back(f);
  };
  if (!noise_.Enabled()) {
    // The projector's balanced selection (a CPU projector finds it without testing every
    // visible vertex of a large scene).
    if (Status s = projector_->ProjectBalanced(world_from_camera, camera_, send_grid_, send_budget_,
                                               &scratch_);
        !s) {
      return s;
    }
    frame.features.reserve(scratch_.size());
    for (const ProjectedVertex& p : scratch_) add(p);
  } else {
    // Noise moves features and changes ids: every visible vertex first, then the in-image
    // ones, then the balanced selection of them.
    if (Status s = projector_->Project(world_from_camera, camera_, &scratch_); !s) return s;
    ApplyFeatureNoise(noise_, camera_, num_scene_vertices_, frame_index, &scratch_);
    std::erase_if(scratch_,
                  [this](const ProjectedVertex& p) { return !camera_.InImage(p.u, p.v); });
    const std::vector<uint32_t>& kept = selector_.Select(
        scratch_.size(), [this](size_t i) { return scratch_[i].id; },
        [this](size_t i) { return std::pair(scratch_[i].u, scratch_[i].v); }, send_grid_,
        send_budget_);
    frame.features.reserve(kept.size());
    for (const uint32_t j : kept) add(scratch_[j]);
  }
  last_projection_ms_ =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return frame;
}

}  // namespace m2s::client
