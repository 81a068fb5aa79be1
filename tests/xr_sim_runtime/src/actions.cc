// Semantic paths and the action API (OpenXR 1.0, chapters 6 and 11): action sets, actions,
// suggested bindings, attachment to a session, xrSyncActions and the action states, driven by
// the scripted inputs of M2S_XR_SIM_INPUT (sim_config.h).
#include <algorithm>
#include <cstring>
#include <set>

#include "api.h"
#include "interaction_profiles.h"

namespace m2s::xrsim {

XrPath InternPath(InstanceObj& instance, const std::string& path) {
  const auto it = instance.paths.find(path);
  if (it != instance.paths.end()) return it->second;
  instance.path_strings.push_back(path);
  const XrPath value = instance.path_strings.size();
  instance.paths[path] = value;
  return value;
}

const std::string* PathString(const InstanceObj& instance, XrPath path) {
  if (path == XR_NULL_PATH || path > instance.path_strings.size()) return nullptr;
  return &instance.path_strings[path - 1];
}

int64_t Runtime::EraseActionSet(XrActionSet h) {
  int64_t erased = 1;
  for (auto it = actions.begin(); it != actions.end();) {
    it = it->second->action_set == h ? (++erased, actions.erase(it)) : std::next(it);
  }
  action_sets.erase(reinterpret_cast<uint64_t>(h));
  return erased;
}

namespace api {
namespace {

// The instance of an action set, or nullptr.
InstanceObj* InstanceOfSet(XrActionSet set) {
  const ActionSetObj* obj = Runtime::Get().FindActionSet(set);
  return obj == nullptr ? nullptr : Runtime::Get().FindInstance(obj->instance);
}

bool IsHandPath(const InstanceObj& instance, XrPath path) {
  const std::string* s = PathString(instance, path);
  return s != nullptr && (*s == kLeftHand || *s == kRightHand);
}

bool Attached(const SessionObj& session, XrActionSet set) {
  return std::find(session.attached_action_sets.begin(), session.attached_action_sets.end(), set) !=
         session.attached_action_sets.end();
}

struct Names {
  std::string name;
  std::string localized;
};

// Reads and checks the names of a new action set or action (spec 11.2, 11.3): NUL-terminated
// within their arrays, `name` a well-formed path segment, `localized` not empty, both unique
// among `taken`. XR_SUCCESS, or the error with `why`.
template <size_t kNameSize, size_t kLocalizedSize>
XrResult ReadNames(const char (&name)[kNameSize], const char (&localized)[kLocalizedSize],
                   const std::vector<Names>& taken, Names* out, std::string* why) {
  out->name.assign(name, strnlen(name, kNameSize));
  out->localized.assign(localized, strnlen(localized, kLocalizedSize));
  if (out->name.size() == kNameSize || out->localized.size() == kLocalizedSize) {
    *why = "a name is not NUL-terminated";
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (!WellFormedName(out->name)) {
    *why = "'" + out->name + "' is not a well-formed path segment";
    return XR_ERROR_PATH_FORMAT_INVALID;
  }
  if (out->localized.empty()) {
    *why = "the localized name is empty";
    return XR_ERROR_LOCALIZED_NAME_INVALID;
  }
  for (const Names& other : taken) {
    if (other.name == out->name) {
      *why = "'" + out->name + "' is taken";
      return XR_ERROR_NAME_DUPLICATED;
    }
    if (other.localized == out->localized) {
      *why = "'" + out->localized + "' is taken";
      return XR_ERROR_LOCALIZED_NAME_DUPLICATED;
    }
  }
  return XR_SUCCESS;
}

// Samples the bound inputs of every action of `set` at the current frame and updates the
// action's states (all bindings, and per subaction path).
void SyncActionSet(const InstanceObj& instance, const SessionObj& session, XrActionSet set,
                   bool focused) {
  Runtime& rt = Runtime::Get();
  for (auto& [key, action] : rt.actions) {
    if (action->action_set != set) continue;
    std::vector<XrPath> filters = action->subaction_paths;
    filters.push_back(XR_NULL_PATH);
    for (const XrPath filter : filters) {
      const std::string* hand = PathString(instance, filter);
      bool bound = false;
      float value = 0.f;
      for (const auto& [bound_action, input] : session.bindings) {
        const std::string& input_path = *PathString(instance, input);
        if (bound_action != action->handle) continue;
        if (hand != nullptr && TopLevelPath(input_path) != *hand) continue;
        bound = true;
        value = std::max(value, instance.config.input.ValueAt(input_path, instance.frame_counter));
      }
      ActionState& state = action->states[filter];
      const bool active = focused && bound;
      if (action->type == XR_ACTION_TYPE_BOOLEAN_INPUT) value = value >= 0.5f ? 1.f : 0.f;
      if (!active) value = 0.f;
      // A change counts only between two syncs in which the action was active (spec 11.5).
      state.changed = active && state.active && value != state.value;
      if (state.changed) state.last_change_time = instance.Now();
      if (!active) state.last_change_time = 0;
      state.value = value;
      state.active = active;
    }
  }
}

// Shared by the xrGetActionState* functions: the action, checked against the session.
#define M2S_SIM_ACTION_STATE(action, session, info, state, xr_type, action_type)                 \
  M2S_SIM_SESSION(s, inst, session);                                                             \
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_ACTION_STATE_GET_INFO, "getInfo");                          \
  M2S_SIM_REQUIRE_TYPE(state, xr_type, "state");                                                 \
  ActionObj* action = Runtime::Get().FindAction(info->action);                                   \
  M2S_SIM_REQUIRE(action != nullptr && InstanceOfSet(action->action_set) == inst,                \
                  XR_ERROR_HANDLE_INVALID, "unknown XrAction");                                  \
  M2S_SIM_REQUIRE(Attached(*s, action->action_set), XR_ERROR_ACTIONSET_NOT_ATTACHED,             \
                  "the action's set is not attached to this session");                           \
  M2S_SIM_REQUIRE(action->type == (action_type), XR_ERROR_ACTION_TYPE_MISMATCH,                  \
                  "action '" + action->name + "' has another type");                             \
  M2S_SIM_REQUIRE(info->subactionPath == XR_NULL_PATH ||                                         \
                      std::count(action->subaction_paths.begin(), action->subaction_paths.end(), \
                                 info->subactionPath) > 0,                                       \
                  XR_ERROR_PATH_UNSUPPORTED,                                                     \
                  "subactionPath was not given when the action was created");                    \
  const ActionState& action##_state = action->states[info->subactionPath]

}  // namespace

XrResult XRAPI_CALL StringToPath(XrInstance instance, const char* path_string, XrPath* path) {
  constexpr const char* kFn = "xrStringToPath";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(inst, instance);
  M2S_SIM_REQUIRE(path_string != nullptr && path != nullptr, XR_ERROR_VALIDATION_FAILURE,
                  "pathString or path is NULL");
  M2S_SIM_REQUIRE(WellFormedPath(path_string), XR_ERROR_PATH_FORMAT_INVALID,
                  std::string("'") + path_string + "' is not a well-formed path");
  *path = InternPath(*inst, path_string);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL PathToString(XrInstance instance, XrPath path, uint32_t capacity,
                                 uint32_t* count, char* buffer) {
  constexpr const char* kFn = "xrPathToString";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(inst, instance);
  const std::string* s = PathString(*inst, path);
  M2S_SIM_REQUIRE(s != nullptr, XR_ERROR_PATH_INVALID, "not a path of this instance");
  const uint32_t n = static_cast<uint32_t>(s->size() + 1);  // with the terminating NUL
  return TwoCall(kFn, capacity, count, buffer, n, [&](uint32_t i, char* c) {
    *c = i < s->size() ? (*s)[i] : '\0';
    return XR_SUCCESS;
  });
}

XrResult XRAPI_CALL CreateActionSet(XrInstance instance, const XrActionSetCreateInfo* info,
                                    XrActionSet* action_set) {
  constexpr const char* kFn = "xrCreateActionSet";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  M2S_SIM_INSTANCE(inst, instance);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_ACTION_SET_CREATE_INFO, "createInfo");
  M2S_SIM_REQUIRE(action_set != nullptr, XR_ERROR_VALIDATION_FAILURE, "actionSet is NULL");
  std::vector<Names> taken;
  for (const auto& [key, other] : rt.action_sets) {
    if (other->instance == instance) taken.push_back({other->name, other->localized_name});
  }
  Names names;
  std::string why;
  const XrResult named =
      ReadNames(info->actionSetName, info->localizedActionSetName, taken, &names, &why);
  M2S_SIM_REQUIRE(named == XR_SUCCESS, named, "action set names: " + why);
  auto obj = std::make_unique<ActionSetObj>();
  obj->handle = ToHandle<XrActionSet>(rt.NewHandle());
  obj->instance = instance;
  obj->name = names.name;
  obj->localized_name = names.localized;
  obj->priority = info->priority;
  *action_set = obj->handle;
  ++inst->counters.action_sets_created;
  rt.action_sets[reinterpret_cast<uint64_t>(obj->handle)] = std::move(obj);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL DestroyActionSet(XrActionSet action_set) {
  constexpr const char* kFn = "xrDestroyActionSet";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  InstanceObj* inst = InstanceOfSet(action_set);
  M2S_SIM_REQUIRE(inst != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrActionSet");
  const int64_t erased = rt.EraseActionSet(action_set);
  ++inst->counters.action_sets_destroyed;
  inst->counters.actions_destroyed += erased - 1;  // its actions go with it (spec 11.2)
  return XR_SUCCESS;
}

XrResult XRAPI_CALL CreateAction(XrActionSet action_set, const XrActionCreateInfo* info,
                                 XrAction* action) {
  constexpr const char* kFn = "xrCreateAction";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  ActionSetObj* set = rt.FindActionSet(action_set);
  M2S_SIM_REQUIRE(set != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrActionSet");
  InstanceObj* inst = rt.FindInstance(set->instance);
  if (inst->lost) return XR_ERROR_INSTANCE_LOST;
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_ACTION_CREATE_INFO, "createInfo");
  M2S_SIM_REQUIRE(action != nullptr, XR_ERROR_VALIDATION_FAILURE, "action is NULL");
  M2S_SIM_REQUIRE(!set->attached, XR_ERROR_ACTIONSETS_ALREADY_ATTACHED,
                  "action set '" + set->name + "' is attached to a session: immutable");
  std::vector<Names> taken;
  for (const auto& [key, other] : rt.actions) {
    if (other->action_set == action_set) taken.push_back({other->name, other->localized_name});
  }
  Names names;
  std::string why;
  const XrResult named =
      ReadNames(info->actionName, info->localizedActionName, taken, &names, &why);
  M2S_SIM_REQUIRE(named == XR_SUCCESS, named, "action names: " + why);
  const XrActionType type = info->actionType;
  M2S_SIM_REQUIRE(type == XR_ACTION_TYPE_BOOLEAN_INPUT || type == XR_ACTION_TYPE_FLOAT_INPUT ||
                      type == XR_ACTION_TYPE_VECTOR2F_INPUT || type == XR_ACTION_TYPE_POSE_INPUT ||
                      type == XR_ACTION_TYPE_VIBRATION_OUTPUT,
                  XR_ERROR_VALIDATION_FAILURE, "actionType is not a valid XrActionType");
  M2S_SIM_REQUIRE(info->countSubactionPaths == 0 || info->subactionPaths != nullptr,
                  XR_ERROR_VALIDATION_FAILURE, "subactionPaths is NULL");
  std::set<XrPath> subaction_paths;
  for (uint32_t i = 0; i < info->countSubactionPaths; ++i) {
    const XrPath path = info->subactionPaths[i];
    M2S_SIM_REQUIRE(PathString(*inst, path) != nullptr, XR_ERROR_PATH_INVALID,
                    "subactionPaths[i] is not a path of this instance");
    M2S_SIM_REQUIRE(IsHandPath(*inst, path) && subaction_paths.insert(path).second,
                    XR_ERROR_PATH_UNSUPPORTED,
                    "subactionPaths[i] is not /user/hand/left or /user/hand/right, or repeated");
  }
  auto obj = std::make_unique<ActionObj>();
  obj->handle = ToHandle<XrAction>(rt.NewHandle());
  obj->action_set = action_set;
  obj->name = names.name;
  obj->localized_name = names.localized;
  obj->type = type;
  obj->subaction_paths.assign(info->subactionPaths,
                              info->subactionPaths + info->countSubactionPaths);
  *action = obj->handle;
  ++inst->counters.actions_created;
  rt.actions[reinterpret_cast<uint64_t>(obj->handle)] = std::move(obj);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL DestroyAction(XrAction action) {
  constexpr const char* kFn = "xrDestroyAction";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  ActionObj* obj = rt.FindAction(action);
  M2S_SIM_REQUIRE(obj != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrAction");
  ++InstanceOfSet(obj->action_set)->counters.actions_destroyed;
  rt.actions.erase(reinterpret_cast<uint64_t>(action));
  return XR_SUCCESS;
}

XrResult XRAPI_CALL SuggestInteractionProfileBindings(
    XrInstance instance, const XrInteractionProfileSuggestedBinding* suggested) {
  constexpr const char* kFn = "xrSuggestInteractionProfileBindings";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  M2S_SIM_INSTANCE(inst, instance);
  M2S_SIM_REQUIRE_TYPE(suggested, XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING,
                       "suggestedBindings");
  const std::string* profile = PathString(*inst, suggested->interactionProfile);
  M2S_SIM_REQUIRE(profile != nullptr, XR_ERROR_PATH_INVALID,
                  "interactionProfile is not a path of this instance");
  M2S_SIM_REQUIRE(KnownProfile(*profile), XR_ERROR_PATH_UNSUPPORTED,
                  "interaction profile '" + *profile + "' is not supported");
  M2S_SIM_REQUIRE(suggested->countSuggestedBindings > 0 && suggested->suggestedBindings != nullptr,
                  XR_ERROR_VALIDATION_FAILURE, "no suggested bindings");
  Bindings bindings;
  for (uint32_t i = 0; i < suggested->countSuggestedBindings; ++i) {
    const XrActionSuggestedBinding& b = suggested->suggestedBindings[i];
    const ActionObj* action = rt.FindAction(b.action);
    M2S_SIM_REQUIRE(action != nullptr && InstanceOfSet(action->action_set) == inst,
                    XR_ERROR_HANDLE_INVALID, "suggestedBindings[i].action is unknown");
    M2S_SIM_REQUIRE(!rt.FindActionSet(action->action_set)->attached,
                    XR_ERROR_ACTIONSETS_ALREADY_ATTACHED,
                    "action '" + action->name + "' belongs to an attached action set");
    const std::string* binding = PathString(*inst, b.binding);
    M2S_SIM_REQUIRE(binding != nullptr, XR_ERROR_PATH_INVALID,
                    "suggestedBindings[i].binding is not a path of this instance");
    M2S_SIM_REQUIRE(ProfileHasPath(*profile, *binding), XR_ERROR_PATH_UNSUPPORTED,
                    "'" + *binding + "' is not a binding path of " + *profile);
    bindings.emplace_back(b.action, b.binding);
  }
  // A later suggestion for the same profile replaces the earlier one (spec 11.4).
  inst->suggested_bindings[suggested->interactionProfile] = std::move(bindings);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL AttachSessionActionSets(XrSession session,
                                            const XrSessionActionSetsAttachInfo* info) {
  constexpr const char* kFn = "xrAttachSessionActionSets";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO, "attachInfo");
  M2S_SIM_REQUIRE(!s->actions_attached, XR_ERROR_ACTIONSETS_ALREADY_ATTACHED,
                  "action sets were already attached to this session");
  M2S_SIM_REQUIRE(info->countActionSets > 0 && info->actionSets != nullptr,
                  XR_ERROR_VALIDATION_FAILURE, "no action sets");
  for (uint32_t i = 0; i < info->countActionSets; ++i) {
    M2S_SIM_REQUIRE(InstanceOfSet(info->actionSets[i]) == inst, XR_ERROR_HANDLE_INVALID,
                    "actionSets[i] is not an action set of this instance");
  }
  s->actions_attached = true;
  s->attached_action_sets.assign(info->actionSets, info->actionSets + info->countActionSets);
  for (const XrActionSet set : s->attached_action_sets) rt.FindActionSet(set)->attached = true;
  // The runtime picks the profile it has (M2S_XR_SIM_CONTROLLER) if the app suggested it.
  const XrPath profile = InternPath(*inst, inst->config.interaction_profile);
  const auto suggested = inst->suggested_bindings.find(profile);
  if (suggested != inst->suggested_bindings.end()) {
    s->interaction_profile = profile;
    for (const auto& binding : suggested->second) {
      const ActionObj* action = rt.FindAction(binding.first);
      if (action != nullptr && Attached(*s, action->action_set)) s->bindings.push_back(binding);
    }
    XrEventDataBuffer buffer{XR_TYPE_EVENT_DATA_BUFFER};
    auto* event = reinterpret_cast<XrEventDataInteractionProfileChanged*>(&buffer);
    *event = {XR_TYPE_EVENT_DATA_INTERACTION_PROFILE_CHANGED};
    event->session = session;
    inst->events.push_back(buffer);
  }
  LogInfo("action sets attached; interaction profile " +
          (s->interaction_profile == XR_NULL_PATH
               ? std::string("none (no bindings suggested for ") +
                     inst->config.interaction_profile + ")"
               : inst->config.interaction_profile));
  return XR_SUCCESS;
}

XrResult XRAPI_CALL GetCurrentInteractionProfile(XrSession session, XrPath top_level_user_path,
                                                 XrInteractionProfileState* profile) {
  constexpr const char* kFn = "xrGetCurrentInteractionProfile";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE_TYPE(profile, XR_TYPE_INTERACTION_PROFILE_STATE, "interactionProfile");
  M2S_SIM_REQUIRE(PathString(*inst, top_level_user_path) != nullptr, XR_ERROR_PATH_INVALID,
                  "topLevelUserPath is not a path of this instance");
  M2S_SIM_REQUIRE(IsHandPath(*inst, top_level_user_path), XR_ERROR_PATH_UNSUPPORTED,
                  "topLevelUserPath is not /user/hand/left or /user/hand/right");
  M2S_SIM_REQUIRE(s->actions_attached, XR_ERROR_ACTIONSET_NOT_ATTACHED,
                  "no action sets attached to this session");
  profile->interactionProfile = s->interaction_profile;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL SyncActions(XrSession session, const XrActionsSyncInfo* info) {
  constexpr const char* kFn = "xrSyncActions";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_ACTIONS_SYNC_INFO, "syncInfo");
  M2S_SIM_REQUIRE(info->countActiveActionSets == 0 || info->activeActionSets != nullptr,
                  XR_ERROR_VALIDATION_FAILURE, "activeActionSets is NULL");
  M2S_SIM_REQUIRE(s->actions_attached, XR_ERROR_ACTIONSET_NOT_ATTACHED,
                  "no action sets attached to this session");
  for (uint32_t i = 0; i < info->countActiveActionSets; ++i) {
    const XrActiveActionSet& active = info->activeActionSets[i];
    M2S_SIM_REQUIRE(InstanceOfSet(active.actionSet) == inst, XR_ERROR_HANDLE_INVALID,
                    "activeActionSets[i].actionSet is unknown");
    M2S_SIM_REQUIRE(Attached(*s, active.actionSet), XR_ERROR_ACTIONSET_NOT_ATTACHED,
                    "activeActionSets[i].actionSet is not attached to this session");
    M2S_SIM_REQUIRE(active.subactionPath == XR_NULL_PATH || IsHandPath(*inst, active.subactionPath),
                    XR_ERROR_PATH_UNSUPPORTED, "activeActionSets[i].subactionPath unsupported");
  }
  // Only a focused session gets input; the others see every action inactive (spec 11.5).
  const bool focused = s->running && s->state == XR_SESSION_STATE_FOCUSED;
  for (const XrActionSet set : s->attached_action_sets) {
    bool active = false;
    for (uint32_t i = 0; i < info->countActiveActionSets; ++i) {
      active |= info->activeActionSets[i].actionSet == set;
    }
    SyncActionSet(*inst, *s, set, focused && active);
  }
  ++inst->counters.action_syncs;
  if (!focused) {
    ++inst->counters.action_syncs_unfocused;
    return XR_SESSION_NOT_FOCUSED;
  }
  return XR_SUCCESS;
}

XrResult XRAPI_CALL GetActionStateBoolean(XrSession session, const XrActionStateGetInfo* info,
                                          XrActionStateBoolean* state) {
  constexpr const char* kFn = "xrGetActionStateBoolean";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_ACTION_STATE(action, session, info, state, XR_TYPE_ACTION_STATE_BOOLEAN,
                       XR_ACTION_TYPE_BOOLEAN_INPUT);
  state->currentState = action_state.value >= 0.5f ? XR_TRUE : XR_FALSE;
  state->changedSinceLastSync = action_state.changed ? XR_TRUE : XR_FALSE;
  state->lastChangeTime = action_state.last_change_time;
  state->isActive = action_state.active ? XR_TRUE : XR_FALSE;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL GetActionStateFloat(XrSession session, const XrActionStateGetInfo* info,
                                        XrActionStateFloat* state) {
  constexpr const char* kFn = "xrGetActionStateFloat";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_ACTION_STATE(action, session, info, state, XR_TYPE_ACTION_STATE_FLOAT,
                       XR_ACTION_TYPE_FLOAT_INPUT);
  state->currentState = action_state.value;
  state->changedSinceLastSync = action_state.changed ? XR_TRUE : XR_FALSE;
  state->lastChangeTime = action_state.last_change_time;
  state->isActive = action_state.active ? XR_TRUE : XR_FALSE;
  return XR_SUCCESS;
}

}  // namespace api
}  // namespace m2s::xrsim

#undef M2S_SIM_ACTION_STATE
