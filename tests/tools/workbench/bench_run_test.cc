// Running commands and whole sweeps: m2s_bench with the real m2s_client, as a user runs it.
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "m2s/workbench/runner.h"
#include "temp_dir.h"

namespace m2s::workbench {
namespace {

namespace fs = std::filesystem;

std::string Read(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

TEST(WorkbenchRunner, CommandsExitCodesOutputAndTimeLimit) {
  const fs::path dir = TempDir("commands");
  const std::string log = (dir / "log.txt").string();
  CommandResult ok = RunCommand({"sh", "-c", "echo out; echo err >&2; exit 3"}, log, 60);
  EXPECT_EQ(ok.exit_code, 3);
  EXPECT_FALSE(ok.timed_out);
  EXPECT_EQ(Read(log), "out\nerr\n");
  // A command that would run for a minute, stopped at the 1 s limit.
  CommandResult slow = RunCommand({"sleep", "60"}, log, 1);
  EXPECT_TRUE(slow.timed_out);
  CommandResult missing = RunCommand({"/nonexistent/m2s_client"}, log, 60);
  EXPECT_NE(missing.exit_code, 0);
  fs::remove_all(dir);
}

// A small sweep end to end: two noise levels of the built-in SLAM and a plug-in path that does
// not exist (its runs fail cleanly and are reported), on the default scene for 2 s.
TEST(WorkbenchRunner, SweepOfRealRunsWritesTablesAndPlots) {
  const fs::path dir = TempDir("sweep");
  std::ofstream(dir / "sweep.json") << R"({
      "methods": [{"name": "vertex"}, {"name": "broken", "plugin": "./no_such_plugin.so"}],
      "scenes": [{"name": "room", "duration_s": 2}],
      "fps": [30], "noise_px": [0, 0.5]})";
  const std::string bin = std::string(M2S_BINARY_DIR) + "/bin/m2s_bench";
  const std::string cmd = bin + " --config " + (dir / "sweep.json").string() + " --out " +
                          (dir / "out").string() + " --jobs 2 2>" + (dir / "stderr.txt").string();
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1) << Read(dir / "stderr.txt");  // the broken runs failed

  std::ifstream json_file(dir / "out" / "results.json");
  const nlohmann::json json = nlohmann::json::parse(json_file);
  ASSERT_EQ(json["results"].size(), 4u);
  const nlohmann::json& clean = json["results"][0];
  const nlohmann::json& noisy = json["results"][1];
  EXPECT_EQ(clean["status"], "ok");
  EXPECT_EQ(clean["frames_total"], 61);  // 2 s at 30 fps, both ends
  EXPECT_GT(clean["frames_tracked"].get<int>(), 20);
  EXPECT_EQ(clean["frames_lost"], 0);
  // Noise-free vertex features: sub-0.1 mm; 0.5 px noise: millimetres, not metres.
  EXPECT_LT(clean["ate_rmse_m"].get<double>(), 1e-4);
  EXPECT_GT(noisy["ate_rmse_m"].get<double>(), clean["ate_rmse_m"].get<double>());
  EXPECT_LT(noisy["ate_rmse_m"].get<double>(), 0.01);
  for (int i : {2, 3}) {
    EXPECT_EQ(json["results"][i]["status"], "failed");
    EXPECT_NE(json["results"][i]["message"].get<std::string>().find("exit"), std::string::npos);
  }
  EXPECT_TRUE(fs::exists(dir / "out" / "results.md"));
  EXPECT_TRUE(fs::exists(dir / "out" / "results.csv"));
  EXPECT_TRUE(fs::exists(dir / "out" / "plots" / "ate_vs_noise_room.png"));
  EXPECT_TRUE(fs::exists(dir / "out" / "plots" / "error_over_time_room_30fps.png"));
  EXPECT_TRUE(fs::exists(dir / "out" / "runs" / "vertex__room__30fps__n0__o0" / "log.txt"));
  fs::remove_all(dir);
}

TEST(WorkbenchRunner, BadSweepFileIsOneLineAndExitTwo) {
  const fs::path dir = TempDir("bad");
  std::ofstream(dir / "sweep.json") << R"({"methods": [{"name": "x"}], "scenes": []})";
  const std::string bin = std::string(M2S_BINARY_DIR) + "/bin/m2s_bench";
  const std::string cmd = bin + " --config " + (dir / "sweep.json").string() + " --out " +
                          (dir / "out").string() + " 2>" + (dir / "stderr.txt").string();
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2);
  const std::string err = Read(dir / "stderr.txt");
  EXPECT_NE(err.find("at least one scene"), std::string::npos) << err;
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace m2s::workbench
