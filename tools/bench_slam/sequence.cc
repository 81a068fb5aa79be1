#include "sequence.h"

namespace m2s::bench {

Camera BenchCamera() { return Camera::FromHorizontalFov(640, 480, 90.0, 0.05, 50.0); }

Expected<std::vector<Sequence>> MakeSequences(const std::vector<uint64_t>& room_seeds,
                                              double duration_s) {
  std::vector<Sequence> sequences;
  HeadMotionOptions options = DefaultHeadMotionOptions();
  if (duration_s > 0.0) {
    options.duration_s = duration_s;
    Expected<Trajectory> trajectory = GenerateHeadMotion(options);
    if (!trajectory) return Status::Error(trajectory.error());
    sequences.push_back({"default", std::move(*trajectory)});
  } else {
    sequences.push_back({"default", DefaultTrajectory()});
  }
  for (uint64_t seed : room_seeds) {
    HeadMotionOptions room = options;
    room.seed = seed;
    if (duration_s <= 0.0) room.duration_s = 60.0;
    Expected<Trajectory> trajectory = GenerateHeadMotion(room);
    if (!trajectory) return Status::Error(trajectory.error());
    sequences.push_back({"room-s" + std::to_string(seed), std::move(*trajectory)});
  }
  return sequences;
}

Expected<std::unique_ptr<FrameSource>> FrameSource::Create(const Scene& scene, const Camera& camera,
                                                           Trajectory ground_truth,
                                                           const FrameSourceOptions& options) {
  if (Status s = options.noise.Check(); !s) return s;
  if (options.vertex_stride < 1) return Status::Error("vertex_stride must be at least 1");
  ProjectorOptions projector_options;
  projector_options.occlusion = options.occlusion;
  projector_options.num_threads = options.projector_threads;
  projector_options.occlusion_resolution_scale = options.occlusion_resolution_scale;
  Expected<std::unique_ptr<CpuProjector>> projector =
      CpuProjector::Create(scene, projector_options);
  if (!projector) return Status::Error(projector.error());
  std::unique_ptr<FrameSource> source(new FrameSource());
  source->camera_ = camera;
  source->ground_truth_ = std::move(ground_truth);
  source->options_ = options;
  source->num_vertices_ = static_cast<uint32_t>(scene.num_vertices());
  source->projector_ = std::move(*projector);
  return source;
}

Status FrameSource::MakeFrame(size_t index, slam::Frame* frame) {
  if (index >= ground_truth_.size()) return Status::Error("frame index out of range");
  const TimedPose& gt = ground_truth_[index];
  Status status = projector_->Project(gt.world_from_camera, camera_, &projected_);
  if (!status) return status;
  if (options_.vertex_stride > 1) {
    const uint32_t stride = static_cast<uint32_t>(options_.vertex_stride);
    std::erase_if(projected_, [stride](const ProjectedVertex& v) { return v.id % stride != 0; });
  }
  if (options_.noise.Enabled()) {
    ApplyFeatureNoise(options_.noise, camera_, num_vertices_, index, &projected_);
  }
  last_visible_ = projected_.size();
  if (options_.send_budget > 0) {
    const std::vector<uint32_t>& kept = selector_.Select(
        projected_.size(), [this](size_t i) { return projected_[i].id; },
        [this](size_t i) { return std::pair(projected_[i].u, projected_[i].v); },
        FeatureGrid::ForImage(camera_.width, camera_.height), options_.send_budget);
    for (size_t k = 0; k < kept.size(); ++k) projected_[k] = projected_[kept[k]];
    projected_.resize(kept.size());
  }
  frame->seq = static_cast<int64_t>(index);
  frame->timestamp = gt.timestamp;
  frame->ground_truth_world_from_camera = gt.world_from_camera;
  frame->features.resize(projected_.size());
  for (size_t i = 0; i < projected_.size(); ++i) {
    frame->features[i].id = projected_[i].id;
    frame->features[i].uv = Eigen::Vector2f(projected_[i].u, projected_[i].v);
  }
  return Status::Ok();
}

}  // namespace m2s::bench
