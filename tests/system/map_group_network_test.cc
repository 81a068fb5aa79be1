// Map groups with the real executables over LCM UDP multicast on the loopback of a private
// network namespace: two agents walking one path in opposite directions share one map; two
// sharded servers and four agents in two groups (every agent served by exactly one server,
// every group one map); a server stopped and restarted with --resume-maps continues its group's
// map in the same world. Clients run --fast (every frame answered before the next; which agent
// of a group starts its map still depends on scheduling). References: the generated ground truth
// through m2s_eval --agent (one Sim3 for all agents of a group) and the clients' metrics.json.
// Skipped, with one line, where namespaces are not permitted.
#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "lcm_test_bus.h"
#include "m2s/common/shard.h"
#include "m2s/common/trajectory.h"
#include "server_script.h"
#include "test_files.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;
constexpr const char* kUrl = testing::kTestLcmUrl;
constexpr double kFps = 30.0;

bool NamespacesPermitted() { return std::system("unshare -n true 2>/dev/null") == 0; }

fs::path Bin(const std::string& name) { return fs::path(M2S_BINARY_DIR) / "bin" / name; }

// A head-motion walk through the default room at 30 Hz: frames [first, first + count), or
// those places walked backwards in time (`reverse`), written as TUM.
void WriteWalk(const fs::path& path, uint64_t seed, size_t first, size_t count, bool reverse) {
  HeadMotionOptions motion = DefaultHeadMotionOptions();
  motion.seed = seed;
  motion.rate_hz = kFps;
  motion.duration_s = static_cast<double>(first + count) / kFps + 1.0;
  auto walk = GenerateHeadMotion(motion);
  ASSERT_TRUE(walk.ok()) << walk.error();
  ASSERT_GE(walk->size(), first + count);
  std::vector<TimedPose> poses;
  for (size_t i = 0; i < count; ++i) {
    const size_t place = first + (reverse ? count - 1 - i : i);
    poses.push_back({(*walk)[first + i].timestamp, (*walk)[place].world_from_camera});
  }
  auto trajectory = Trajectory::FromPoses(std::move(poses));
  ASSERT_TRUE(trajectory.ok()) << trajectory.error();
  ASSERT_TRUE(WriteTum(path.string(), *trajectory).ok());
}

// One m2s_client of `group` walking `walk` in the background (its pid appended to $clients).
std::string ClientLine(const fs::path& walk, const std::string& group, const fs::path& out) {
  return Bin("m2s_client").string() + " --lcm-url '" + kUrl + "' --fast --fps 30 --trajectory " +
         walk.string() + " --map-group " + group +
         " --projector cpu --budget 1000 --pose-timeout 60 --no-map-png --out " + out.string() +
         " > " + out.string() + ".log 2>&1 &\nclients=\"$clients $!\"\n";
}

// Waits for every client of $clients; the script exits 93 when one failed.
std::string WaitClientsLines() {
  return "for c in $clients; do wait $c || failed=1; done\nclients=\n"
         "[ -z \"$failed\" ] || { kill -TERM $server; wait $server; exit 93; }\n";
}

std::string NetnsLines() {
  return "ip link set lo up && ip route add 224.0.0.0/4 dev lo || exit 90\n";
}

int RunInNamespace(const fs::path& script) {
  return std::system(("unshare -n sh " + script.string()).c_str());
}

nlohmann::json Metrics(const fs::path& out) {
  return nlohmann::json::parse(testing::ReadFile(out / "metrics.json"));
}

// m2s_eval --agent over the agents' outputs: {"joint": {...}, "agents": [...]}.
nlohmann::json JointAte(const std::vector<fs::path>& outs, const fs::path& dir) {
  std::string command = Bin("m2s_eval").string() + " --json";
  for (const fs::path& out : outs) {
    command +=
        " --agent " + (out / "groundtruth.tum").string() + " " + (out / "trajectory.tum").string();
  }
  const fs::path result = dir / "joint.json";
  EXPECT_EQ(std::system((command + " > " + result.string()).c_str()), 0) << command;
  return nlohmann::json::parse(testing::ReadFile(result));
}

std::string Logs(const std::vector<fs::path>& outs, const fs::path& dir) {
  std::string all = testing::ReadFile(dir / "server.log");
  for (const fs::path& out : outs) all += testing::ReadFile(out.string() + ".log");
  return all;
}

