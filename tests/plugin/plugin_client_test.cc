// m2s_client --on-device --fast --method pnp_odometry end to end: the plug-in is found by name
// in <build>/plugins and the run writes metrics.json; a missing method is one clear line.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace {

const std::string kClient = std::string(M2S_BINARY_DIR) + "/bin/m2s_client";

// Runs `command`, returns its exit status and (with 2>&1 in it) its output.
int RunCommand(const std::string& command, std::string* output) {
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return -1;
  char buffer[512];
  while (fgets(buffer, sizeof(buffer), pipe) != nullptr) *output += buffer;
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(PluginClient, PnpOdometryRunWritesMetrics) {
  const auto out = std::filesystem::temp_directory_path() / "m2s_plugin_client_test";
  std::filesystem::remove_all(out);
  std::string output;
  const int frames = 61;  // 2 s at 30 fps
  const int rc =
      RunCommand("env -u M2S_PLUGIN_PATH " + kClient +
                     " --on-device --fast --method pnp_odometry --projector cpu --fps 30 "
                     "--duration 2 --no-map-png --out " +
                     out.string() + " 2>&1",
                 &output);
  ASSERT_EQ(rc, 0) << output;
  std::ifstream file(out / "metrics.json");
  ASSERT_TRUE(file) << output;
  const nlohmann::json metrics = nlohmann::json::parse(file);
  EXPECT_EQ(metrics.at("frames_total").get<int>(), frames);
  EXPECT_EQ(metrics.at("frames_processed").get<int>(), frames);
  // Initialisation waits for 20 px of median feature motion (about 1 s of this trajectory);
  // from then on every frame is tracked. Measured: 32 tracked, ATE 1.5 mm.
  EXPECT_GE(metrics.at("frames_tracked").get<int>(), 25);
  EXPECT_EQ(metrics.at("frames_lost").get<int>(), 0);
  EXPECT_LT(metrics.at("ate_rmse").get<double>(), 5e-3);
  EXPECT_GT(metrics.at("map_points").get<int>(), 0);
  EXPECT_EQ(metrics.at("keyframes").get<int>(), 0);  // an odometry has none
  std::filesystem::remove_all(out);
}

TEST(PluginClient, AMissingMethodIsOneClearLine) {
  std::string output;
  const int rc = RunCommand("M2S_PLUGIN_PATH=/nonexistent " + kClient +
                                " --on-device --fast --method no_such_method --projector cpu "
                                "--duration 0.1 --no-map-png --out /tmp/m2s_never 2>&1",
                            &output);
  EXPECT_NE(rc, 0);
  EXPECT_NE(output.find("m2s_client: plug-in no_such_method: libm2s_plugin_no_such_method.so "
                        "not found (searched /nonexistent, "),
            std::string::npos)
      << output;
}

TEST(PluginClient, RefusesMethodWithMapGroup) {
  std::string output;
  EXPECT_EQ(RunCommand(kClient + " --method pnp_odometry --map-group room 2>&1", &output), 2);
  EXPECT_NE(output.find("--map-group needs the built-in SLAM"), std::string::npos) << output;
}

}  // namespace
