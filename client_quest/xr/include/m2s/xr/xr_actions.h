// ControllerActions: the app's controller buttons as OpenXR actions. One action set
// ("m2s_controls") with three boolean actions, bound for the Khronos simple controller and
// the Oculus Touch controller:
//
//   action                    khr/simple_controller          oculus/touch_controller
//   reset_slam                /user/hand/left/input/menu     /user/hand/right/input/b
//   toggle_overlay            /user/hand/right/input/select  /user/hand/right/input/a
//   toggle_other_keyframes    /user/hand/left/input/select   /user/hand/left/input/x
//   (all .../click)
//
// A press is a rising edge seen by xrSyncActions (currentState and changedSinceLastSync of an
// active action); only a focused session gets input.
//
// Thread-safety: the render thread only, like XrSessionDriver, which owns it: Create() after
// xrCreateInstance, Attach() on each new session, Sync() once per frame, destroyed before
// xrDestroyInstance.
//
//   auto actions = ControllerActions::Create(instance);
//   (*actions)->Attach(session);
//   std::vector<ControllerAction> pressed;
//   (*actions)->Sync(session, &pressed);
#pragma once

#include <array>
#include <memory>
#include <vector>

#include "m2s/common/status.h"
#include "m2s/xr/xr_headers.h"

namespace m2s::xr {

enum class ControllerAction { kResetSlam, kToggleOverlay, kToggleOtherKeyframes };

struct SuggestedBinding {
  const char* interaction_profile;
  ControllerAction action;
  const char* input_path;
};

// Every binding the app suggests, by profile.
const std::vector<SuggestedBinding>& ControllerBindings();

class ControllerActions {
 public:
  // Creates the action set and its actions and suggests the bindings. A profile the runtime
  // refuses is skipped with a warning; failing to create the actions is an error.
  static Expected<std::unique_ptr<ControllerActions>> Create(XrInstance instance);
  ~ControllerActions();
  ControllerActions(const ControllerActions&) = delete;
  ControllerActions& operator=(const ControllerActions&) = delete;

  // xrAttachSessionActionSets (once per session).
  XrResult Attach(XrSession session);
  // xrSyncActions, then appends the actions pressed since the previous sync to `pressed`.
  XrResult Sync(XrSession session, std::vector<ControllerAction>* pressed);

 private:
  explicit ControllerActions(XrInstance instance) : instance_(instance) {}

  XrInstance instance_;
  XrActionSet action_set_ = XR_NULL_HANDLE;
  std::array<XrAction, 3> actions_{};  // indexed by ControllerAction
};

}  // namespace m2s::xr
