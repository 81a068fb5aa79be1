#include "m2s/xr/xr_session.h"

#include <GLES3/gl3.h>

#include <chrono>
#include <cstring>
#include <thread>

#include "m2s/common/logging.h"

namespace m2s::xr {
namespace {

std::string ResultString(XrInstance instance, XrResult result) {
  char buffer[XR_MAX_RESULT_STRING_SIZE] = {};
  if (instance == XR_NULL_HANDLE || XR_FAILED(xrResultToString(instance, result, buffer))) {
    return "XrResult " + std::to_string(result);
  }
  return buffer;
}

const char* StateName(XrSessionState state) {
  switch (state) {
    case XR_SESSION_STATE_IDLE:
      return "XR_SESSION_STATE_IDLE";
    case XR_SESSION_STATE_READY:
      return "XR_SESSION_STATE_READY";
    case XR_SESSION_STATE_SYNCHRONIZED:
      return "XR_SESSION_STATE_SYNCHRONIZED";
    case XR_SESSION_STATE_VISIBLE:
      return "XR_SESSION_STATE_VISIBLE";
    case XR_SESSION_STATE_FOCUSED:
      return "XR_SESSION_STATE_FOCUSED";
    case XR_SESSION_STATE_STOPPING:
      return "XR_SESSION_STATE_STOPPING";
    case XR_SESSION_STATE_LOSS_PENDING:
      return "XR_SESSION_STATE_LOSS_PENDING";
    case XR_SESSION_STATE_EXITING:
      return "XR_SESSION_STATE_EXITING";
    default:
      return "XR_SESSION_STATE_UNKNOWN";
  }
}

Pose3 FromXr(const XrPosef& p) {
  return PoseFromXr(
      Eigen::Vector4d(p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w),
      Eigen::Vector3d(p.position.x, p.position.y, p.position.z));
}

XrPosef ToXr(const Pose3& p) {
  const Eigen::Quaterniond& q = p.rotation();
  XrPosef out;
  out.orientation = {static_cast<float>(q.x()), static_cast<float>(q.y()),
                     static_cast<float>(q.z()), static_cast<float>(q.w())};
  out.position = {static_cast<float>(p.translation().x()), static_cast<float>(p.translation().y()),
                  static_cast<float>(p.translation().z())};
  return out;
}

}  // namespace

Expected<std::unique_ptr<XrSessionDriver>> XrSessionDriver::Create(const XrSessionOptions& options,
                                                                   XrPlatform* platform,
                                                                   const EglHandles& egl) {
  std::unique_ptr<XrSessionDriver> driver(new XrSessionDriver(options, platform, egl));
  if (Status s = driver->CreateInstance(); !s) return s;
  if (Status s = driver->GetSystem(); !s) return s;
  auto controls = ControllerActions::Create(driver->instance_);
  if (!controls) return controls.status();
  driver->controls_ = std::move(*controls);
  if (Status s = driver->CreateSession(); !s) return s;
  return driver;
}

XrSessionDriver::~XrSessionDriver() {
  if (session_ != XR_NULL_HANDLE && running_ && !session_lost_ && !instance_lost_) {
    // Leaving without the runtime's STOPPING: end the session anyway (the runtime may refuse
    // when it is not stopping; the handles are destroyed regardless).
    M2S_LOG(kWarning) << "OpenXR session still running at shutdown";
  }
  DestroySession();
  controls_.reset();
  if (instance_ != XR_NULL_HANDLE) xrDestroyInstance(instance_);
}

bool XrSessionDriver::Check(XrResult result, const char* what) {
  if (XR_SUCCEEDED(result)) return true;
  if (result == XR_ERROR_SESSION_LOST) {
    session_lost_ = true;
  } else if (result == XR_ERROR_INSTANCE_LOST) {
    instance_lost_ = true;
  } else if (error_.empty()) {
    error_ = std::string(what) + " failed: " + ResultString(instance_, result);
    M2S_LOG(kError) << error_;
  }
  return false;
}

Status XrSessionDriver::CreateInstance() {
  std::vector<std::string> wanted = platform_->InstanceExtensions();
  uint32_t n = 0;
  if (XR_FAILED(xrEnumerateInstanceExtensionProperties(nullptr, 0, &n, nullptr))) {
    return Status::Error("no OpenXR runtime (is XR_RUNTIME_JSON or the active runtime set?)");
  }
  std::vector<XrExtensionProperties> available(n, {XR_TYPE_EXTENSION_PROPERTIES});
  xrEnumerateInstanceExtensionProperties(nullptr, n, &n, available.data());
  std::vector<const char*> names;
  for (const std::string& name : wanted) {
    bool found = false;
    for (const auto& e : available) found |= name == e.extensionName;
    if (!found) return Status::Error("the OpenXR runtime lacks " + name);
    names.push_back(name.c_str());
  }
  XrInstanceCreateInfo info{XR_TYPE_INSTANCE_CREATE_INFO};
  info.next = platform_->InstanceCreateNext();
  std::snprintf(info.applicationInfo.applicationName, XR_MAX_APPLICATION_NAME_SIZE, "%s",
                options_.application_name.c_str());
  std::snprintf(info.applicationInfo.engineName, XR_MAX_ENGINE_NAME_SIZE, "Mesh2SLAM");
  info.applicationInfo.apiVersion = XR_MAKE_VERSION(1, 0, 0);
  info.enabledExtensionCount = static_cast<uint32_t>(names.size());
  info.enabledExtensionNames = names.data();
  if (XrResult r = xrCreateInstance(&info, &instance_); XR_FAILED(r)) {
    return Status::Error("xrCreateInstance failed: " + ResultString(XR_NULL_HANDLE, r));
  }
  XrInstanceProperties properties{XR_TYPE_INSTANCE_PROPERTIES};
  if (XR_SUCCEEDED(xrGetInstanceProperties(instance_, &properties))) {
    runtime_name_ = properties.runtimeName;
  }
  M2S_LOG(kInfo) << "OpenXR runtime: " << runtime_name_;
  return Status::Ok();
}

Status XrSessionDriver::GetSystem() {
  XrSystemGetInfo info{XR_TYPE_SYSTEM_GET_INFO};
  info.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  for (int attempt = 0;; ++attempt) {
    const XrResult r = xrGetSystem(instance_, &info, &system_);
    if (XR_SUCCEEDED(r)) break;
    if (r != XR_ERROR_FORM_FACTOR_UNAVAILABLE || attempt + 1 >= options_.system_retry_limit) {
      if (r == XR_ERROR_INSTANCE_LOST) instance_lost_ = true;
      return Status::Error("xrGetSystem failed: " + ResultString(instance_, r));
    }
    // The headset is not available right now (e.g. just after a session loss).
    std::this_thread::sleep_for(std::chrono::duration<double>(options_.system_retry_wait_s));
  }
  uint32_t n = 0;
  xrEnumerateViewConfigurationViews(instance_, system_, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO,
                                    0, &n, nullptr);
  if (n != 2) return Status::Error("the system has no PRIMARY_STEREO view configuration");
  std::vector<XrViewConfigurationView> views(n, {XR_TYPE_VIEW_CONFIGURATION_VIEW});
  if (XrResult r = xrEnumerateViewConfigurationViews(
          instance_, system_, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, n, &n, views.data());
      XR_FAILED(r)) {
    return Status::Error("xrEnumerateViewConfigurationViews: " + ResultString(instance_, r));
  }
  eye_width_ = static_cast<int>(views[0].recommendedImageRectWidth);
  eye_height_ = static_cast<int>(views[0].recommendedImageRectHeight);
  return platform_->CheckGraphicsRequirements(instance_, system_);
}

Status XrSessionDriver::CreateSession() {
  XrSessionCreateInfo info{XR_TYPE_SESSION_CREATE_INFO};
  info.next = platform_->GraphicsBinding(egl_);
  info.systemId = system_;
  if (XrResult r = xrCreateSession(instance_, &info, &session_); XR_FAILED(r)) {
    return Status::Error("xrCreateSession failed: " + ResultString(instance_, r));
  }
  ++sessions_created_;
  session_lost_ = false;
  state_ = XR_SESSION_STATE_UNKNOWN;
  if (XrResult r = controls_->Attach(session_); XR_FAILED(r)) {
    return Status::Error("xrAttachSessionActionSets failed: " + ResultString(instance_, r));
  }
  XrReferenceSpaceCreateInfo space{XR_TYPE_REFERENCE_SPACE_CREATE_INFO};
  space.poseInReferenceSpace.orientation.w = 1.f;
  space.referenceSpaceType =
      options_.stage_space ? XR_REFERENCE_SPACE_TYPE_STAGE : XR_REFERENCE_SPACE_TYPE_LOCAL;
  if (XrResult r = xrCreateReferenceSpace(session_, &space, &world_space_); XR_FAILED(r)) {
    return Status::Error("xrCreateReferenceSpace(world) failed: " + ResultString(instance_, r));
  }
  space.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_VIEW;
  if (XrResult r = xrCreateReferenceSpace(session_, &space, &view_space_); XR_FAILED(r)) {
    return Status::Error("xrCreateReferenceSpace(VIEW) failed: " + ResultString(instance_, r));
  }
  uint32_t n = 0;
  xrEnumerateSwapchainFormats(session_, 0, &n, nullptr);
  std::vector<int64_t> formats(n);
  xrEnumerateSwapchainFormats(session_, n, &n, formats.data());
  swapchain_format_ = 0;
  for (int64_t preferred : {int64_t{GL_SRGB8_ALPHA8}, int64_t{GL_RGBA8}}) {
    for (int64_t f : formats) {
      if (f == preferred && swapchain_format_ == 0) swapchain_format_ = f;
    }
  }
  if (swapchain_format_ == 0) return Status::Error("no RGBA8 / SRGB8_ALPHA8 swapchain format");
  for (EyeSwapchain& eye : eyes_) {
    XrSwapchainCreateInfo sc{XR_TYPE_SWAPCHAIN_CREATE_INFO};
    sc.usageFlags = XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT | XR_SWAPCHAIN_USAGE_SAMPLED_BIT;
    sc.format = swapchain_format_;
    sc.sampleCount = sc.faceCount = sc.arraySize = sc.mipCount = 1;
    sc.width = static_cast<uint32_t>(eye_width_);
    sc.height = static_cast<uint32_t>(eye_height_);
    if (XrResult r = xrCreateSwapchain(session_, &sc, &eye.handle); XR_FAILED(r)) {
      return Status::Error("xrCreateSwapchain failed: " + ResultString(instance_, r));
    }
    xrEnumerateSwapchainImages(eye.handle, 0, &n, nullptr);
    eye.images.assign(n, {XR_TYPE_SWAPCHAIN_IMAGE_OPENGL_ES_KHR});
    xrEnumerateSwapchainImages(eye.handle, n, &n,
                               reinterpret_cast<XrSwapchainImageBaseHeader*>(eye.images.data()));
    glGenFramebuffers(1, &eye.framebuffer);
    glGenRenderbuffers(1, &eye.depth);
    glBindRenderbuffer(GL_RENDERBUFFER, eye.depth);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, eye_width_, eye_height_);
    glBindRenderbuffer(GL_RENDERBUFFER, 0);
  }
  M2S_LOG(kInfo) << "OpenXR session " << sessions_created_ << ": eyes " << eye_width_ << "x"
                 << eye_height_ << (swapchain_format_ == GL_SRGB8_ALPHA8 ? " sRGB" : " RGBA8")
                 << ", world space " << (options_.stage_space ? "STAGE" : "LOCAL");
  return Status::Ok();
}

