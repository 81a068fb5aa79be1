// xrEndFrame (layer validation), the left-eye capture and the report.
#include <GLES3/gl3.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "api.h"

namespace m2s::xrsim {
namespace {

nlohmann::json PoseJson(const XrPosef& p) {
  return {
      {"position", {p.position.x, p.position.y, p.position.z}},
      {"orientation_xyzw", {p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w}}};
}

}  // namespace

void CaptureLeftEye(InstanceObj& instance, SessionObj& session,
                    const XrCompositionLayerProjection& layer, int64_t frame) {
  Runtime& rt = Runtime::Get();
  const XrCompositionLayerProjectionView& view = layer.views[0];
  SwapchainObj* sc = rt.FindSwapchain(view.subImage.swapchain);
  const XrRect2Di& rect = view.subImage.imageRect;
  std::vector<uint8_t> rgba(static_cast<size_t>(rect.extent.width) * rect.extent.height * 4);
  {
    ScopedAppContext context(session);
    if (!context.ok()) {
      ++instance.counters.gl_failures;
      return;
    }
    GLint previous_fbo = 0, previous_pack = 4;
    glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &previous_fbo);
    glGetIntegerv(GL_PACK_ALIGNMENT, &previous_pack);
    GLuint fbo = 0;
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D,
                           sc->textures[sc->last_released], 0);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(rect.offset.x, rect.offset.y, rect.extent.width, rect.extent.height, GL_RGBA,
                 GL_UNSIGNED_BYTE, rgba.data());
    glPixelStorei(GL_PACK_ALIGNMENT, previous_pack);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, static_cast<GLuint>(previous_fbo));
    glDeleteFramebuffers(1, &fbo);
    if (const GLenum error = glGetError(); error != GL_NO_ERROR) {
      LogInfo("ERROR: GL error " + std::to_string(error) + " reading back the left eye");
      ++instance.counters.gl_failures;
      return;
    }
  }
  // GL rows start at the bottom of the image: flip so the PNG is upright.
  cv::Mat image(rect.extent.height, rect.extent.width, CV_8UC4, rgba.data());
  cv::Mat upright, bgra;
  cv::flip(image, upright, 0);
  cv::cvtColor(upright, bgra, cv::COLOR_RGBA2BGRA);
  std::error_code ignored;
  std::filesystem::create_directories(instance.config.capture_dir, ignored);
  char stem[64];
  std::snprintf(stem, sizeof(stem), "left_%06lld", static_cast<long long>(frame));
  const std::string base = instance.config.capture_dir + "/" + stem;
  if (!cv::imwrite(base + ".png", bgra)) {
    LogInfo("ERROR: cannot write " + base + ".png");
    return;
  }
  const SimPose head = instance.Head(instance.DisplayTime(frame));
  const Eigen::Quaterniond& q = head.rotation;
  nlohmann::json meta = {
      {"frame", frame},
      {"display_time_ns", instance.DisplayTime(frame)},
      {"width", rect.extent.width},
      {"height", rect.extent.height},
      {"format", sc->format},
      {"srgb", sc->format == GL_SRGB8_ALPHA8},
      {"pose_in_layer_space", PoseJson(view.pose)},
      {"played_head_in_local",
       {{"position", {head.translation.x(), head.translation.y(), head.translation.z()}},
        {"orientation_xyzw", {q.x(), q.y(), q.z(), q.w()}}}},
      {"fov_rad",
       {{"left", view.fov.angleLeft},
        {"right", view.fov.angleRight},
        {"up", view.fov.angleUp},
        {"down", view.fov.angleDown}}}};
  std::ofstream(base + ".json") << meta.dump(2) << "\n";
  instance.captures.push_back(base + ".png");
  ++instance.counters.captures;
}