TEST(MapGroupNetworkTest, TwoAgentsInOppositeDirectionsShareOneMapAcrossProcesses) {
  if (!NamespacesPermitted()) GTEST_SKIP() << "skipped: network namespaces not permitted here";
  const fs::path dir = testing::TempDir("group", "opposite");
  WriteWalk(dir / "a.tum", /*seed=*/4, 0, 180, /*reverse=*/false);
  WriteWalk(dir / "b.tum", /*seed=*/4, 0, 180, /*reverse=*/true);
  const std::vector<fs::path> outs = {dir / "a", dir / "b"};
  std::ofstream(dir / "run.sh") << NetnsLines()
                                << testing::StartServerLines(Bin("m2s_server").string() +
                                                                 " --lcm-url '" + kUrl +
                                                                 "' --stats-period 0 --stats-out " +
                                                                 (dir / "stats.json").string(),
                                                             dir)
                                << ClientLine(dir / "a.tum", "room", outs[0])
                                << ClientLine(dir / "b.tum", "room", outs[1]) << WaitClientsLines()
                                << testing::StopServerLines() << "exit 0\n";
  ASSERT_EQ(RunInNamespace(dir / "run.sh"), 0) << Logs(outs, dir);
  // Which agent starts the group's map depends on scheduling. That agent loses no frame; the
  // other either starts a map of its own at once, or first joins the group's map, which it
  // cannot see (it starts at the other end of the walk), and is lost until it starts its own
  // (MultiMapOptions::new_map_after_lost_s, 0.5 s) and initialises it: under 1 s of frames.
  std::vector<int> lost;
  for (const fs::path& out : outs) {
    const nlohmann::json m = Metrics(out);
    EXPECT_EQ(m["map_group"], "room");
    EXPECT_EQ(m["servers_seen"], 1);
    lost.push_back(m["frames_lost"].get<int>());
    EXPECT_LT(lost.back(), kFps) << out;
    EXPECT_FALSE(m["merged_at_s"].is_null()) << out;  // in the group's map by the end
  }
  EXPECT_EQ(*std::min_element(lost.begin(), lost.end()), 0);
  const nlohmann::json joint = JointAte(outs, dir);
  EXPECT_LT(joint["joint"]["ate_rmse"].get<double>(), 1e-3) << joint.dump();
  const nlohmann::json stats = nlohmann::json::parse(testing::ReadFile(dir / "stats.json"));
  ASSERT_EQ(stats["groups"].size(), 1u);
  EXPECT_EQ(stats["groups"][0]["agents_joined"], 2);
  fs::remove_all(dir);
}

// Two group names that hash to different shards of 2.
std::vector<std::string> GroupsOnBothShards() {
  const ShardSpec first{0, 2};
  std::string on_first, on_second;
  for (int i = 0; on_first.empty() || on_second.empty(); ++i) {
    const std::string name = "room-" + std::to_string(i);
    (first.Owns(ShardKeyOfGroup(name)) ? on_first : on_second) = name;
  }
  return {on_first, on_second};
}