void XrSessionDriver::DestroySession() {
  for (EyeSwapchain& eye : eyes_) {
    if (eye.framebuffer != 0) glDeleteFramebuffers(1, &eye.framebuffer);
    if (eye.depth != 0) glDeleteRenderbuffers(1, &eye.depth);
    if (eye.handle != XR_NULL_HANDLE) xrDestroySwapchain(eye.handle);
    eye = EyeSwapchain();
  }
  if (view_space_ != XR_NULL_HANDLE) xrDestroySpace(view_space_);
  if (world_space_ != XR_NULL_HANDLE) xrDestroySpace(world_space_);
  view_space_ = world_space_ = XR_NULL_HANDLE;
  if (session_ != XR_NULL_HANDLE) xrDestroySession(session_);
  session_ = XR_NULL_HANDLE;
  running_ = false;
  frame_begun_ = false;
}

void XrSessionDriver::OnStateChanged(XrSessionState state) {
  state_ = state;
  state_log_.push_back(StateName(state));
  M2S_LOG(kInfo) << "OpenXR session state: " << StateName(state);
  switch (state) {
    case XR_SESSION_STATE_READY: {
      XrSessionBeginInfo begin{XR_TYPE_SESSION_BEGIN_INFO};
      begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
      if (Check(xrBeginSession(session_, &begin), "xrBeginSession")) running_ = true;
      if (running_ && exit_requested_)
        Check(xrRequestExitSession(session_), "xrRequestExitSession");
      break;
    }
    case XR_SESSION_STATE_STOPPING:
      Check(xrEndSession(session_), "xrEndSession");
      running_ = false;
      frame_begun_ = false;
      break;
    case XR_SESSION_STATE_EXITING:
      exiting_ = true;
      break;
    case XR_SESSION_STATE_LOSS_PENDING:
      session_lost_ = true;
      break;
    default:
      break;
  }
}