void WriteReport(const InstanceObj& instance, int64_t live_children) {
  const Runtime& rt = Runtime::Get();
  const int64_t misuse = rt.misuse_count() - instance.misuse_at_create;
  const Counters& c = instance.counters;
  LogInfo("summary for '" + instance.application_name + "': misuse=" + std::to_string(misuse) +
          " handles_left_alive=" + std::to_string(live_children) +
          " implicitly_destroyed=" + std::to_string(c.implicitly_destroyed) +
          " frames waited/ended=" + std::to_string(c.frames_waited) + "/" +
          std::to_string(c.frames_ended) + " sessions=" + std::to_string(c.sessions_created));
  if (instance.config.report_path.empty()) return;
  std::vector<std::string> messages(rt.misuse_log().begin() + instance.misuse_at_create,
                                    rt.misuse_log().end());
  const nlohmann::json report = {{"application", instance.application_name},
                                 {"misuse", misuse},
                                 {"misuse_messages", messages},
                                 {"handles_left_alive", live_children},
                                 {"implicitly_destroyed", c.implicitly_destroyed},
                                 {"sessions_created", c.sessions_created},
                                 {"sessions_destroyed", c.sessions_destroyed},
                                 {"sessions_destroyed_running", c.sessions_destroyed_running},
                                 {"spaces_created", c.spaces_created},
                                 {"spaces_destroyed", c.spaces_destroyed},
                                 {"swapchains_created", c.swapchains_created},
                                 {"swapchains_destroyed", c.swapchains_destroyed},
                                 {"frames_waited", c.frames_waited},
                                 {"frames_begun", c.frames_begun},
                                 {"frames_ended", c.frames_ended},
                                 {"frames_discarded", c.frames_discarded},
                                 {"layers_submitted", c.layers_submitted},
                                 {"events_delivered", c.events_delivered},
                                 {"events_pending", instance.events.size()},
                                 {"gl_failures", c.gl_failures},
                                 {"action_sets_created", c.action_sets_created},
                                 {"action_sets_destroyed", c.action_sets_destroyed},
                                 {"actions_created", c.actions_created},
                                 {"actions_destroyed", c.actions_destroyed},
                                 {"action_syncs", c.action_syncs},
                                 {"action_syncs_unfocused", c.action_syncs_unfocused},
                                 {"interaction_profile", instance.config.interaction_profile},
                                 {"input_script", instance.config.input_path},
                                 {"instance_lost", instance.lost},
                                 {"rate_hz", instance.config.rate_hz},
                                 {"time_origin_ns", instance.time_origin},
                                 {"trajectory_time_origin_s", instance.trajectory_time_origin},
                                 {"transitions", instance.transitions},
                                 {"captures", instance.captures}};
  std::ofstream file(instance.config.report_path);
  file << report.dump(2) << "\n";
  if (!file) LogInfo("ERROR: cannot write report " + instance.config.report_path);
}

