// OrbFrameSource: the image front end's frame source. Each pose is rendered (SceneRenderer,
// GLES on a headless EGL context the source owns), the image turned grey and into ORB features
// with track ids (image_features::OrbFrontEnd), and packed into the same wire frame as
// client::FrameSource makes, ground truth attached. The feature count is bounded by the ORB
// options (num_features); no send budget or research noise applies.
//
// Thread-safety: not thread-safe; create, use and destroy it on one thread (its GL context is
// current there). Destroy it before another GL context is made current on that thread.
//
//   auto source = OrbFrameSource::Create(render_mesh, camera, orb_options);
//   if (!source) return source.status();              // e.g. no EGL display
//   reporting::FrontEndTime time;
//   Expected<wire::FeatureFrame> frame = (*source)->Make(world_from_camera, capture_us, &time);
#pragma once

#include <cstdint>
#include <memory>

#include <opencv2/core.hpp>

#include "m2s/common/render_mesh.h"
#include "m2s/common/wire_format.h"
#include "m2s/image_features/orb_front_end.h"
#include "m2s/reporting/run_outputs.h"

namespace m2s {
class GlContext;
class SceneRenderer;
struct RenderedFrame;
}  // namespace m2s

namespace m2s::headless {

class OrbFrameSource {
 public:
  // Error (one line) when the options are invalid, no EGL display is available or the mesh
  // cannot be uploaded.
  static Expected<std::unique_ptr<OrbFrameSource>> Create(
      const RenderMesh& mesh, const Camera& camera,
      const image_features::OrbFrontEnd::Options& options);
  ~OrbFrameSource();

  // The frame seen from world_from_camera; session_id, seq and send_wall_us are left for the
  // session to fill. `time` (may be null) gets the render, extraction and matching times and
  // the id counts; its seq is left alone.
  Expected<wire::FeatureFrame> Make(const Pose3& world_from_camera, int64_t capture_time_us,
                                    reporting::FrontEndTime* time);
  const Camera& camera() const { return camera_; }

 private:
  OrbFrameSource(const Camera& camera, const image_features::OrbFrontEnd::Options& options);

  const Camera camera_;
  std::unique_ptr<GlContext> context_;  // declared first: destroyed after the renderer
  std::unique_ptr<SceneRenderer> renderer_;
  std::unique_ptr<RenderedFrame> image_;
  image_features::OrbFrontEnd front_end_;
  cv::Mat grey_;
};

}  // namespace m2s::headless