LoopAction XrSessionDriver::PollEvents() {
  while (!instance_lost_ && error_.empty()) {
    XrEventDataBuffer event{XR_TYPE_EVENT_DATA_BUFFER};
    const XrResult r = xrPollEvent(instance_, &event);
    if (r == XR_EVENT_UNAVAILABLE) break;
    if (!Check(r, "xrPollEvent")) break;
    switch (event.type) {
      case XR_TYPE_EVENT_DATA_INSTANCE_LOSS_PENDING:
        M2S_LOG(kWarning) << "OpenXR instance loss pending";
        instance_lost_ = true;
        break;
      case XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED: {
        const auto& changed = reinterpret_cast<const XrEventDataSessionStateChanged&>(event);
        if (changed.session == session_) OnStateChanged(changed.state);
        break;
      }
      case XR_TYPE_EVENT_DATA_EVENTS_LOST:
        M2S_LOG(kWarning) << "OpenXR events lost";
        break;
      default:
        break;
    }
  }
  if (instance_lost_) {
    state_log_.push_back("INSTANCE_LOST");
    M2S_LOG(kWarning) << "OpenXR instance lost: leaving";
    return LoopAction::kExit;
  }
  if (!error_.empty() || exiting_) return LoopAction::kExit;
  if (session_lost_) {
    // Destroy everything of the lost session and start a new one when the system is back.
    M2S_LOG(kWarning) << "OpenXR session lost: recreating";
    DestroySession();
    if (Status s = GetSystem(); !s) {
      if (!instance_lost_) error_ = s.message();
      return LoopAction::kExit;
    }
    if (Status s = CreateSession(); !s) {
      error_ = s.message();
      return LoopAction::kExit;
    }
    return LoopAction::kIdle;
  }
  return running_ ? LoopAction::kRunFrame : LoopAction::kIdle;
}