namespace api {
namespace {

bool ValidPose(const XrPosef& p) {
  const double n = std::sqrt(p.orientation.x * p.orientation.x + p.orientation.y * p.orientation.y +
                             p.orientation.z * p.orientation.z + p.orientation.w * p.orientation.w);
  return std::isfinite(n) && std::abs(n - 1.0) <= 0.01;
}

// Validates one projection layer (spec 10.5); returns XR_SUCCESS or the error to report.
XrResult CheckProjectionLayer(const XrCompositionLayerProjection& layer, XrSession session,
                              std::string* why) {
  Runtime& rt = Runtime::Get();
  const SpaceObj* space = rt.FindSpace(layer.space);
  if (space == nullptr || space->session != session) {
    *why = "layer space is not a space of this session";
    return XR_ERROR_HANDLE_INVALID;
  }
  if (layer.viewCount != 2 || layer.views == nullptr) {
    *why = "projection layer must have 2 views for PRIMARY_STEREO";
    return XR_ERROR_VALIDATION_FAILURE;
  }
  for (uint32_t i = 0; i < 2; ++i) {
    const XrCompositionLayerProjectionView& v = layer.views[i];
    if (v.type != XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW) {
      *why = "views[i].type is not XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW";
      return XR_ERROR_VALIDATION_FAILURE;
    }
    const SwapchainObj* sc = rt.FindSwapchain(v.subImage.swapchain);
    if (sc == nullptr || sc->session != session) {
      *why = "views[i].subImage.swapchain is not a swapchain of this session";
      return XR_ERROR_HANDLE_INVALID;
    }
    if (sc->last_released < 0) {
      *why = "views[i].subImage.swapchain has no released image";
      return XR_ERROR_LAYER_INVALID;
    }
    const XrRect2Di& r = v.subImage.imageRect;
    if (r.offset.x < 0 || r.offset.y < 0 || r.extent.width <= 0 || r.extent.height <= 0 ||
        r.offset.x + r.extent.width > static_cast<int32_t>(sc->width) ||
        r.offset.y + r.extent.height > static_cast<int32_t>(sc->height)) {
      *why = "views[i].subImage.imageRect is outside the swapchain image";
      return XR_ERROR_SWAPCHAIN_RECT_INVALID;
    }
    if (v.subImage.imageArrayIndex != 0) {
      *why = "views[i].subImage.imageArrayIndex must be 0 (arraySize 1)";
      return XR_ERROR_VALIDATION_FAILURE;
    }
    if (!ValidPose(v.pose)) {
      *why = "views[i].pose has a non-unit orientation";
      return XR_ERROR_POSE_INVALID;
    }
    if (!(v.fov.angleLeft < v.fov.angleRight && v.fov.angleDown < v.fov.angleUp)) {
      *why = "views[i].fov is degenerate";
      return XR_ERROR_VALIDATION_FAILURE;
    }
  }
  return XR_SUCCESS;
}

}  // namespace

XrResult XRAPI_CALL EndFrame(XrSession session, const XrFrameEndInfo* info) {
  constexpr const char* kFn = "xrEndFrame";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_FRAME_END_INFO, "frameEndInfo");
  M2S_SIM_REQUIRE(s->running, XR_ERROR_SESSION_NOT_RUNNING, "session is not running");
  M2S_SIM_REQUIRE(s->frame_begun, XR_ERROR_CALL_ORDER_INVALID,
                  "xrEndFrame without a preceding xrBeginFrame");
  M2S_SIM_REQUIRE(info->displayTime == inst->DisplayTime(s->begun_frame), XR_ERROR_TIME_INVALID,
                  "displayTime is not the predictedDisplayTime of the frame begun");
  M2S_SIM_REQUIRE(info->environmentBlendMode == XR_ENVIRONMENT_BLEND_MODE_OPAQUE,
                  XR_ERROR_ENVIRONMENT_BLEND_MODE_UNSUPPORTED, "only OPAQUE is supported");
  M2S_SIM_REQUIRE(info->layerCount <= kMaxLayers, XR_ERROR_LAYER_LIMIT_EXCEEDED,
                  "more than 16 layers");
  M2S_SIM_REQUIRE(info->layerCount == 0 || info->layers != nullptr, XR_ERROR_VALIDATION_FAILURE,
                  "layers is NULL");
  const XrCompositionLayerProjection* first_projection = nullptr;
  for (uint32_t i = 0; i < info->layerCount; ++i) {
    const XrCompositionLayerBaseHeader* layer = info->layers[i];
    M2S_SIM_REQUIRE(layer != nullptr, XR_ERROR_LAYER_INVALID, "layers[i] is NULL");
    M2S_SIM_REQUIRE(layer->type == XR_TYPE_COMPOSITION_LAYER_PROJECTION, XR_ERROR_LAYER_INVALID,
                    "only projection layers are supported");
    const auto* projection = reinterpret_cast<const XrCompositionLayerProjection*>(layer);
    std::string why;
    const XrResult r = CheckProjectionLayer(*projection, session, &why);
    M2S_SIM_REQUIRE(r == XR_SUCCESS, r, why);
    if (first_projection == nullptr) first_projection = projection;
  }
  s->frame_begun = false;
  ++inst->counters.frames_ended;
  inst->counters.layers_submitted += info->layerCount;
  if (first_projection != nullptr && inst->config.ShouldCapture(s->begun_frame)) {
    CaptureLeftEye(*inst, *s, *first_projection, s->begun_frame);
  }
  return XR_SUCCESS;
}

}  // namespace api
}  // namespace m2s::xrsim
