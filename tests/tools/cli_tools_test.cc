// Runs m2s_features, m2s_eval and m2s_server (its config handling) as processes and checks what
// they write.
#include <signal.h>
#include <sys/wait.h>

#include <unistd.h>
#include <cstdio>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "m2s/common/camera.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;

struct RunResult {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

// Runs `bin args` with stdout and stderr captured to files in `dir`.
RunResult RunTool(const fs::path& dir, const std::string& bin, const std::string& args) {
  const fs::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string cmd = std::string(M2S_BINARY_DIR) + "/bin/" + bin + " " + args + " >" +
                          out.string() + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  RunResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream o(out), e(err);
  std::stringstream so, se;
  so << o.rdbuf();
  se << e.rdbuf();
  r.out = so.str();
  r.err = se.str();
  return r;
}

class CliToolsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("m2s_cli_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(CliToolsTest, FeaturesMatchNaiveProjectionOfTheDefaultScene) {
  const Trajectory traj = DefaultTrajectory();
  ASSERT_TRUE(WriteTum((dir_ / "gt.tum").string(), traj).ok());
  const fs::path csv = dir_ / "features.csv";
  const RunResult r =
      RunTool(dir_, "m2s_features",
              "--default-scene --trajectory " + (dir_ / "gt.tum").string() +
                  " --index 100 --width 640 --height 480 --fov-deg 90 --out " + csv.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;

  // Independent reference: project every vertex in double precision, one at a time.
  const Scene scene = MakeDefaultScene();
  const Camera cam = Camera::FromHorizontalFov(640, 480, 90.0);
  const Pose3 camera_from_world = traj[100].world_from_camera.Inverse();
  std::map<uint32_t, Eigen::Vector2d> expected;
  for (size_t id = 0; id < scene.positions.size(); ++id) {
    const Eigen::Vector3d pc = camera_from_world * scene.positions[id].cast<double>();
    if (pc.z() < cam.near || pc.z() > cam.far) continue;
    const Eigen::Vector2d uv = cam.Project(pc);
    // Vertices within 1e-3 px of the border are ambiguous in float; skip them on both sides.
    if (uv.x() < 1e-3 || uv.y() < 1e-3 || uv.x() > cam.width - 1e-3 || uv.y() > cam.height - 1e-3)
      continue;
    expected[static_cast<uint32_t>(id)] = uv;
  }
  ASSERT_GT(expected.size(), 1000u);

  std::ifstream in(csv);
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  EXPECT_EQ(line, "id,u,v,depth,x,y,z");
  size_t matched = 0;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string field;
    double v[7];
    for (double& x : v) {
      ASSERT_TRUE(std::getline(ss, field, ',')) << line;
      x = std::stod(field);
    }
    const auto id = static_cast<uint32_t>(v[0]);
    const auto it = expected.find(id);
    if (it == expected.end()) continue;  // border-ambiguous vertex
    ++matched;
    // Measured: u, v within 9.3e-5 px of the double reference (the tool projects in float:
    // one float ulp at u = 640 is 6e-5), positions within 5e-9 m of the mesh's floats (the
    // CSV's decimal digits). The bounds allow about 10x.
    EXPECT_NEAR(v[1], it->second.x(), 1e-3);
    EXPECT_NEAR(v[2], it->second.y(), 1e-3);
    EXPECT_NEAR(v[4], scene.positions[id].x(), 5e-8);
    EXPECT_NEAR(v[6], scene.positions[id].z(), 5e-8);
  }
  EXPECT_EQ(matched, expected.size());
}

TEST_F(CliToolsTest, FeaturesRejectsBadInputWithOneLine) {
  const RunResult missing =
      RunTool(dir_, "m2s_features", "--mesh /nonexistent/mesh.obj --index 0 --out x.csv");
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_NE(missing.err.find("nonexistent"), std::string::npos) << missing.err;
  std::ofstream(dir_ / "bad.tum") << "0 1 2 3\n";
  const RunResult bad_traj = RunTool(dir_, "m2s_features",
                                     "--default-scene --trajectory " + (dir_ / "bad.tum").string() +
                                         " --index 0 --out " + (dir_ / "x.csv").string());
  EXPECT_NE(bad_traj.exit_code, 0);
  EXPECT_NE(bad_traj.err.find("line 1"), std::string::npos) << bad_traj.err;
  EXPECT_EQ(std::count(bad_traj.err.begin(), bad_traj.err.end(), '\n'), 1) << bad_traj.err;
}

// The server reads its JSON config before it touches the network: every bad config ends the
// process with exit code 2 and one line naming the problem.
TEST_F(CliToolsTest, ServerRejectsBadConfigWithOneLine) {
  auto run_with = [this](const std::string& json, const std::string& flags = "") {
    std::ofstream(dir_ / "server.json") << json;
    return RunTool(dir_, "m2s_server",
                   "--lcm-url memq:// --config " + (dir_ / "server.json").string() + " " + flags);
  };
  auto expect_one_line = [](const RunResult& r, const std::string& needle) {
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  };
  expect_one_line(run_with(R"({"max_sessions": 2, "max_sesions": 3})"),
                  "unknown key \"max_sesions\"");
  expect_one_line(run_with(R"({"max_sessions": "four"})"), "type must be number");
  expect_one_line(run_with(R"({"max_sessions": 2,)"), "parse error");
  expect_one_line(run_with(R"([1, 2])"), "not a JSON object");
  // A value from the file reaches the options' check; a flag given on the command line wins.
  expect_one_line(run_with(R"({"max_sessions": 0})"), "max_sessions must be positive");
  expect_one_line(run_with(R"({"max_sessions": 4})", "--max-sessions 0"),
                  "max_sessions must be positive");
  expect_one_line(run_with(R"({"queue_capacity": -1})", "--max-sessions 2"),
                  "queue_capacity must be positive");
  const RunResult missing =
      RunTool(dir_, "m2s_server", "--lcm-url memq:// --config " + (dir_ / "none.json").string());
  expect_one_line(missing, "cannot open config file");
}

TEST_F(CliToolsTest, EvalRecoversAKnownSimilarity) {
  const Trajectory gt = DefaultTrajectory();
  const Sim3 est_from_gt(
      0.4, Eigen::Quaterniond(Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, -2, 0.5).normalized())),
      Eigen::Vector3d(2, -1, 0.3));
  std::vector<TimedPose> est_poses;
  for (const TimedPose& p : gt)
    est_poses.push_back({p.timestamp, est_from_gt.TransformPose(p.world_from_camera)});
  const Expected<Trajectory> est = Trajectory::FromPoses(est_poses);
  ASSERT_TRUE(est.ok());
  ASSERT_TRUE(WriteTum((dir_ / "gt.tum").string(), gt).ok());
  ASSERT_TRUE(WriteTum((dir_ / "est.tum").string(), *est).ok());

  const RunResult sim3 = RunTool(
      dir_, "m2s_eval",
      (dir_ / "gt.tum").string() + " " + (dir_ / "est.tum").string() + " --align sim3 --json");
  ASSERT_EQ(sim3.exit_code, 0) << sim3.err;
  const nlohmann::json j = nlohmann::json::parse(sim3.out);
  // Measured: ATE 4.0e-15 m and scale off by 4.4e-16. The TUM files keep 17 significant
  // digits, so what is left is double rounding in the alignment; the bounds allow 10x that.
  EXPECT_LT(j.at("ate_rmse").get<double>(), 4e-14);
  EXPECT_NEAR(j.at("scale").get<double>(), 1.0 / 0.4, 5e-15);
  EXPECT_EQ(j.at("n_matched").get<int>(), static_cast<int>(gt.size()));
  for (const char* key : {"ate_mean", "ate_max", "rpe_rmse"}) EXPECT_TRUE(j.contains(key)) << key;

  // Rigid alignment cannot absorb the scale: the error must be large.
  const RunResult se3 = RunTool(
      dir_, "m2s_eval",
      (dir_ / "gt.tum").string() + " " + (dir_ / "est.tum").string() + " --align se3 --json");
  ASSERT_EQ(se3.exit_code, 0) << se3.err;
  EXPECT_GT(nlohmann::json::parse(se3.out).at("ate_rmse").get<double>(), 0.1);
}