bool XrSessionDriver::BeginFrame(FrameInfo* frame) {
  if (!running_ || session_lost_) return false;
  XrFrameState state{XR_TYPE_FRAME_STATE};
  if (!Check(xrWaitFrame(session_, nullptr, &state), "xrWaitFrame")) return false;
  if (!Check(xrBeginFrame(session_, nullptr), "xrBeginFrame")) return false;
  frame_begun_ = true;
  frame->index = frames_begun_++;
  const size_t presses_before = pressed_.size();
  if (const XrResult r = controls_->Sync(session_, &pressed_); r != XR_SESSION_NOT_FOCUSED) {
    Check(r, "xrSyncActions");
  }
  controller_presses_ += static_cast<int64_t>(pressed_.size() - presses_before);
  frame->display_time = state.predictedDisplayTime;
  frame->should_render = state.shouldRender == XR_TRUE;
  frame->view_valid = false;
  for (EyeSwapchain& eye : eyes_) eye.rendered = false;
  XrSpaceLocation location{XR_TYPE_SPACE_LOCATION};
  if (!Check(xrLocateSpace(view_space_, world_space_, state.predictedDisplayTime, &location),
             "xrLocateSpace")) {
    return true;  // the frame was begun: it must still be ended
  }
  constexpr XrSpaceLocationFlags kValid =
      XR_SPACE_LOCATION_ORIENTATION_VALID_BIT | XR_SPACE_LOCATION_POSITION_VALID_BIT;
  frame->view_valid = (location.locationFlags & kValid) == kValid;
  frame->world_from_view_xr = FromXr(location.pose);
  XrViewLocateInfo locate{XR_TYPE_VIEW_LOCATE_INFO};
  locate.viewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  locate.displayTime = state.predictedDisplayTime;
  locate.space = world_space_;
  XrViewState view_state{XR_TYPE_VIEW_STATE};
  XrView views[2] = {{XR_TYPE_VIEW}, {XR_TYPE_VIEW}};
  uint32_t n = 0;
  if (!Check(xrLocateViews(session_, &locate, &view_state, 2, &n, views), "xrLocateViews")) {
    frame->should_render = false;
    return true;
  }
  for (int i = 0; i < 2; ++i) {
    frame->eyes[i].world_from_eye_xr = FromXr(views[i].pose);
    frame->eyes[i].fov = {views[i].fov.angleLeft, views[i].fov.angleRight, views[i].fov.angleUp,
                          views[i].fov.angleDown};
  }
  return true;
}

