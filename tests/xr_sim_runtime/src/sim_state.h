// State of the simulated OpenXR runtime: the handle objects, the runtime-wide registry and the
// misuse accounting shared by every entry point.
//
// Thread-safety: every entry point locks Runtime::mutex() for its whole body (OpenXR allows
// calls from several threads; the runtime is a test double and serialises them). The registry
// is the one process-wide object a runtime loaded by the OpenXR loader can have: the loader
// hands out only function pointers.
//
// Honesty: each entry point validates handles, structure types and call order and returns the
// XR_ERROR_* code the specification names. Every such rejection is "misuse": it is logged to
// stderr with a MISUSE prefix, counted, and listed in the report written on xrDestroyInstance.
// Errors the runtime itself causes (session or instance loss, an unavailable system) are
// returned but not counted.
#pragma once

#include <EGL/egl.h>
#include <EGL/eglext.h>
#define XR_USE_PLATFORM_EGL
#define XR_USE_GRAPHICS_API_OPENGL_ES
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>

#include <chrono>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "sim_config.h"

namespace m2s::xrsim {

constexpr uint32_t kSwapchainImageCount = 3;
constexpr uint32_t kMaxSwapchainSize = 4096;
constexpr uint32_t kMaxLayers = 16;
constexpr int kUnavailableSystemCallsAfterLoss = 2;
constexpr XrSystemId kSystemId = 1;
constexpr int64_t kDefaultTimeOriginNs = 1'000'000'000;

struct Counters {
  int64_t frames_waited = 0;
  int64_t frames_begun = 0;
  int64_t frames_ended = 0;
  int64_t frames_discarded = 0;
  int64_t layers_submitted = 0;
  int64_t events_delivered = 0;
  int64_t captures = 0;
  int64_t sessions_created = 0;
  int64_t sessions_destroyed = 0;
  int64_t sessions_destroyed_running = 0;  // destroyed without xrEndSession (not after a loss)
  int64_t spaces_created = 0;
  int64_t spaces_destroyed = 0;
  int64_t swapchains_created = 0;
  int64_t swapchains_destroyed = 0;
  int64_t implicitly_destroyed = 0;  // children freed with their parent, not by the app
  int64_t gl_failures = 0;
  int64_t action_sets_created = 0;
  int64_t action_sets_destroyed = 0;
  int64_t actions_created = 0;
  int64_t actions_destroyed = 0;
  int64_t action_syncs = 0;            // xrSyncActions calls that succeeded
  int64_t action_syncs_unfocused = 0;  // ... of which answered XR_SESSION_NOT_FOCUSED
};

// An interaction profile's suggested bindings: (action, input path) pairs.
using Bindings = std::vector<std::pair<XrAction, XrPath>>;

struct InstanceObj {
  XrInstance handle = XR_NULL_HANDLE;
  std::string application_name;
  bool egl_enabled = false;
  bool system_queried = false;
  bool lost = false;
  int unavailable_system_calls = 0;
  SimConfig config;
  HeadTrajectory trajectory;
  XrTime time_origin = kDefaultTimeOriginNs;  // display time of frame 0
  double trajectory_time_origin = 0.0;        // trajectory stamp played at frame 0
  std::chrono::steady_clock::time_point wall_origin;
  int64_t frame_counter = 0;           // xrWaitFrame calls so far (the script's clock)
  XrSession session = XR_NULL_HANDLE;  // the live session, if any
  std::deque<XrEventDataBuffer> events;
  Counters counters;
  int64_t misuse_at_create = 0;
  std::vector<std::string> transitions;  // "frame N: STATE"
  std::vector<std::string> captures;
  // Semantic paths (xrStringToPath): XrPath n names path_strings[n - 1].
  std::vector<std::string> path_strings;
  std::map<std::string, XrPath> paths;
  std::map<XrPath, Bindings> suggested_bindings;  // by interaction profile

  XrDuration period_ns() const { return static_cast<XrDuration>(1e9 / config.rate_hz + 0.5); }
  XrTime DisplayTime(int64_t frame) const { return time_origin + frame * period_ns(); }
  XrTime Now() const { return DisplayTime(frame_counter); }
  // Head pose (VIEW in LOCAL) at a display time.
  SimPose Head(XrTime time) const {
    return trajectory.Sample(trajectory_time_origin + (time - time_origin) * 1e-9);
  }
};

struct SessionObj {
  XrSession handle = XR_NULL_HANDLE;
  XrInstance instance = XR_NULL_HANDLE;
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
  XrSessionState state = XR_SESSION_STATE_UNKNOWN;
  bool running = false;
  bool stopping = false;  // heading to STOPPING (app or script asked to exit)
  bool lost = false;
  bool synchronized_once = false;
  // Frame loop: a frame is waited, then begun, then ended.
  bool frame_waited = false;  // xrWaitFrame returned, xrBeginFrame not yet called
  bool frame_begun = false;   // xrBeginFrame returned, xrEndFrame not yet called
  int64_t waited_frame = -1;
  int64_t begun_frame = -1;
  // Actions (xrAttachSessionActionSets, once per session).
  bool actions_attached = false;
  std::vector<XrActionSet> attached_action_sets;
  XrPath interaction_profile = XR_NULL_PATH;  // of both hands; XR_NULL_PATH: no bindings
  Bindings bindings;                          // those suggested for interaction_profile
};

struct ActionSetObj {
  XrActionSet handle = XR_NULL_HANDLE;
  XrInstance instance = XR_NULL_HANDLE;
  std::string name;
  std::string localized_name;
  uint32_t priority = 0;
  bool attached = false;  // to any session: then immutable (no new actions, no suggestions)
};

// The state of an action as of the last xrSyncActions, for one subaction path (XR_NULL_PATH:
// every binding).
struct ActionState {
  float value = 0.f;  // boolean actions: 0 or 1
  bool changed = false;
  bool active = false;
  XrTime last_change_time = 0;
};

struct ActionObj {
  XrAction handle = XR_NULL_HANDLE;
  XrActionSet action_set = XR_NULL_HANDLE;
  std::string name;
  std::string localized_name;
  XrActionType type = XR_ACTION_TYPE_BOOLEAN_INPUT;
  std::vector<XrPath> subaction_paths;
  std::map<XrPath, ActionState> states;  // by subaction path, XR_NULL_PATH included
};

struct SpaceObj {
  XrSpace handle = XR_NULL_HANDLE;
  XrSession session = XR_NULL_HANDLE;
  XrReferenceSpaceType type = XR_REFERENCE_SPACE_TYPE_LOCAL;
  SimPose reference_from_space;
};

struct SwapchainObj {
  XrSwapchain handle = XR_NULL_HANDLE;
  XrSession session = XR_NULL_HANDLE;
  int64_t format = 0;
  uint32_t width = 0;
  uint32_t height = 0;
  std::vector<uint32_t> textures;  // GL texture names in the app's context
  std::deque<uint32_t> acquired;   // acquired, not yet released, oldest first
  bool oldest_waited = false;
  uint32_t next_index = 0;
  int64_t last_released = -1;
};

class Runtime {
 public:
  static Runtime& Get();
  std::mutex& mutex() { return mutex_; }

