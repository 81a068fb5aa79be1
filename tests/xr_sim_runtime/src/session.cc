// Session lifecycle, the state machine driven by the app and the script, and the frame loop.
#include <cstring>
#include <thread>

#include "api.h"

namespace m2s::xrsim {

void SetState(InstanceObj& instance, SessionObj& session, XrSessionState state) {
  session.state = state;
  XrEventDataBuffer buffer{XR_TYPE_EVENT_DATA_BUFFER};
  auto* event = reinterpret_cast<XrEventDataSessionStateChanged*>(&buffer);
  *event = {XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED};
  event->session = session.handle;
  event->state = state;
  event->time = instance.Now();
  instance.events.push_back(buffer);
  instance.transitions.push_back("frame " + std::to_string(instance.frame_counter) + ": " +
                                 StateName(state));
  if (instance.config.verbose) LogInfo(std::string("session state -> ") + StateName(state));
}

namespace {

// 0: SYNCHRONIZED, 1: VISIBLE, 2: FOCUSED.
int Level(XrSessionState state) {
  switch (state) {
    case XR_SESSION_STATE_VISIBLE:
      return 1;
    case XR_SESSION_STATE_FOCUSED:
      return 2;
    default:
      return 0;
  }
}

int TargetLevel(const InstanceObj& instance) {
  int level = 2;
  const int64_t frame = instance.frame_counter;
  for (const ScriptEvent& e : instance.config.script) {
    if (frame < e.frame || frame >= e.frame + e.duration) continue;
    if (e.kind == ScriptEvent::Kind::kFocusLoss) level = std::min(level, 1);
    if (e.kind == ScriptEvent::Kind::kHide) level = 0;
  }
  return level;
}

// Walks FOCUSED <-> VISIBLE <-> SYNCHRONIZED one state at a time, as a runtime must.
void StepTo(InstanceObj& instance, SessionObj& session, int target) {
  static constexpr XrSessionState kByLevel[] = {XR_SESSION_STATE_SYNCHRONIZED,
                                                XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_FOCUSED};
  int level = Level(session.state);
  while (level != target) {
    level += target > level ? 1 : -1;
    SetState(instance, session, kByLevel[level]);
  }
}

void BeginStopping(InstanceObj& instance, SessionObj& session) {
  if (session.stopping || session.lost) return;
  session.stopping = true;
  if (!session.running) return;  // reaches STOPPING once it runs and synchronises
  if (session.synchronized_once) StepTo(instance, session, 0);
  SetState(instance, session, XR_SESSION_STATE_STOPPING);
}

}  // namespace

void UpdateVisibility(InstanceObj& instance, SessionObj& session) {
  if (!session.running || session.lost || session.stopping || !session.synchronized_once) return;
  StepTo(instance, session, TargetLevel(instance));
}

void RunScript(InstanceObj& instance) {
  Runtime& rt = Runtime::Get();
  SessionObj* session = instance.session ? rt.FindSession(instance.session) : nullptr;
  for (const ScriptEvent& e : instance.config.script) {
    if (e.frame != instance.frame_counter) continue;
    switch (e.kind) {
      case ScriptEvent::Kind::kExit:
        if (session) BeginStopping(instance, *session);
        break;
      case ScriptEvent::Kind::kSessionLoss:
        if (session && !session->lost) {
          SetState(instance, *session, XR_SESSION_STATE_LOSS_PENDING);
          session->lost = true;
          instance.unavailable_system_calls = kUnavailableSystemCallsAfterLoss;
        }
        break;
      case ScriptEvent::Kind::kInstanceLoss: {
        XrEventDataBuffer buffer{XR_TYPE_EVENT_DATA_BUFFER};
        auto* event = reinterpret_cast<XrEventDataInstanceLossPending*>(&buffer);
        *event = {XR_TYPE_EVENT_DATA_INSTANCE_LOSS_PENDING};
        event->lossTime = instance.Now();
        instance.events.push_back(buffer);
        instance.transitions.push_back("frame " + std::to_string(instance.frame_counter) +
                                       ": INSTANCE_LOSS_PENDING");
        instance.lost = true;
        break;
      }
      case ScriptEvent::Kind::kFocusLoss:
      case ScriptEvent::Kind::kHide:
        break;  // windows, applied by UpdateVisibility
    }
  }
}

namespace api {
XrResult XRAPI_CALL CreateSession(XrInstance instance, const XrSessionCreateInfo* info,
                                  XrSession* session) {
  constexpr const char* kFn = "xrCreateSession";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  InstanceObj* inst = rt.FindInstance(instance);
  M2S_SIM_REQUIRE(inst != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrInstance");
  if (inst->lost) return XR_ERROR_INSTANCE_LOST;
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_SESSION_CREATE_INFO, "createInfo");
  M2S_SIM_REQUIRE(session != nullptr, XR_ERROR_VALIDATION_FAILURE, "session output is NULL");
  M2S_SIM_REQUIRE(info->systemId == kSystemId && inst->system_queried, XR_ERROR_SYSTEM_INVALID,
                  "systemId was not returned by xrGetSystem");
  M2S_SIM_REQUIRE(inst->session == XR_NULL_HANDLE, XR_ERROR_LIMIT_REACHED,
                  "a session already exists on this instance");
  const XrGraphicsBindingEGLMNDX* binding = nullptr;
  for (auto* next = static_cast<const XrBaseInStructure*>(info->next); next; next = next->next) {
    if (next->type == XR_TYPE_GRAPHICS_BINDING_EGL_MNDX) {
      binding = reinterpret_cast<const XrGraphicsBindingEGLMNDX*>(next);
    }
  }
  M2S_SIM_REQUIRE(binding != nullptr, XR_ERROR_GRAPHICS_DEVICE_INVALID,
                  "no XrGraphicsBindingEGLMNDX in the next chain (headless sessions unsupported)");
  M2S_SIM_REQUIRE(inst->egl_enabled, XR_ERROR_VALIDATION_FAILURE,
                  "XrGraphicsBindingEGLMNDX used without enabling XR_MNDX_egl_enable");
  EGLint config_id = 0;
  M2S_SIM_REQUIRE(binding->display != EGL_NO_DISPLAY && binding->context != EGL_NO_CONTEXT &&
                      binding->getProcAddress != nullptr &&
                      eglQueryContext(binding->display, binding->context, EGL_CONFIG_ID,
                                      &config_id) == EGL_TRUE,
                  XR_ERROR_GRAPHICS_DEVICE_INVALID,
                  "the EGL display/context of the binding is not valid");
  auto obj = std::make_unique<SessionObj>();
  obj->handle = ToHandle<XrSession>(rt.NewHandle());
  obj->instance = instance;
  obj->display = binding->display;
  obj->context = binding->context;
  inst->session = obj->handle;
  *session = obj->handle;
  ++inst->counters.sessions_created;
  SessionObj& s = *obj;
  rt.sessions[reinterpret_cast<uint64_t>(obj->handle)] = std::move(obj);
  SetState(*inst, s, XR_SESSION_STATE_IDLE);
  SetState(*inst, s, XR_SESSION_STATE_READY);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL DestroySession(XrSession session) {
  constexpr const char* kFn = "xrDestroySession";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  SessionObj* s = rt.FindSession(session);
  M2S_SIM_REQUIRE(s != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrSession");
  InstanceObj* inst = rt.InstanceOf(*s);
  int64_t children = 0;
  for (auto it = rt.spaces.begin(); it != rt.spaces.end();) {
    it = it->second->session == session ? (++children, rt.spaces.erase(it)) : std::next(it);
  }
  for (auto it = rt.swapchains.begin(); it != rt.swapchains.end();) {
    it = it->second->session == session ? (++children, rt.swapchains.erase(it)) : std::next(it);
  }
  if (children > 0) {
    // Allowed by the spec, but an app that cleans up properly destroys them first.
    LogInfo("WARNING: xrDestroySession freed " + std::to_string(children) +
            " space/swapchain handle(s) the app did not destroy");
    inst->counters.implicitly_destroyed += children;
  }
  if (s->running && !s->lost && !inst->lost) ++inst->counters.sessions_destroyed_running;
  ++inst->counters.sessions_destroyed;
  inst->session = XR_NULL_HANDLE;
  // Events about a destroyed session must not be delivered afterwards.
  std::erase_if(inst->events, [&](const XrEventDataBuffer& e) {
    return e.type == XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED &&
           reinterpret_cast<const XrEventDataSessionStateChanged&>(e).session == session;
  });
  rt.sessions.erase(reinterpret_cast<uint64_t>(session));
  return XR_SUCCESS;
}

XrResult XRAPI_CALL BeginSession(XrSession session, const XrSessionBeginInfo* info) {
  constexpr const char* kFn = "xrBeginSession";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_SESSION_BEGIN_INFO, "beginInfo");
  M2S_SIM_REQUIRE(info->primaryViewConfigurationType == XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO,
                  XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED, "only PRIMARY_STEREO");
  M2S_SIM_REQUIRE(!s->running, XR_ERROR_SESSION_RUNNING, "session is already running");
  M2S_SIM_REQUIRE(s->state == XR_SESSION_STATE_READY, XR_ERROR_SESSION_NOT_READY,
                  std::string("session state is ") + StateName(s->state) + ", not READY");
  s->running = true;
  if (s->stopping) {  // an exit was requested before the session ran
    s->stopping = false;
    BeginStopping(*inst, *s);
  }
  return XR_SUCCESS;
}

XrResult XRAPI_CALL EndSession(XrSession session) {
  constexpr const char* kFn = "xrEndSession";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE(s->running, XR_ERROR_SESSION_NOT_RUNNING, "session is not running");
  M2S_SIM_REQUIRE(s->state == XR_SESSION_STATE_STOPPING, XR_ERROR_SESSION_NOT_STOPPING,
                  std::string("session state is ") + StateName(s->state) + ", not STOPPING");
  if (s->frame_begun) ++inst->counters.frames_discarded;
  s->running = false;
  s->frame_waited = s->frame_begun = false;
  SetState(*inst, *s, XR_SESSION_STATE_IDLE);
  SetState(*inst, *s, XR_SESSION_STATE_EXITING);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL RequestExitSession(XrSession session) {
  constexpr const char* kFn = "xrRequestExitSession";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE(s->running, XR_ERROR_SESSION_NOT_RUNNING, "session is not running");
  BeginStopping(*inst, *s);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL WaitFrame(XrSession session, const XrFrameWaitInfo* info, XrFrameState* state) {
  constexpr const char* kFn = "xrWaitFrame";
  std::unique_lock<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  if (info != nullptr) M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_FRAME_WAIT_INFO, "frameWaitInfo");
  M2S_SIM_REQUIRE_TYPE(state, XR_TYPE_FRAME_STATE, "frameState");
  M2S_SIM_REQUIRE(s->running, XR_ERROR_SESSION_NOT_RUNNING, "session is not running");
  // A real runtime would block until the previous frame is begun (a deadlock for a
  // single-threaded app); the simulation reports it instead.
  M2S_SIM_REQUIRE(!s->frame_waited, XR_ERROR_CALL_ORDER_INVALID,
                  "xrWaitFrame again before xrBeginFrame of the previous wait");
  ++inst->frame_counter;
  ++inst->counters.frames_waited;
  RunScript(*inst);
  if (inst->lost) return XR_ERROR_INSTANCE_LOST;
  if (s->lost) return XR_ERROR_SESSION_LOST;
  if (!s->synchronized_once && s->state == XR_SESSION_STATE_READY) {
    s->synchronized_once = true;
    SetState(*inst, *s, XR_SESSION_STATE_SYNCHRONIZED);
    if (s->stopping) SetState(*inst, *s, XR_SESSION_STATE_STOPPING);
  } else {
    UpdateVisibility(*inst, *s);
  }
  const int64_t frame = inst->frame_counter;
  s->frame_waited = true;
  s->waited_frame = frame;
  state->predictedDisplayTime = inst->DisplayTime(frame);
  state->predictedDisplayPeriod = inst->period_ns();
  state->shouldRender =
      (s->state == XR_SESSION_STATE_VISIBLE || s->state == XR_SESSION_STATE_FOCUSED) ? XR_TRUE
                                                                                     : XR_FALSE;
  if (inst->config.realtime) {
    const auto wake = inst->wall_origin + std::chrono::nanoseconds(frame * inst->period_ns());
    lock.unlock();
    std::this_thread::sleep_until(wake);
  }
  return XR_SUCCESS;
}

XrResult XRAPI_CALL BeginFrame(XrSession session, const XrFrameBeginInfo* info) {
  constexpr const char* kFn = "xrBeginFrame";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  if (info != nullptr) M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_FRAME_BEGIN_INFO, "frameBeginInfo");
  M2S_SIM_REQUIRE(s->running, XR_ERROR_SESSION_NOT_RUNNING, "session is not running");
  M2S_SIM_REQUIRE(s->frame_waited, XR_ERROR_CALL_ORDER_INVALID,
                  "xrBeginFrame without a preceding xrWaitFrame");
  s->frame_waited = false;
  ++inst->counters.frames_begun;
  const bool discarded = s->frame_begun;  // the previous frame never reached xrEndFrame
  if (discarded) ++inst->counters.frames_discarded;
  s->frame_begun = true;
  s->begun_frame = s->waited_frame;
  return discarded ? XR_FRAME_DISCARDED : XR_SUCCESS;
}

}  // namespace api
}  // namespace m2s::xrsim
