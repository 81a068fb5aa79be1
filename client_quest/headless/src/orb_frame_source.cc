#include "m2s/headless/orb_frame_source.h"

#include <chrono>

#include <opencv2/imgproc.hpp>

#include "m2s/gpu/gl_context.h"
#include "m2s/render/scene_renderer.h"

namespace m2s::headless {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace

OrbFrameSource::OrbFrameSource(const Camera& camera,
                               const image_features::OrbFrontEnd::Options& options)
    : camera_(camera), image_(std::make_unique<RenderedFrame>()), front_end_(options) {}

OrbFrameSource::~OrbFrameSource() {
  if (context_) (void)context_->MakeCurrent();  // the renderer frees its GL objects in it
  renderer_.reset();
}

Expected<std::unique_ptr<OrbFrameSource>> OrbFrameSource::Create(
    const RenderMesh& mesh, const Camera& camera,
    const image_features::OrbFrontEnd::Options& options) {
  if (Status s = options.Check(); !s) return s.Prefixed("ORB options: ");
  if (Status s = camera.Check(); !s) return s.Prefixed("camera: ");
  auto context = GlContext::CreateHeadless();
  if (!context) {
    return Status::Error("the ORB front end renders images and needs EGL (GLES 3.1): " +
                         context.error());
  }
  std::unique_ptr<OrbFrameSource> source(new OrbFrameSource(camera, options));
  source->context_ = std::move(*context);
  auto renderer = SceneRenderer::Create(mesh, camera);
  if (!renderer) return renderer.status().Prefixed("scene renderer: ");
  source->renderer_ = std::move(*renderer);
  return source;
}

Expected<wire::FeatureFrame> OrbFrameSource::Make(const Pose3& world_from_camera,
                                                  int64_t capture_time_us,
                                                  reporting::FrontEndTime* time) {
  reporting::FrontEndTime local;
  reporting::FrontEndTime& t = time ? *time : local;
  if (Status s = context_->MakeCurrent(); !s) return s;
  const auto render_start = Clock::now();
  if (Status s = renderer_->Render(world_from_camera, image_.get()); !s) {
    return s.Prefixed("render: ");
  }
  t.render_ms = MsSince(render_start);
  if (image_->width != camera_.width || image_->height != camera_.height ||
      image_->rgb.size() != static_cast<size_t>(camera_.width) * camera_.height * 3) {
    return Status::Error("render: the image does not have the camera's size");
  }

  const auto grey_start = Clock::now();
  const cv::Mat rgb(image_->height, image_->width, CV_8UC3, image_->rgb.data());
  cv::cvtColor(rgb, grey_, cv::COLOR_RGB2GRAY);
  const double grey_ms = MsSince(grey_start);

  wire::FeatureFrame frame;
  frame.capture_time_us = capture_time_us;
  frame.camera = camera_;
  frame.ground_truth_world_from_camera = world_from_camera;
  image_features::OrbTimings orb;
  if (Status s = front_end_.Process(grey_, &frame.features, &orb); !s) return s;
  t.extract_ms = grey_ms + orb.extract_ms;
  t.match_ms = orb.match_ms;
  t.tracked = orb.tracked;
  t.reidentified = orb.reidentified;
  t.new_ids = orb.new_ids;
  return frame;
}

}  // namespace m2s::headless
