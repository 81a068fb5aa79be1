// Helpers of the m2s_xr_client end-to-end tests: run the real binary on the simulated OpenXR
// runtime (through the real loader) with a played head trajectory, and read what it and the
// runtime wrote.
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "m2s/common/trajectory.h"

namespace m2s::xr_test {

namespace fs = std::filesystem;

inline const std::string kBin = std::string(M2S_BINARY_DIR) + "/bin";
inline constexpr double kTimeShiftS = 10.0;  // played stamps start at 10 s: display time == stamp
inline constexpr double kRateHz = 72.0;

// A fresh folder per test under the build tree.
inline fs::path TestDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path dir = fs::path(M2S_BINARY_DIR) / "test_tmp" /
                       (std::string("xr_client_") + info->test_suite_name() + "_" + info->name());
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// The first `seconds` of DefaultTrajectory() (through the default scene), stamps shifted by
// kTimeShiftS, written as TUM.
inline Trajectory WritePlayedTrajectory(const fs::path& path, double seconds) {
  std::vector<TimedPose> poses;
  for (const TimedPose& p : DefaultTrajectory()) {
    if (p.timestamp > seconds) break;
    TimedPose shifted = p;
    shifted.timestamp += kTimeShiftS;
    poses.push_back(shifted);
  }
  Trajectory trajectory = *Trajectory::FromPoses(poses);
  EXPECT_TRUE(WriteTum(path.string(), trajectory).ok());
  return trajectory;
}

inline nlohmann::json ReadJson(const fs::path& path) {
  std::ifstream file(path);
  EXPECT_TRUE(file.good()) << "missing " << path;
  nlohmann::json j;
  if (file) file >> j;
  return j;
}

inline std::string Quote(const std::string& s) { return "'" + s + "'"; }

// The environment of the simulated runtime for one run.
inline std::string RuntimeEnv(const fs::path& dir, const fs::path& trajectory,
                              const std::string& script, const std::string& capture_frames) {
  std::ostringstream env;
  env << "XR_RUNTIME_JSON=" << Quote(M2S_XR_SIM_RUNTIME_JSON)
      << " M2S_XR_SIM_TRAJECTORY=" << Quote(trajectory.string())
      << " M2S_XR_SIM_RATE_HZ=" << kRateHz << " M2S_XR_SIM_EYE_SIZE=320x320"
      << " M2S_XR_SIM_REPORT=" << Quote((dir / "runtime_report.json").string());
  if (!script.empty()) env << " M2S_XR_SIM_SCRIPT=" << Quote(script);
  if (!capture_frames.empty()) {
    env << " M2S_XR_SIM_CAPTURE_DIR=" << Quote((dir / "capture").string())
        << " M2S_XR_SIM_CAPTURE_FRAMES=" << Quote(capture_frames);
  }
  return env.str();
}

// Runs a shell command line with a time bound; returns the exit status (124: timed out). The
// line goes through a script file next to the log so that its own quoting stays intact.
inline int RunBounded(const std::string& command, int timeout_s, const fs::path& log) {
  const fs::path script = fs::path(log).replace_extension(".sh");
  std::ofstream(script) << command << "\n";
  const std::string line = "timeout " + std::to_string(timeout_s) + " sh " +
                           Quote(script.string()) + " > " + Quote(log.string()) + " 2>&1";
  const int status = std::system(line.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

inline std::string ReadText(const fs::path& path) {
  std::ifstream file(path);
  std::stringstream s;
  s << file.rdbuf();
  return s.str();
}

// The runtime's own account of the run: no misuse, every handle destroyed by the app.
inline void ExpectCleanRuntimeReport(const nlohmann::json& report) {
  EXPECT_EQ(report.value("misuse", -1), 0) << report["misuse_messages"].dump(1);
  EXPECT_EQ(report.value("handles_left_alive", -1), 0);
  EXPECT_EQ(report.value("implicitly_destroyed", -1), 0);
  EXPECT_EQ(report.value("sessions_destroyed_running", -1), 0);
  EXPECT_EQ(report.value("sessions_created", -1), report.value("sessions_destroyed", -2));
  EXPECT_EQ(report.value("swapchains_created", -1), report.value("swapchains_destroyed", -2));
  EXPECT_EQ(report.value("spaces_created", -1), report.value("spaces_destroyed", -2));
  EXPECT_EQ(report.value("gl_failures", -1), 0);
}

}  // namespace m2s::xr_test
