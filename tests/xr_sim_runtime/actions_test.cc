// The action API of the simulated runtime through the real loader: paths, action sets and
// actions, suggested bindings, attachment, and the action states xrSyncActions samples from
// the scripted input file (M2S_XR_SIM_INPUT), plus the misuse it detects.
#include "sim_test_fixture.h"

namespace m2s::xrsim_test {
namespace {

constexpr const char* kTouch = "/interaction_profiles/oculus/touch_controller";
constexpr const char* kSimple = "/interaction_profiles/khr/simple_controller";

XrActionSet MakeActionSet(XrInstance instance, const char* name, const char* localized) {
  XrActionSetCreateInfo info{XR_TYPE_ACTION_SET_CREATE_INFO};
  std::snprintf(info.actionSetName, sizeof(info.actionSetName), "%s", name);
  std::snprintf(info.localizedActionSetName, sizeof(info.localizedActionSetName), "%s", localized);
  XrActionSet set = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateActionSet(instance, &info, &set), XR_SUCCESS);
  return set;
}

XrResult MakeAction(XrActionSet set, const char* name, XrActionType type,
                    std::vector<XrPath> subaction_paths, XrAction* action) {
  XrActionCreateInfo info{XR_TYPE_ACTION_CREATE_INFO};
  std::snprintf(info.actionName, sizeof(info.actionName), "%s", name);
  std::snprintf(info.localizedActionName, sizeof(info.localizedActionName), "%s", name);
  info.actionType = type;
  info.countSubactionPaths = static_cast<uint32_t>(subaction_paths.size());
  info.subactionPaths = subaction_paths.data();
  return xrCreateAction(set, &info, action);
}

XrResult Suggest(XrInstance instance, XrPath profile,
                 const std::vector<XrActionSuggestedBinding>& bindings) {
  XrInteractionProfileSuggestedBinding info{XR_TYPE_INTERACTION_PROFILE_SUGGESTED_BINDING};
  info.interactionProfile = profile;
  info.countSuggestedBindings = static_cast<uint32_t>(bindings.size());
  info.suggestedBindings = bindings.data();
  return xrSuggestInteractionProfileBindings(instance, &info);
}

XrResult Attach(XrSession session, XrActionSet set) {
  XrSessionActionSetsAttachInfo info{XR_TYPE_SESSION_ACTION_SETS_ATTACH_INFO};
  info.countActionSets = 1;
  info.actionSets = &set;
  return xrAttachSessionActionSets(session, &info);
}

XrResult Sync(XrSession session, XrActionSet set) {
  XrActiveActionSet active{set, XR_NULL_PATH};
  XrActionsSyncInfo info{XR_TYPE_ACTIONS_SYNC_INFO};
  info.countActiveActionSets = 1;
  info.activeActionSets = &active;
  return xrSyncActions(session, &info);
}

XrActionStateBoolean BooleanState(XrSession session, XrAction action, XrPath subaction) {
  XrActionStateGetInfo get{XR_TYPE_ACTION_STATE_GET_INFO};
  get.action = action;
  get.subactionPath = subaction;
  XrActionStateBoolean state{XR_TYPE_ACTION_STATE_BOOLEAN};
  EXPECT_EQ(xrGetActionStateBoolean(session, &get, &state), XR_SUCCESS);
  return state;
}

// currentState, changedSinceLastSync, isActive.
std::array<bool, 3> Flags(const XrActionStateBoolean& s) {
  return {s.currentState == XR_TRUE, s.changedSinceLastSync == XR_TRUE, s.isActive == XR_TRUE};
}
using Expect = std::array<bool, 3>;

TEST_F(SimRuntimeTest, PathsRoundTrip) {
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  const XrPath a = Path("/user/hand/left/input/x/click");
  EXPECT_NE(a, XR_NULL_PATH);
  EXPECT_EQ(Path("/user/hand/left/input/x/click"), a);  // interned
  EXPECT_NE(Path("/user/hand/right"), a);
  uint32_t n = 0;
  ASSERT_EQ(xrPathToString(instance_, a, 0, &n, nullptr), XR_SUCCESS);
  EXPECT_EQ(n, std::strlen("/user/hand/left/input/x/click") + 1);
  std::string text(n, '?');
  ASSERT_EQ(xrPathToString(instance_, a, n, &n, text.data()), XR_SUCCESS);
  EXPECT_STREQ(text.c_str(), "/user/hand/left/input/x/click");
  ASSERT_EQ(xrDestroyInstance(instance_), XR_SUCCESS);
  instance_ = XR_NULL_HANDLE;
  EXPECT_EQ(Report()["misuse"], 0);
}

TEST_F(SimRuntimeTest, ScriptedButtonsDriveActions) {
  // Frames count xrWaitFrame calls from 1; the session is FOCUSED from frame 2.
  std::ofstream(dir_ / "buttons.txt") << "# frame path value\n"
                                         "3 /user/hand/right/input/a/click 1\n"
                                         "5 /user/hand/right/input/a/click 0\n"
                                         "4 /user/hand/left/input/x/click 1\n"
                                         "4 /user/hand/right/input/squeeze/value 0.75\n";
  setenv("M2S_XR_SIM_INPUT", (dir_ / "buttons.txt").c_str(), 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  const XrPath left = Path("/user/hand/left"), right = Path("/user/hand/right");
  XrActionSet set = MakeActionSet(instance_, "controls", "Controls");
  XrAction press = XR_NULL_HANDLE, squeeze = XR_NULL_HANDLE;
  ASSERT_EQ(MakeAction(set, "press", XR_ACTION_TYPE_BOOLEAN_INPUT, {left, right}, &press),
            XR_SUCCESS);
  ASSERT_EQ(MakeAction(set, "squeeze", XR_ACTION_TYPE_FLOAT_INPUT, {}, &squeeze), XR_SUCCESS);
  ASSERT_EQ(Suggest(instance_, Path(kTouch),
                    {{press, Path("/user/hand/right/input/a/click")},
                     {press, Path("/user/hand/left/input/x/click")},
                     {squeeze, Path("/user/hand/right/input/squeeze/value")}}),
            XR_SUCCESS);
  ASSERT_EQ(
      Suggest(instance_, Path(kSimple), {{press, Path("/user/hand/right/input/select/click")}}),
      XR_SUCCESS);
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  ASSERT_EQ(Attach(session_, set), XR_SUCCESS);
  XrInteractionProfileState profile{XR_TYPE_INTERACTION_PROFILE_STATE};
  ASSERT_EQ(xrGetCurrentInteractionProfile(session_, right, &profile), XR_SUCCESS);
  EXPECT_EQ(profile.interactionProfile, Path(kTouch));
  Begin();

  Frame(kRed);  // 1: SYNCHRONIZED, no input
  EXPECT_EQ(Sync(session_, set), XR_SESSION_NOT_FOCUSED);
  EXPECT_EQ(Flags(BooleanState(session_, press, XR_NULL_PATH)), (Expect{false, false, false}));
  Frame(kRed);  // 2: FOCUSED, nothing pressed
  EXPECT_EQ(Sync(session_, set), XR_SUCCESS);
  EXPECT_EQ(Flags(BooleanState(session_, press, XR_NULL_PATH)), (Expect{false, false, true}));
  const XrFrameState third = Frame(kRed);  // 3: A down
  EXPECT_EQ(Sync(session_, set), XR_SUCCESS);
  const XrActionStateBoolean pressed = BooleanState(session_, press, XR_NULL_PATH);
  EXPECT_EQ(Flags(pressed), (Expect{true, true, true}));
  EXPECT_EQ(pressed.lastChangeTime, third.predictedDisplayTime);
  EXPECT_EQ(Flags(BooleanState(session_, press, right)), (Expect{true, true, true}));
  EXPECT_EQ(Flags(BooleanState(session_, press, left)), (Expect{false, false, true}));
  Frame(kRed);  // 4: X down too
  EXPECT_EQ(Sync(session_, set), XR_SUCCESS);
  EXPECT_EQ(Flags(BooleanState(session_, press, XR_NULL_PATH)), (Expect{true, false, true}));
  EXPECT_EQ(Flags(BooleanState(session_, press, left)), (Expect{true, true, true}));
  XrActionStateGetInfo get{XR_TYPE_ACTION_STATE_GET_INFO};
  get.action = squeeze;
  XrActionStateFloat value{XR_TYPE_ACTION_STATE_FLOAT};
  ASSERT_EQ(xrGetActionStateFloat(session_, &get, &value), XR_SUCCESS);
  EXPECT_FLOAT_EQ(value.currentState, 0.75f);
  EXPECT_TRUE(value.changedSinceLastSync);
  Frame(kRed);  // 5: A up, X still down
  EXPECT_EQ(Sync(session_, set), XR_SUCCESS);
  EXPECT_EQ(Flags(BooleanState(session_, press, XR_NULL_PATH)), (Expect{true, false, true}));
  EXPECT_EQ(Flags(BooleanState(session_, press, right)), (Expect{false, true, true}));

  ASSERT_EQ(xrDestroyActionSet(set), XR_SUCCESS);
  EndAndDestroyAll();
  const nlohmann::json report = Report();
  EXPECT_EQ(report["misuse"], 0) << report["misuse_messages"];
  EXPECT_EQ(report["action_syncs"], 5);
  EXPECT_EQ(report["action_syncs_unfocused"], 1);
  EXPECT_EQ(report["actions_created"], 2);
  EXPECT_EQ(report["actions_destroyed"], 2);  // with their set
  EXPECT_EQ(report["handles_left_alive"], 0);
}

TEST_F(SimRuntimeTest, ProfileWithoutSuggestionsLeavesActionsInactive) {
  std::ofstream(dir_ / "buttons.txt") << "1 /user/hand/right/input/select/click 1\n";
  setenv("M2S_XR_SIM_CONTROLLER", kSimple, 1);
  setenv("M2S_XR_SIM_INPUT", (dir_ / "buttons.txt").c_str(), 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  XrActionSet set = MakeActionSet(instance_, "controls", "Controls");
  XrAction press = XR_NULL_HANDLE;
  ASSERT_EQ(MakeAction(set, "press", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &press), XR_SUCCESS);
  ASSERT_EQ(Suggest(instance_, Path(kTouch), {{press, Path("/user/hand/right/input/a/click")}}),
            XR_SUCCESS);
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  ASSERT_EQ(Attach(session_, set), XR_SUCCESS);
  XrInteractionProfileState profile{XR_TYPE_INTERACTION_PROFILE_STATE};
  ASSERT_EQ(xrGetCurrentInteractionProfile(session_, Path("/user/hand/left"), &profile),
            XR_SUCCESS);
  EXPECT_EQ(profile.interactionProfile, XR_NULL_PATH);
  Begin();
  Frame(kRed);
  Frame(kRed);
  EXPECT_EQ(Sync(session_, set), XR_SUCCESS);
  EXPECT_EQ(Flags(BooleanState(session_, press, XR_NULL_PATH)), (Expect{false, false, false}));
  ASSERT_EQ(xrDestroyAction(press), XR_SUCCESS);
  ASSERT_EQ(xrDestroyActionSet(set), XR_SUCCESS);
  EndAndDestroyAll();
  EXPECT_EQ(Report()["misuse"], 0) << Report()["misuse_messages"];
}

TEST_F(SimRuntimeTest, MalformedInputScriptFailsTheInstance) {
  for (const char* line :
       {"3 /user/hand/left/input/a/click 1\n",  // A is on the right hand
        "x /user/hand/right/input/a/click 1\n", "3 /user/hand/right/input/a/click 2\n",
        "3 /user/hand/right/input/grip/pose 1\n"}) {
    std::ofstream(dir_ / "buttons.txt") << line;
    setenv("M2S_XR_SIM_INPUT", (dir_ / "buttons.txt").c_str(), 1);
    EXPECT_EQ(TryCreateInstance(), XR_ERROR_RUNTIME_FAILURE) << line;
  }
  instance_ = XR_NULL_HANDLE;
}

TEST_F(SimRuntimeTest, ActionMisuse) {
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  XrPath bad = XR_NULL_PATH;
  EXPECT_EQ(xrStringToPath(instance_, "/user/hand//left", &bad),
            XR_ERROR_PATH_FORMAT_INVALID);  // 1
  uint32_t n = 0;
  EXPECT_EQ(xrPathToString(instance_, 12345, 0, &n, nullptr), XR_ERROR_PATH_INVALID);  // 2
  XrActionSetCreateInfo set_info{XR_TYPE_ACTION_SET_CREATE_INFO};
  std::snprintf(set_info.actionSetName, sizeof(set_info.actionSetName), "Bad Name");
  std::snprintf(set_info.localizedActionSetName, sizeof(set_info.localizedActionSetName), "x");
  XrActionSet other = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateActionSet(instance_, &set_info, &other), XR_ERROR_PATH_FORMAT_INVALID);  // 3
  XrActionSet set = MakeActionSet(instance_, "controls", "Controls");
  std::snprintf(set_info.actionSetName, sizeof(set_info.actionSetName), "controls");
  EXPECT_EQ(xrCreateActionSet(instance_, &set_info, &other), XR_ERROR_NAME_DUPLICATED);  // 4
  XrAction press = XR_NULL_HANDLE;
  EXPECT_EQ(MakeAction(set, "press", XR_ACTION_TYPE_BOOLEAN_INPUT, {Path("/user/head")}, &press),
            XR_ERROR_PATH_UNSUPPORTED);  // 5
  ASSERT_EQ(
      MakeAction(set, "press", XR_ACTION_TYPE_BOOLEAN_INPUT, {Path("/user/hand/left")}, &press),
      XR_SUCCESS);
  EXPECT_EQ(Suggest(instance_, Path("/interaction_profiles/acme/wand"),
                    {{press, Path("/user/hand/left/input/select/click")}}),
            XR_ERROR_PATH_UNSUPPORTED);  // 6
  EXPECT_EQ(Suggest(instance_, Path(kTouch), {{press, Path("/user/hand/right/input/x/click")}}),
            XR_ERROR_PATH_UNSUPPORTED);  // 7: X is on the left controller
  ASSERT_EQ(Suggest(instance_, Path(kTouch), {{press, Path("/user/hand/left/input/x/click")}}),
            XR_SUCCESS);
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  EXPECT_EQ(Sync(session_, set), XR_ERROR_ACTIONSET_NOT_ATTACHED);  // 8
  XrActionSet late = MakeActionSet(instance_, "late", "Late");
  XrAction late_press = XR_NULL_HANDLE;
  ASSERT_EQ(MakeAction(late, "press", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &late_press), XR_SUCCESS);
  ASSERT_EQ(Attach(session_, set), XR_SUCCESS);
  EXPECT_EQ(Attach(session_, set), XR_ERROR_ACTIONSETS_ALREADY_ATTACHED);  // 9
  XrAction more = XR_NULL_HANDLE;
  EXPECT_EQ(MakeAction(set, "more", XR_ACTION_TYPE_BOOLEAN_INPUT, {}, &more),
            XR_ERROR_ACTIONSETS_ALREADY_ATTACHED);  // 10
  EXPECT_EQ(Suggest(instance_, Path(kTouch), {{press, Path("/user/hand/left/input/y/click")}}),
            XR_ERROR_ACTIONSETS_ALREADY_ATTACHED);  // 11
  XrActionStateGetInfo get{XR_TYPE_ACTION_STATE_GET_INFO};
  get.action = press;
  XrActionStateFloat value{XR_TYPE_ACTION_STATE_FLOAT};
  EXPECT_EQ(xrGetActionStateFloat(session_, &get, &value), XR_ERROR_ACTION_TYPE_MISMATCH);  // 12
  XrActionStateBoolean state{XR_TYPE_ACTION_STATE_BOOLEAN};
  get.subactionPath = Path("/user/hand/right");
  EXPECT_EQ(xrGetActionStateBoolean(session_, &get, &state), XR_ERROR_PATH_UNSUPPORTED);  // 13
  get.action = late_press;
  get.subactionPath = XR_NULL_PATH;
  EXPECT_EQ(xrGetActionStateBoolean(session_, &get, &state),
            XR_ERROR_ACTIONSET_NOT_ATTACHED);  // 14
  ASSERT_EQ(xrDestroyAction(press), XR_SUCCESS);
  get.action = press;
  EXPECT_EQ(xrGetActionStateBoolean(session_, &get, &state), XR_ERROR_HANDLE_INVALID);  // 15
  ASSERT_EQ(xrDestroyActionSet(set), XR_SUCCESS);
  // `late` and its action are left alive: reported at xrDestroyInstance (16).
  DestroyAll();
  const nlohmann::json report = Report();
  EXPECT_EQ(report["misuse"], 16) << report["misuse_messages"];
  EXPECT_EQ(report["handles_left_alive"], 2);
}

}  // namespace
}  // namespace m2s::xrsim_test