TEST_F(CliToolsTest, EvalSavesThePerPoseErrors) {
  // One pose displaced by 0.25 m, no alignment: that pose's error is 0.25 m, every other 0.
  const Trajectory gt = DefaultTrajectory();
  const size_t displaced = gt.size() / 3;
  std::vector<TimedPose> est_poses(gt.begin(), gt.end());
  est_poses[displaced].world_from_camera =
      Pose3(est_poses[displaced].world_from_camera.rotation(),
            est_poses[displaced].world_from_camera.translation() + Eigen::Vector3d(0, 0.15, 0.2));
  const Expected<Trajectory> est = Trajectory::FromPoses(est_poses);
  ASSERT_TRUE(est.ok());
  ASSERT_TRUE(WriteTum((dir_ / "gt.tum").string(), gt).ok());
  ASSERT_TRUE(WriteTum((dir_ / "est.tum").string(), *est).ok());
  const fs::path errors = dir_ / "errors.txt";
  const RunResult r = RunTool(dir_, "m2s_eval",
                              (dir_ / "gt.tum").string() + " " + (dir_ / "est.tum").string() +
                                  " --align none --save-errors " + errors.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream in(errors);
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  EXPECT_EQ(line[0], '#');
  size_t n = 0;
  double t = 0.0, e = 0.0;
  while (in >> t >> e) {
    ASSERT_LT(n, gt.size());
    // Measured: stamps exact, errors within 8.3e-17 m (double rounding of |(0, 0.15, 0.2)|).
    EXPECT_NEAR(t, gt[n].timestamp, 1e-12);
    EXPECT_NEAR(e, n == displaced ? 0.25 : 0.0, 1e-15) << "pose " << n;
    ++n;
  }
  EXPECT_EQ(n, gt.size());
}

// Group mode: two agents, each a part of the default trajectory with its own ground truth.
// Estimates made by one known Sim3 from the ground truth share one world: joint ATE ~0. With a
// different Sim3 per agent, each agent alone still aligns exactly (per-agent ATE ~0) but no
// single transform fits both (joint ATE large).
TEST_F(CliToolsTest, EvalJointAteOfAGroupRecoversAKnownSimilarity) {
  const Trajectory gt = DefaultTrajectory();
  const size_t half = gt.size() / 2;
  const Sim3 shared(
      0.4, Eigen::Quaterniond(Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, -2, 0.5).normalized())),
      Eigen::Vector3d(2, -1, 0.3));
  const Sim3 other(
      1.7, Eigen::Quaterniond(Eigen::AngleAxisd(-1.1, Eigen::Vector3d(0, 1, 1).normalized())),
      Eigen::Vector3d(-0.5, 3, 1));
  auto write = [&](const std::string& name, size_t begin, size_t end, const Sim3* est_from_gt) {
    std::vector<TimedPose> poses;
    for (size_t i = begin; i < end; ++i) {
      poses.push_back({gt[i].timestamp, est_from_gt
                                            ? est_from_gt->TransformPose(gt[i].world_from_camera)
                                            : gt[i].world_from_camera});
    }
    const Expected<Trajectory> t = Trajectory::FromPoses(poses);
    ASSERT_TRUE(t.ok());
    ASSERT_TRUE(WriteTum((dir_ / name).string(), *t).ok());
  };
  write("gt1.tum", 0, half, nullptr);
  write("gt2.tum", half, gt.size(), nullptr);
  write("est1.tum", 0, half, &shared);
  write("est2_shared.tum", half, gt.size(), &shared);
  write("est2_other.tum", half, gt.size(), &other);
  auto run = [&](const std::string& est2) {
    const RunResult r = RunTool(
        dir_, "m2s_eval",
        "--agent " + (dir_ / "gt1.tum").string() + " " + (dir_ / "est1.tum").string() +
            " --agent " + (dir_ / "gt2.tum").string() + " " + (dir_ / est2).string() + " --json");
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return nlohmann::json::parse(r.out);
  };
  const nlohmann::json one_world = run("est2_shared.tum");
  // Measured: joint ATE 1.5e-14 m, scale off by 8.9e-16 (double rounding of the 17-digit TUM
  // files, as in the one-agent test); the bounds allow about 10x.
  EXPECT_LT(one_world.at("joint").at("ate_rmse").get<double>(), 1.5e-13);
  EXPECT_NEAR(one_world.at("joint").at("scale").get<double>(), 1.0 / 0.4, 1e-14);
  EXPECT_EQ(one_world.at("joint").at("n_matched").get<size_t>(), gt.size());
  ASSERT_EQ(one_world.at("agents").size(), 2u);
  EXPECT_EQ(one_world.at("agents")[0].at("n_matched").get<size_t>(), half);
  EXPECT_EQ(one_world.at("agents")[1].at("n_matched").get<size_t>(), gt.size() - half);

  // Measured: joint ATE 1.76 m; each agent alone 1.1e-14 and 5.0e-15 m, the second agent's
  // scale off by 1.1e-15.
  const nlohmann::json two_worlds = run("est2_other.tum");
  EXPECT_GT(two_worlds.at("joint").at("ate_rmse").get<double>(), 0.5);
  for (const nlohmann::json& agent : two_worlds.at("agents")) {
    EXPECT_LT(agent.at("ate_rmse").get<double>(), 1.5e-13) << agent.dump();
  }
  EXPECT_NEAR(two_worlds.at("agents")[1].at("scale").get<double>(), 1.0 / 1.7, 1e-14);

  // An odd number of files, or --agent with --save-errors: one line, non-zero exit.
  const RunResult odd = RunTool(dir_, "m2s_eval", "--agent " + (dir_ / "gt1.tum").string());
  EXPECT_NE(odd.exit_code, 0);
  EXPECT_EQ(std::count(odd.err.begin(), odd.err.end(), '\n'), 1) << odd.err;
}