TEST(MapGroupNetworkTest, TwoShardedServersServeFourAgentsInTwoGroupsEachExactlyOnce) {
  if (!NamespacesPermitted()) GTEST_SKIP() << "skipped: network namespaces not permitted here";
  const fs::path dir = testing::TempDir("group", "shards");
  const std::vector<std::string> groups = GroupsOnBothShards();
  // In each group, the second agent walks the first one's path one second behind it.
  WriteWalk(dir / "lead.tum", /*seed=*/6, 0, 120, false);
  WriteWalk(dir / "follow.tum", /*seed=*/6, 30, 120, false);
  std::vector<fs::path> outs;
  std::string clients;
  for (const std::string& group : groups) {
    for (const char* role : {"lead", "follow"}) {
      outs.push_back(dir / (group + "-" + role));
      clients += ClientLine(dir / (std::string(role) + ".tum"), group, outs.back());
    }
  }
  const std::string server =
      Bin("m2s_server").string() + " --lcm-url '" + kUrl + "' --stats-period 0 --shard ";
  const fs::path first = dir / "first", second = dir / "second";
  fs::create_directories(first);
  fs::create_directories(second);
  std::ofstream(dir / "run.sh")
      << NetnsLines()
      << testing::StartServerLines(server + "0/2 --stats-out " + (dir / "s0.json").string(), first)
      << "server0=$server\nserver0_log=$server_log\n"
      << testing::StartServerLines(server + "1/2 --stats-out " + (dir / "s1.json").string(), second)
      << clients << WaitClientsLines() << testing::StopServerLines()
      << "server=$server0\nserver_log=$server0_log\n"
      << testing::StopServerLines() << "exit 0\n";
  ASSERT_EQ(RunInNamespace(dir / "run.sh"), 0)
      << testing::ReadFile(first / "server.log") << testing::ReadFile(second / "server.log");
  for (const fs::path& out : outs) {
    const nlohmann::json m = Metrics(out);
    EXPECT_EQ(m["servers_seen"], 1) << out;  // exactly one server answered
    EXPECT_EQ(m["frames_lost"], 0) << out;
    EXPECT_FALSE(m["merged_at_s"].is_null()) << out;
  }
  const nlohmann::json s0 = nlohmann::json::parse(testing::ReadFile(dir / "s0.json"));
  const nlohmann::json s1 = nlohmann::json::parse(testing::ReadFile(dir / "s1.json"));
  // Each group on its own server, with both its agents; no session opened twice.
  ASSERT_EQ(s0["groups"].size(), 1u);
  ASSERT_EQ(s1["groups"].size(), 1u);
  EXPECT_EQ(s0["groups"][0]["name"], groups[0]);
  EXPECT_EQ(s1["groups"][0]["name"], groups[1]);
  EXPECT_EQ(s0["groups"][0]["agents_joined"], 2);
  EXPECT_EQ(s1["groups"][0]["agents_joined"], 2);
  EXPECT_EQ(s0["sessions_started"].get<int>() + s1["sessions_started"].get<int>(), 4);
  for (size_t g = 0; g < groups.size(); ++g) {
    const nlohmann::json joint = JointAte({outs[2 * g], outs[2 * g + 1]}, dir);
    EXPECT_LT(joint["joint"]["ate_rmse"].get<double>(), 1e-3) << groups[g] << joint.dump();
  }
  fs::remove_all(dir);
}

TEST(MapGroupNetworkTest, ARestartedServerResumesTheGroupsMapInTheSameWorld) {
  if (!NamespacesPermitted()) GTEST_SKIP() << "skipped: network namespaces not permitted here";
  const fs::path dir = testing::TempDir("group", "restart");
  WriteWalk(dir / "before.tum", /*seed=*/8, 0, 120, false);
  WriteWalk(dir / "after.tum", /*seed=*/8, 90, 90, false);
  const fs::path maps = dir / "maps";
  const std::vector<fs::path> outs = {dir / "before", dir / "after"};
  const std::string server = Bin("m2s_server").string() + " --lcm-url '" + kUrl +
                             "' --stats-period 0 --save-maps " + maps.string();
  std::ofstream(dir / "run.sh")
      << NetnsLines() << testing::StartServerLines(server, dir)
      << ClientLine(dir / "before.tum", "lab", outs[0]) << WaitClientsLines()
      << testing::StopServerLines()  // SIGTERM: the group's map is saved at exit
      << "mv " << (dir / "server.log").string() << " " << (dir / "first_server.log").string()
      << "\n"
      << testing::StartServerLines(server + " --resume-maps", dir)
      << ClientLine(dir / "after.tum", "lab", outs[1]) << WaitClientsLines()
      << testing::StopServerLines() << "exit 0\n";
  ASSERT_EQ(RunInNamespace(dir / "run.sh"), 0)
      << testing::ReadFile(dir / "first_server.log") << Logs(outs, dir);
  EXPECT_TRUE(fs::exists(maps / "group-lab.m2smap"));
  EXPECT_NE(testing::ReadFile(dir / "server.log").find("map group lab resumed"), std::string::npos);
  const nlohmann::json after = Metrics(outs[1]);
  // It walks where the first agent mapped: in the resumed map from its first frame (every
  // frame tracked, the first pose already in the group's map: merged_at_s is that pose's
  // round trip).
  EXPECT_EQ(after["frames_tracked"], after["frames_total"]);
  EXPECT_EQ(after["frames_in_unmerged_maps"], 0);
  EXPECT_FALSE(after["merged_at_s"].is_null());
  // Both servers' poses are in one world.
  const nlohmann::json joint = JointAte(outs, dir);
  EXPECT_LT(joint["joint"]["ate_rmse"].get<double>(), 1e-3) << joint.dump();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace m2s
