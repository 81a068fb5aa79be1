// XrSessionDriver: the OpenXR side of the app. Owns the instance, the system, the session, the
// reference spaces (LOCAL or STAGE as the world, VIEW for the camera) and one GLES swapchain
// per eye, and follows every session state:
//   IDLE -> READY (xrBeginSession) -> SYNCHRONIZED -> VISIBLE -> FOCUSED, and back;
//   STOPPING (xrEndSession), EXITING (leave the loop), LOSS_PENDING (destroy the session and
//   create a new one once the system is available again), instance loss (leave the loop).
// The controller buttons are OpenXR actions (xr_actions.h): created with the instance,
// attached to every session, synced in BeginFrame; TakeControllerPresses() hands the presses on.
// The frame loop is BeginFrame (xrWaitFrame, xrBeginFrame, sync actions, locate the VIEW space
// and the eyes), RenderEye per eye (acquire, wait, draw into the eye's framebuffer, release),
// EndFrame (one projection layer, or none when the runtime says not to render).
//
// Thread-safety: one thread (the render thread, with the app's GLES context current) calls
// everything. Not copyable. The destructor destroys every handle in order (swapchains, spaces,
// session, instance), ending a running session first.
//
//   auto xr = XrSessionDriver::Create(options, platform.get(), egl);
//   while (xr->PollEvents() != LoopAction::kExit) {
//     FrameInfo frame;
//     if (!xr->running() || !xr->BeginFrame(&frame)) continue;
//     for (int eye : {0, 1}) xr->RenderEye(eye, frame, [&](int w, int h) { ... });
//     xr->EndFrame(frame);
//   }
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "m2s/common/geometry.h"
#include "m2s/common/status.h"
#include "m2s/xr/axis_conversion.h"
#include "m2s/xr/xr_actions.h"
#include "m2s/xr/xr_platform.h"

namespace m2s::xr {

struct XrSessionOptions {
  std::string application_name = "m2s_xr_client";
  bool stage_space = false;  // the world is STAGE (floor-level origin) instead of LOCAL
  // After a session loss: how many xrGetSystem attempts, and the wait between two.
  int system_retry_limit = 100;
  double system_retry_wait_s = 0.01;
  // Near/far planes of the eye projections (metres).
  double near_m = 0.05;
  double far_m = 100.0;
};

enum class LoopAction {
  kRunFrame,  // the session is running: run a frame
  kIdle,      // not running yet (or between sessions): poll again shortly
  kExit,      // EXITING, instance lost, or a fatal error (see error())
};

struct EyeView {
  Pose3 world_from_eye_xr;  // OpenXR axes (x right, y up, z backward)
  FieldOfView fov;
};

struct FrameInfo {
  int64_t index = 0;  // frames begun in this process
  XrTime display_time = 0;
  bool should_render = false;
  bool view_valid = false;      // the VIEW space was located (position and orientation)
  Pose3 world_from_view_xr;     // the centre eye (VIEW space) in the world space
  std::array<EyeView, 2> eyes;  // left, right
};

class XrSessionDriver {
 public:
  static Expected<std::unique_ptr<XrSessionDriver>> Create(const XrSessionOptions& options,
                                                           XrPlatform* platform,
                                                           const EglHandles& egl);
  ~XrSessionDriver();
  XrSessionDriver(const XrSessionDriver&) = delete;
  XrSessionDriver& operator=(const XrSessionDriver&) = delete;

  // Drains the event queue and acts on every state change; then says what to do.
  LoopAction PollEvents();
  bool running() const { return running_; }
  XrSessionState state() const { return state_; }
  bool focused() const { return state_ == XR_SESSION_STATE_FOCUSED; }

  // xrWaitFrame + xrBeginFrame + locate views. False when no frame was begun (session not
  // running, lost, or an error: PollEvents() reports what follows).
  bool BeginFrame(FrameInfo* frame);
  // Acquires the eye's swapchain image, binds a framebuffer (colour + depth) and the viewport,
  // calls draw(width, height), releases the image. Only between BeginFrame and EndFrame.
  bool RenderEye(int eye, const std::function<void(int width, int height)>& draw);
  // xrEndFrame with a projection layer of both eyes when the frame rendered, else no layer.
  bool EndFrame(const FrameInfo& frame);
  // Asks the runtime to stop the session (the states then lead to EXITING).
  void RequestExit();
  // The controller buttons pressed since the last call, in order.
  std::vector<ControllerAction> TakeControllerPresses();

  // The recommended eye image size.
  int eye_width() const { return eye_width_; }
  int eye_height() const { return eye_height_; }
  const std::string& runtime_name() const { return runtime_name_; }
  const std::string& error() const { return error_; }
  bool instance_lost() const { return instance_lost_; }
  int64_t sessions_created() const { return sessions_created_; }
  int64_t frames_begun() const { return frames_begun_; }
  int64_t controller_presses() const { return controller_presses_; }
  // Every state change seen, in order ("XR_SESSION_STATE_READY", ...).
  const std::vector<std::string>& state_log() const { return state_log_; }

 private:
  struct EyeSwapchain {
    XrSwapchain handle = XR_NULL_HANDLE;
    std::vector<XrSwapchainImageOpenGLESKHR> images;
    uint32_t framebuffer = 0;
    uint32_t depth = 0;
    bool rendered = false;
  };

  XrSessionDriver(const XrSessionOptions& options, XrPlatform* platform, const EglHandles& egl)
      : options_(options), platform_(platform), egl_(egl) {}
  Status CreateInstance();
  Status GetSystem();  // retries while the form factor is unavailable
  Status CreateSession();
  void DestroySession();
  void OnStateChanged(XrSessionState state);
  // Records a failed call: loss results set the flags, anything else is fatal.
  bool Check(XrResult result, const char* what);

  const XrSessionOptions options_;
  XrPlatform* const platform_;
  const EglHandles egl_;
  XrInstance instance_ = XR_NULL_HANDLE;
  XrSystemId system_ = XR_NULL_SYSTEM_ID;
  XrSession session_ = XR_NULL_HANDLE;
  XrSpace world_space_ = XR_NULL_HANDLE;
  XrSpace view_space_ = XR_NULL_HANDLE;
  std::array<EyeSwapchain, 2> eyes_;
  std::unique_ptr<ControllerActions> controls_;
  std::vector<ControllerAction> pressed_;
  int eye_width_ = 0;
  int eye_height_ = 0;
  int64_t swapchain_format_ = 0;
  XrSessionState state_ = XR_SESSION_STATE_UNKNOWN;
  bool running_ = false;
  bool exit_requested_ = false;
  bool exiting_ = false;
  bool session_lost_ = false;
  bool instance_lost_ = false;
  bool frame_begun_ = false;
  std::string error_;
  std::string runtime_name_;
  int64_t sessions_created_ = 0;
  int64_t frames_begun_ = 0;
  int64_t controller_presses_ = 0;
  std::vector<std::string> state_log_;
};

}  // namespace m2s::xr