// --load-map GROUP=FILE: a file that does not exist or that the group cannot load ends the
// server before it serves anything, with one line naming the file and a non-zero exit.
TEST_F(CliToolsTest, ServerRefusesAMapGroupFileItCannotLoad) {
  const fs::path missing = dir_ / "missing.m2smap";
  const RunResult none =
      RunTool(dir_, "m2s_server", "--lcm-url memq:// --load-map room-a=" + missing.string());
  EXPECT_NE(none.exit_code, 0);
  EXPECT_NE(none.err.find(missing.string()), std::string::npos) << none.err;
  EXPECT_EQ(std::count(none.err.begin(), none.err.end(), '\n'), 1) << none.err;

  const fs::path garbage = dir_ / "garbage.m2smap";
  std::ofstream(garbage) << "not a map";
  const RunResult bad =
      RunTool(dir_, "m2s_server", "--lcm-url memq:// --load-map room-a=" + garbage.string());
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.err.find("room-a"), std::string::npos) << bad.err;
  EXPECT_NE(bad.err.rfind("m2s_server: "), std::string::npos) << bad.err;

  const RunResult name = RunTool(dir_, "m2s_server", "--lcm-url memq:// --load-map 'a b=x'");
  EXPECT_NE(name.exit_code, 0);
  EXPECT_NE(name.err.find("map group name"), std::string::npos) << name.err;
  const RunResult shard = RunTool(dir_, "m2s_server", "--lcm-url memq:// --shard 2/2");
  EXPECT_EQ(shard.exit_code, 2);
  EXPECT_NE(shard.err.find("--shard"), std::string::npos) << shard.err;
}