  uint64_t NewHandle() { return next_handle_++; }
  std::map<uint64_t, std::unique_ptr<InstanceObj>> instances;
  std::map<uint64_t, std::unique_ptr<SessionObj>> sessions;
  std::map<uint64_t, std::unique_ptr<SpaceObj>> spaces;
  std::map<uint64_t, std::unique_ptr<SwapchainObj>> swapchains;
  std::map<uint64_t, std::unique_ptr<ActionSetObj>> action_sets;
  std::map<uint64_t, std::unique_ptr<ActionObj>> actions;

  // Logs "m2s_xr_sim: MISUSE #n in FUNCTION: RESULT: message", counts it, returns result.
  XrResult Misuse(const char* function, XrResult result, const std::string& message);
  // Counts a misuse the call still succeeds with (handles left alive at xrDestroyInstance).
  void MisuseWithoutError(const char* function, const std::string& message);
  int64_t misuse_count() const { return static_cast<int64_t>(misuse_log_.size()); }
  const std::vector<std::string>& misuse_log() const { return misuse_log_; }

  InstanceObj* FindInstance(XrInstance h) { return Find(instances, h); }
  SessionObj* FindSession(XrSession h) { return Find(sessions, h); }
  SpaceObj* FindSpace(XrSpace h) { return Find(spaces, h); }
  SwapchainObj* FindSwapchain(XrSwapchain h) { return Find(swapchains, h); }
  ActionSetObj* FindActionSet(XrActionSet h) { return Find(action_sets, h); }
  ActionObj* FindAction(XrAction h) { return Find(actions, h); }
  InstanceObj* InstanceOf(const SessionObj& s) { return FindInstance(s.instance); }
  // Destroys an action set and its actions; returns how many handles that was.
  int64_t EraseActionSet(XrActionSet h);

 private:
  template <typename Map, typename Handle>
  static typename Map::mapped_type::element_type* Find(Map& map, Handle handle) {
    const auto it = map.find(reinterpret_cast<uint64_t>(handle));
    return it == map.end() ? nullptr : it->second.get();
  }

  std::mutex mutex_;
  uint64_t next_handle_ = 0x1000;
  std::vector<std::string> misuse_log_;
};

template <typename Handle>
Handle ToHandle(uint64_t value) {
  return reinterpret_cast<Handle>(value);
}

// Logging to stderr with the runtime's prefix (a runtime has no other channel to the user).
void LogInfo(const std::string& message);
const char* ResultName(XrResult result);
const char* StateName(XrSessionState state);

// Queues a session state change event and records the transition.
void SetState(InstanceObj& instance, SessionObj& session, XrSessionState state);
// Moves a synchronised session towards the level the script asks for at the current frame.
void UpdateVisibility(InstanceObj& instance, SessionObj& session);
// Runs the script events due at the current frame.
void RunScript(InstanceObj& instance);

// Makes the session's EGL context current for GL work and restores the previous one after.
class ScopedAppContext {
 public:
  explicit ScopedAppContext(const SessionObj& session);
  ~ScopedAppContext();
  bool ok() const { return ok_; }

 private:
  bool ok_ = false;
  bool switched_ = false;
  EGLDisplay previous_display_ = EGL_NO_DISPLAY;
  EGLSurface previous_draw_ = EGL_NO_SURFACE;
  EGLSurface previous_read_ = EGL_NO_SURFACE;
  EGLContext previous_context_ = EGL_NO_CONTEXT;
};

// Writes the left-eye image of a projection layer (see M2S_XR_SIM_CAPTURE_* in sim_config.h).
void CaptureLeftEye(InstanceObj& instance, SessionObj& session,
                    const XrCompositionLayerProjection& layer, int64_t frame);
// The path of a string (interned: equal strings, equal paths), and back (nullptr: not a path
// of this instance).
XrPath InternPath(InstanceObj& instance, const std::string& path);
const std::string* PathString(const InstanceObj& instance, XrPath path);

// Writes the JSON report and prints the one-line summary; called by xrDestroyInstance.
void WriteReport(const InstanceObj& instance, int64_t live_children);

}  // namespace m2s::xrsim
