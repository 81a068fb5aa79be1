// Session lifecycle of the real m2s_xr_client driven by the simulated runtime's script, and
// the GPU projector on the app's own context. The LCM mode against a separate m2s_server runs
// in real time: it is in xr_client_realtime_test.cc.
#include "xr_client_test_util.h"

namespace m2s::xr_test {
namespace {

// Light settings: these tests are about behaviour, not accuracy.
const std::string kLight = " --projector cpu --budget 1000 --no-mesh";

std::string Client(const fs::path& dir, const std::string& script, const std::string& args) {
  return RuntimeEnv(dir, dir / "head.tum", script, "") + " " + kBin + "/m2s_xr_client --out " +
         Quote((dir / "out").string()) + " " + args;
}

bool HasState(const nlohmann::json& metrics, const std::string& state) {
  for (const auto& s : metrics["session_states"]) {
    if (s == state) return true;
  }
  return false;
}

TEST(XrClientLifecycle, FocusLossHiddenSessionLossControlsAndRuntimeExit) {
  const fs::path dir = TestDir();
  WritePlayedTrajectory(dir / "head.tum", 5.0);
  // The runtime ends the session at frame 200; no --frames.
  const int rc = RunBounded(Client(dir, "focus_loss@40:20,hide@70:10,session_loss@100,exit@200",
                                   "--events overlay@50,overlay@60,reset@150" + kLight),
                            120, dir / "log.txt");
  ASSERT_EQ(rc, 0) << ReadText(dir / "log.txt");
  const nlohmann::json report = ReadJson(dir / "runtime_report.json");
  ExpectCleanRuntimeReport(report);
  EXPECT_EQ(report["sessions_created"], 2);  // a new session after the loss
  EXPECT_EQ(report["frames_waited"], 200);
  const nlohmann::json metrics = ReadJson(dir / "out" / "xr_metrics.json");
  EXPECT_EQ(metrics["openxr_sessions"], 2);
  EXPECT_EQ(metrics["slam_sessions"], 2);
  EXPECT_EQ(metrics["overlay_toggles"], 2);
  for (const char* state :
       {"XR_SESSION_STATE_VISIBLE", "XR_SESSION_STATE_FOCUSED", "XR_SESSION_STATE_LOSS_PENDING",
        "XR_SESSION_STATE_STOPPING", "XR_SESSION_STATE_EXITING"}) {
    EXPECT_TRUE(HasState(metrics, state)) << state;
  }
  // Frames are projected only while the session is visible: not while hidden (10 frames), not
  // in the SYNCHRONIZED frame after each session start, not during the loss. By the script,
  // the runtime waited 200 frames: session 1 shows frames 2-99 but for 70-79, session 2
  // frames 102-199, 186 in all (measured: 185 sent). The app learns of a state change from
  // the event it polls before its next frame, so each of the four changes of visibility may
  // shift one frame.
  constexpr int kVisibleFrames = (99 - 2 + 1) - 10 + (199 - 102 + 1);
  EXPECT_NEAR(metrics["frames_sent"].get<int>(), kVisibleFrames, 4);
  EXPECT_TRUE(fs::exists(dir / "out" / "trajectory.tum"));
}

TEST(XrClientLifecycle, InstanceLossLeavesCleanly) {
  const fs::path dir = TestDir();
  WritePlayedTrajectory(dir / "head.tum", 3.0);
  const int rc = RunBounded(Client(dir, "instance_loss@60", kLight), 120, dir / "log.txt");
  ASSERT_EQ(rc, 0) << ReadText(dir / "log.txt");
  const nlohmann::json report = ReadJson(dir / "runtime_report.json");
  ExpectCleanRuntimeReport(report);
  EXPECT_EQ(report["instance_lost"], true);
  const nlohmann::json metrics = ReadJson(dir / "out" / "xr_metrics.json");
  EXPECT_EQ(metrics["instance_lost"], true);
  EXPECT_TRUE(HasState(metrics, "INSTANCE_LOST"));
}

TEST(XrClientLifecycle, StdinKeysToggleAndQuitBeforeTheSessionRuns) {
  const fs::path dir = TestDir();
  WritePlayedTrajectory(dir / "head.tum", 2.0);
  // The keys are read on the first loop iteration, before the session is READY: the exit is
  // requested as soon as the session runs (READY -> begin -> exit -> STOPPING -> EXITING).
  const int rc =
      RunBounded("printf 'o\\nq\\n' | " + Client(dir, "", "--keys" + kLight), 60, dir / "log.txt");
  ASSERT_EQ(rc, 0) << ReadText(dir / "log.txt");
  ExpectCleanRuntimeReport(ReadJson(dir / "runtime_report.json"));
  const nlohmann::json metrics = ReadJson(dir / "out" / "xr_metrics.json");
  EXPECT_EQ(metrics["overlay_toggles"], 1);
  EXPECT_LE(metrics["frames"].get<int>(), 3);
  EXPECT_TRUE(HasState(metrics, "XR_SESSION_STATE_EXITING"));
}

TEST(XrClientLifecycle, GpuProjectorOnTheAppsContext) {
  const fs::path dir = TestDir();
  WritePlayedTrajectory(dir / "head.tum", 2.0);
  const int rc =
      RunBounded(Client(dir, "", "--projector gpu --no-mesh --frames 30"), 120, dir / "log.txt");
  ASSERT_EQ(rc, 0) << ReadText(dir / "log.txt");
  ExpectCleanRuntimeReport(ReadJson(dir / "runtime_report.json"));
  const nlohmann::json metrics = ReadJson(dir / "out" / "xr_metrics.json");
  EXPECT_EQ(metrics["projector"], "gpu");
  EXPECT_EQ(metrics["frames"], 30);
  EXPECT_GE(metrics["frames_sent"].get<int>(), 28);
}

}  // namespace
}  // namespace m2s::xr_test