bool XrSessionDriver::RenderEye(int eye_index, const std::function<void(int, int)>& draw) {
  EyeSwapchain& eye = eyes_.at(eye_index);
  uint32_t image = 0;
  if (!Check(xrAcquireSwapchainImage(eye.handle, nullptr, &image), "xrAcquireSwapchainImage")) {
    return false;
  }
  XrSwapchainImageWaitInfo wait{XR_TYPE_SWAPCHAIN_IMAGE_WAIT_INFO};
  wait.timeout = XR_INFINITE_DURATION;
  if (!Check(xrWaitSwapchainImage(eye.handle, &wait), "xrWaitSwapchainImage")) return false;
  glBindFramebuffer(GL_FRAMEBUFFER, eye.framebuffer);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D,
                         eye.images[image].image, 0);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, eye.depth);
  glViewport(0, 0, eye_width_, eye_height_);
  draw(eye_width_, eye_height_);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  if (!Check(xrReleaseSwapchainImage(eye.handle, nullptr), "xrReleaseSwapchainImage")) {
    return false;
  }
  eye.rendered = true;
  return true;
}

bool XrSessionDriver::EndFrame(const FrameInfo& frame) {
  if (!frame_begun_) return false;
  frame_begun_ = false;
  XrCompositionLayerProjectionView views[2];
  for (int i = 0; i < 2; ++i) {
    views[i] = {XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW};
    views[i].pose = ToXr(frame.eyes[i].world_from_eye_xr);
    const FieldOfView& fov = frame.eyes[i].fov;
    views[i].fov = {static_cast<float>(fov.angle_left), static_cast<float>(fov.angle_right),
                    static_cast<float>(fov.angle_up), static_cast<float>(fov.angle_down)};
    views[i].subImage.swapchain = eyes_[i].handle;
    views[i].subImage.imageRect = {{0, 0}, {eye_width_, eye_height_}};
  }
  XrCompositionLayerProjection layer{XR_TYPE_COMPOSITION_LAYER_PROJECTION};
  layer.space = world_space_;
  layer.viewCount = 2;
  layer.views = views;
  const XrCompositionLayerBaseHeader* layers[] = {
      reinterpret_cast<const XrCompositionLayerBaseHeader*>(&layer)};
  XrFrameEndInfo end{XR_TYPE_FRAME_END_INFO};
  end.displayTime = frame.display_time;
  end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  end.layerCount = (frame.should_render && eyes_[0].rendered && eyes_[1].rendered) ? 1 : 0;
  end.layers = layers;
  return Check(xrEndFrame(session_, &end), "xrEndFrame");
}

std::vector<ControllerAction> XrSessionDriver::TakeControllerPresses() {
  std::vector<ControllerAction> pressed;
  pressed.swap(pressed_);
  return pressed;
}

void XrSessionDriver::RequestExit() {
  if (exit_requested_) return;
  exit_requested_ = true;
  if (running_ && !session_lost_) Check(xrRequestExitSession(session_), "xrRequestExitSession");
}

}  // namespace m2s::xr