// --stats-out: the server writes its counters as JSON when it stops. The test reads the
// server's log through a pipe until it listens (no sleep), stops it with SIGTERM and reads the
// file.
TEST_F(CliToolsTest, ServerWritesItsStatsAtExit) {
  const fs::path stats = dir_ / "stats.json";
  int pipe_fds[2];
  ASSERT_EQ(::pipe(pipe_fds), 0);
  const std::string bin = std::string(M2S_BINARY_DIR) + "/bin/m2s_server";
  const std::string out_arg = stats.string();
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::dup2(pipe_fds[1], STDERR_FILENO);
    ::close(pipe_fds[0]);
    ::execl(bin.c_str(), bin.c_str(), "--lcm-url", "memq://", "--shard", "1/3", "--stats-out",
            out_arg.c_str(), "--stats-period", "0", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(pipe_fds[1]);
  FILE* log = ::fdopen(pipe_fds[0], "r");
  ASSERT_NE(log, nullptr);
  char line[4096];
  bool listening = false;
  while (!listening && std::fgets(line, sizeof(line), log)) {
    listening = std::string(line).find("listening on") != std::string::npos;
  }
  ASSERT_TRUE(listening) << "the server ended before listening";
  ::kill(pid, SIGTERM);
  while (std::fgets(line, sizeof(line), log)) {
  }
  std::fclose(log);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  std::ifstream in(stats);
  ASSERT_TRUE(in) << stats;
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("shard"), "1/3");
  EXPECT_EQ(j.at("shard_index"), 1);
  EXPECT_EQ(j.at("shard_count"), 3);
  EXPECT_NE(j.at("server_instance").get<int64_t>(), 0);
  EXPECT_EQ(j.at("messages_in"), 0);
  EXPECT_EQ(j.at("sessions_started"), 0);
  EXPECT_TRUE(j.at("groups").is_array());
  EXPECT_EQ(j.at("authenticated"), false);
  for (const char* key : {"frames_in", "frames_processed", "sessions_ended", "other_shard_hellos",
                          "other_shard_messages", "groups_created", "groups_refused"}) {
    EXPECT_EQ(j.at(key), 0) << key;
  }
  EXPECT_EQ(j.at("drops").at("bad_group_name"), 0);
  EXPECT_EQ(j.at("drops").at("max_groups"), 0);
}

TEST_F(CliToolsTest, EvalRejectsBadInputWithOneLine) {
  const RunResult r = RunTool(dir_, "m2s_eval", "/nonexistent/gt.tum /nonexistent/est.tum --json");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(r.out.empty());
  EXPECT_NE(r.err.find("nonexistent"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

}  // namespace
}  // namespace m2s
