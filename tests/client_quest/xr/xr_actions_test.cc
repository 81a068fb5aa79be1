// The real m2s_xr_client's controller buttons (OpenXR actions) on the simulated runtime: the
// runtime plays a scripted button file (M2S_XR_SIM_INPUT) through the bindings the app
// suggested, and the app resets SLAM, toggles the overlay and toggles other agents' keyframes.
#include "xr_client_test_util.h"

namespace m2s::xr_test {
namespace {

const std::string kLight = " --projector cpu --budget 1000 --no-mesh";

std::string Client(const fs::path& dir, const std::string& env, const std::string& script,
                   const std::string& args) {
  return env + " " + RuntimeEnv(dir, dir / "head.tum", script, "") + " " + kBin +
         "/m2s_xr_client --out " + Quote((dir / "out").string()) + " " + args;
}

TEST(XrClientActions, TouchControllerButtonsResetToggleAndShowOthers) {
  const fs::path dir = TestDir();
  WritePlayedTrajectory(dir / "head.tum", 3.0);
  // Frames are the runtime's xrWaitFrame count; the session is focused from frame 2 to the
  // focus loss at 100 (20 frames), then again until the exit at 150.
  std::ofstream(dir / "buttons.txt") << "# frame input value\n"
                                        "20 /user/hand/right/input/b/click 1\n"  // reset
                                        "23 /user/hand/right/input/b/click 0\n"
                                        "40 /user/hand/right/input/a/click 1\n"  // overlay off
                                        "41 /user/hand/right/input/a/click 0\n"
                                        "60 /user/hand/right/input/a/click 1\n"  // overlay on
                                        "61 /user/hand/right/input/a/click 0\n"
                                        "80 /user/hand/left/input/x/click 1\n"  // others off
                                        "90 /user/hand/left/input/x/click 0\n"
                                        "105 /user/hand/right/input/b/click 1\n"   // unfocused:
                                        "107 /user/hand/right/input/b/click 0\n";  // ignored
  std::ofstream(dir / "config.json") << R"({"map_group": "lab", "other_keyframes": true})";
  const int rc = RunBounded(Client(dir, "M2S_XR_SIM_INPUT=" + Quote((dir / "buttons.txt").string()),
                                   "focus_loss@100:20,exit@150",
                                   "--config " + Quote((dir / "config.json").string()) + kLight),
                            120, dir / "log.txt");
  ASSERT_EQ(rc, 0) << ReadText(dir / "log.txt");
  const nlohmann::json report = ReadJson(dir / "runtime_report.json");
  ExpectCleanRuntimeReport(report);
  EXPECT_EQ(report["interaction_profile"], "/interaction_profiles/oculus/touch_controller");
  EXPECT_EQ(report["action_sets_created"], 1);
  EXPECT_EQ(report["action_sets_destroyed"], 1);
  EXPECT_GE(report["action_syncs"].get<int>(), 140);
  EXPECT_GE(report["action_syncs_unfocused"].get<int>(), 20);
  const nlohmann::json metrics = ReadJson(dir / "out" / "xr_metrics.json");
  EXPECT_EQ(metrics["controller_presses"], 4);
  EXPECT_EQ(metrics["slam_sessions"], 2);  // one reset
  EXPECT_EQ(metrics["overlay_toggles"], 2);
  EXPECT_EQ(metrics["other_keyframe_toggles"], 1);
  EXPECT_EQ(metrics["map_group"], "lab");
}

TEST(XrClientActions, SimpleControllerBindings) {
  const fs::path dir = TestDir();
  WritePlayedTrajectory(dir / "head.tum", 2.0);
  std::ofstream(dir / "buttons.txt") << "10 /user/hand/left/input/menu/click 1\n"  // reset
                                        "12 /user/hand/left/input/menu/click 0\n"
                                        "20 /user/hand/right/input/select/click 1\n"  // overlay
                                        "21 /user/hand/right/input/select/click 0\n"
                                        "30 /user/hand/left/input/select/click 1\n";  // others
  const int rc =
      RunBounded(Client(dir,
                        "M2S_XR_SIM_CONTROLLER=/interaction_profiles/khr/simple_controller "
                        "M2S_XR_SIM_INPUT=" +
                            Quote((dir / "buttons.txt").string()),
                        "", "--frames 40" + kLight),
                 120, dir / "log.txt");
  ASSERT_EQ(rc, 0) << ReadText(dir / "log.txt");
  const nlohmann::json report = ReadJson(dir / "runtime_report.json");
  ExpectCleanRuntimeReport(report);
  EXPECT_EQ(report["interaction_profile"], "/interaction_profiles/khr/simple_controller");
  const nlohmann::json metrics = ReadJson(dir / "out" / "xr_metrics.json");
  EXPECT_EQ(metrics["controller_presses"], 3);
  EXPECT_EQ(metrics["slam_sessions"], 2);
  EXPECT_EQ(metrics["overlay_toggles"], 1);
  EXPECT_EQ(metrics["other_keyframe_toggles"], 1);
  EXPECT_EQ(metrics["map_group"], "");
}

}  // namespace
}  // namespace m2s::xr_test
