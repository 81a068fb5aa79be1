#include "m2s/xr/xr_actions.h"

#include <cstdio>
#include <string>

#include "m2s/common/logging.h"

namespace m2s::xr {
namespace {

constexpr const char* kSimpleController = "/interaction_profiles/khr/simple_controller";
constexpr const char* kTouchController = "/interaction_profiles/oculus/touch_controller";

struct ActionName {
  const char* name;
  const char* localized;
};
constexpr ActionName kActionNames[] = {{"reset_slam", "Reset SLAM"},
                                       {"toggle_overlay", "Toggle the map overlay"},
                                       {"toggle_other_keyframes", "Show other agents' keyframes"}};

size_t Index(ControllerAction action) { return static_cast<size_t>(action); }

}  // namespace

const std::vector<SuggestedBinding>& ControllerBindings() {
  using A = ControllerAction;
  static const std::vector<SuggestedBinding> bindings = {
      {kSimpleController, A::kResetSlam, "/user/hand/left/input/menu/click"},
      {kSimpleController, A::kToggleOverlay, "/user/hand/right/input/select/click"},
      {kSimpleController, A::kToggleOtherKeyframes, "/user/hand/left/input/select/click"},
      {kTouchController, A::kResetSlam, "/user/hand/right/input/b/click"},
      {kTouchController, A::kToggleOverlay, "/user/hand/right/input/a/click"},
      {kTouchController, A::kToggleOtherKeyframes, "/user/hand/left/input/x/click"},
  };
  return bindings;
}

Expected<std::unique_ptr<ControllerActions>> ControllerActions::Create(XrInstance instance) {
  std::unique_ptr<ControllerActions> actions(new ControllerActions(instance));
  XrActionSetCreateInfo set_info{XR_TYPE_ACTION_SET_CREATE_INFO};
  std::snprintf(set_info.actionSetName, sizeof(set_info.actionSetName), "m2s_controls");
  std::snprintf(set_info.localizedActionSetName, sizeof(set_info.localizedActionSetName),
                "Mesh2SLAM controls");
  if (XrResult r = xrCreateActionSet(instance, &set_info, &actions->action_set_); XR_FAILED(r)) {
    return Status::Error("xrCreateActionSet failed: XrResult " + std::to_string(r));
  }
  for (size_t i = 0; i < actions->actions_.size(); ++i) {
    XrActionCreateInfo info{XR_TYPE_ACTION_CREATE_INFO};
    info.actionType = XR_ACTION_TYPE_BOOLEAN_INPUT;
    std::snprintf(info.actionName, sizeof(info.actionName), "%s", kActionNames[i].name);
    std::snprintf(info.localizedActionName, sizeof(info.localizedActionName), "%s",
                  kActionNames[i].localized);
    if (XrResult r = xrCreateAction(actions->action_set_, &info, &actions->actions_[i]);
        XR_FAILED(r)) {
      return Status::Error(std::string("xrCreateAction(") + kActionNames[i].name +
                           ") failed: XrResult " + std::to_string(r));
    }
  }
  for (const char* profile : {kSimpleController, kTouchController}) {
    std::vector<XrActionSuggestedBinding> suggested;
    XrPath profile_path = XR_NULL_PATH;
    bool paths_ok = XR_SUCCEEDED(xrStringToPath(instance, profile, &profile_path));
    for (const SuggestedBinding& b : ControllerBindings()) {
      if (std::string(b.interaction_profile) != profile) continue;
      XrPath input = XR_NULL_PATH;
      paths_ok = paths_ok && XR_SUCCEEDED(xrStringToPath(instance, b.input_path, &input));
      suggested.push_back({actions->actions_[Index(b.action)], input});
    }
    XrInteractionProfileSuggestedBinding info{XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING};
    info.interactionProfile = profile_path;
    info.countSuggestedBindings = static_cast<uint32_t>(suggested.size());
    info.suggestedBindings = suggested.data();
    const XrResult r =
        paths_ok ? xrSuggestInteractionProfileBindings(instance, &info) : XR_ERROR_PATH_INVALID;
    if (XR_FAILED(r)) {
      M2S_LOG(kWarning) << "OpenXR runtime refused the bindings for " << profile << " (XrResult "
                        << r << ")";
    }
  }
  return actions;
}

ControllerActions::~ControllerActions() {
  // Destroying the set destroys its actions.
  if (action_set_ != XR_NULL_HANDLE) xrDestroyActionSet(action_set_);
}

XrResult ControllerActions::Attach(XrSession session) {
  XrSessionActionSetsAttachInfo info{XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO};
  info.countActionSets = 1;
  info.actionSets = &action_set_;
  return xrAttachSessionActionSets(session, &info);
}

XrResult ControllerActions::Sync(XrSession session, std::vector<ControllerAction>* pressed) {
  XrActiveActionSet active{action_set_, XR_NULL_PATH};
  XrActionsSyncInfo info{XR_TYPE_ACTIONS_SYNC_INFO};
  info.countActiveActionSets = 1;
  info.activeActionSets = &active;
  const XrResult synced = xrSyncActions(session, &info);
  if (synced != XR_SUCCESS) return synced;  // XR_SESSION_NOT_FOCUSED: no input, or an error
  for (size_t i = 0; i < actions_.size(); ++i) {
    XrActionStateGetInfo get{XR_TYPE_ACTION_STATE_GET_INFO};
    get.action = actions_[i];
    XrActionStateBoolean state{XR_TYPE_ACTION_STATE_BOOLEAN};
    if (XrResult r = xrGetActionStateBoolean(session, &get, &state); XR_FAILED(r)) return r;
    if (state.isActive && state.currentState && state.changedSinceLastSync) {
      pressed->push_back(static_cast<ControllerAction>(i));
    }
  }
  return XR_SUCCESS;
}

}  // namespace m2s::xr
