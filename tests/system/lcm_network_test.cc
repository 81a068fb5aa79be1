// Client and server over LCM UDP multicast on the loopback of a private network namespace
// (this test process enters its own with unshare(CLONE_NEWNET); the two-process test starts
// the real executables in another one). Skipped, with one line, where namespaces are not
// permitted.
#include <sched.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "fake_system.h"
#include "m2s/client/client_session.h"
#include "m2s/headless/headless_run.h"
#include "m2s/server_app/lcm_server.h"
#include "test_files.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;
constexpr const char* kUrl = "udpm://239.255.76.67:7667?ttl=0";

// Enters a private network namespace with multicast routed over loopback, once per process.
const std::string& NetworkProblem() {
  static const std::string problem = [] {
    if (unshare(CLONE_NEWNET) != 0) return std::string("unshare(CLONE_NEWNET) not permitted");
    if (std::system("ip link set lo up && ip route add 224.0.0.0/4 dev lo") != 0) {
      return std::string("cannot set up loopback multicast in the namespace");
    }
    return std::string();
  }();
  return problem;
}

#define REQUIRE_NETWORK()                                                                          \
  if (!NetworkProblem().empty()) {                                                                 \
    GTEST_SKIP() << "skipped: network namespaces not permitted here (" << NetworkProblem() << ")"; \
  }

std::string ReadFile(const fs::path& path) { return testing::ReadFile(path); }
fs::path TempDir(const std::string& name) { return testing::TempDir("net", name); }

headless::HeadlessOptions ShortRun(const fs::path& out, bool on_device) {
  headless::HeadlessOptions o;
  o.fast = true;
  o.on_device = on_device;
  o.lcm_url = kUrl;
  o.projector = "cpu";
  o.fps = 10;
  o.max_frames = 20;
  o.noise.budget = 2500;
  o.render_map = false;
  o.out_dir = out.string();
  return o;
}

server_app::LcmServerOptions ServerOptions() {
  server_app::LcmServerOptions options;
  options.lcm_url = kUrl;
  options.stats_period_s = 0.2;
  options.log_stats = false;
  options.server.drop_log_period_s = 100;
  return options;
}

TEST(LcmNetworkTest, TwoClientsAtOnceGetTheResultsTheyGetAlone) {
  REQUIRE_NETWORK();
  const fs::path dir = TempDir("two");
  // Alone, on-device (deterministic): the references.
  headless::HeadlessOptions a = ShortRun(dir / "a_alone", true);
  headless::HeadlessOptions b = ShortRun(dir / "b_alone", true);
  b.noise.pixel_noise_sigma = 0.3;
  b.noise.seed = 5;
  ASSERT_TRUE(headless::RunHeadless(a).ok());
  ASSERT_TRUE(headless::RunHeadless(b).ok());
  // Together on one LCM server.
  server_app::LcmServer server(ServerOptions());
  ASSERT_TRUE(server.Start().ok());
  a.on_device = b.on_device = false;
  a.out_dir = (dir / "a").string();
  b.out_dir = (dir / "b").string();
  Expected<headless::HeadlessResult> ra = Status::Error("not run"), rb = Status::Error("not run");
  std::thread ta([&] { ra = headless::RunHeadless(a); });
  std::thread tb([&] { rb = headless::RunHeadless(b); });
  ta.join();
  tb.join();
  ASSERT_TRUE(ra.ok()) << ra.error();
  ASSERT_TRUE(rb.ok()) << rb.error();
  EXPECT_EQ(ra->metrics.frames_processed, 20);
  EXPECT_EQ(rb->metrics.frames_processed, 20);
  EXPECT_GT(ra->counters.other_session_messages, 0);  // they did share the channels
  EXPECT_EQ(ReadFile(dir / "a" / "trajectory.tum"), ReadFile(dir / "a_alone" / "trajectory.tum"));
  EXPECT_EQ(ReadFile(dir / "b" / "trajectory.tum"), ReadFile(dir / "b_alone" / "trajectory.tum"));
  EXPECT_NE(ReadFile(dir / "a" / "trajectory.tum"), ReadFile(dir / "b" / "trajectory.tum"));
  EXPECT_EQ(server.Counters().sessions_started, 2);
  EXPECT_EQ(server.Counters().total_drops(), 0);
  server.Stop();
  fs::remove_all(dir);
}

TEST(LcmNetworkTest, ServerRestartMidSessionStartsANewSession) {
  REQUIRE_NETWORK();
  auto server =
      std::make_unique<server_app::LcmServer>(ServerOptions(), &testing::FakeSystem::Create);
  ASSERT_TRUE(server->Start().ok());
  const int64_t first_instance = server->server_instance();
  client::LcmTransport transport(kUrl);
  client::ClientSession session(&transport, {});
  ASSERT_TRUE(session.Start().ok());
  EXPECT_EQ(session.server_instance(), first_instance);
  auto send = [&](int k) {
    wire::FeatureFrame frame;
    frame.capture_time_us = k * 10000;
    frame.features = {{static_cast<VertexId>(k), {5.f, 5.f}}};
    frame.ground_truth_world_from_camera = Pose3();
    auto seq = session.Send(frame);
    return seq.ok() && session.WaitForPose(*seq, 1.0);
  };
  for (int k = 0; k < 10; ++k) EXPECT_TRUE(send(k));
  const int64_t first_session = session.session_id();
  server->Stop();
  server = std::make_unique<server_app::LcmServer>(ServerOptions(), &testing::FakeSystem::Create);
  ASSERT_TRUE(server->Start().ok());
  int answered_after = 0;
  for (int k = 10; k < 40; ++k) answered_after += send(k);
  const client::ClientCounters c = session.Counters();
  EXPECT_EQ(c.server_restarts + c.sessions_ended_by_server, 1);
  EXPECT_EQ(c.sessions_started, 2);
  EXPECT_NE(session.session_id(), first_session);
  EXPECT_EQ(session.server_instance(), server->server_instance());
  EXPECT_GE(answered_after, 25);  // tracking resumed in the new session
  session.End();
  server->Stop();
}

// Sends junk on every channel: random bytes, other types' fingerprints, and well-formed
// messages with bad contents. Returns how many messages each side must count as bad.
struct HostileCounts {
  int server = 0;  // on M2S_FRAME and M2S_SESSION
  int client = 0;  // undecodable on M2S_POSE, M2S_MAP, M2S_STATS, M2S_SESSION
};
HostileCounts RunHostile(lcm::LCM* lcm, std::atomic<bool>* stop, std::atomic<int>* rounds_done) {
  HostileCounts counts;
  std::mt19937 rng(11);
  const char* channels[] = {wire::kFrameChannel, wire::kSessionChannel, wire::kPoseChannel,
                            wire::kMapChannel, wire::kStatsChannel};
  auto publish = [&](const char* channel, const std::vector<uint8_t>& bytes, bool server_bad,
                     bool client_bad) {
    lcm->publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
    counts.server += server_bad;
    counts.client += client_bad;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  };
  for (int round = 0; round < 40 && !*stop; ++round) {
    for (const char* channel : channels) {
      const std::string c = channel;
      const bool to_server = c == wire::kFrameChannel || c == wire::kSessionChannel;
      const bool to_client = c != wire::kFrameChannel;
      std::vector<uint8_t> junk(1 + rng() % 200);
      for (auto& b : junk) b = static_cast<uint8_t>(rng());
      publish(channel, junk, to_server, to_client);
    }
    // Malformed frames: duplicated ids, out-of-image, NaN ground truth, negative id.
    wire::FeatureFrame f;
    f.session_id = 777;
    f.seq = round + 1;
    f.features = {{3, {10.f, 10.f}}, {3, {20.f, 20.f}}};
    publish(wire::kFrameChannel, wire::EncodeFeatureFrame(f), true, false);
    feature_frame_t m = wire::ToMessage(f);
    m.ids[1] = -2;
    publish(wire::kFrameChannel, wire::Encode(m), true, false);
    m.ids[1] = 4;
    m.v_q[0] = static_cast<int16_t>(480 * 64 + 5);
    publish(wire::kFrameChannel, wire::Encode(m), true, false);
    m = wire::ToMessage(f);
    m.ids[1] = 4;
    m.has_ground_truth = true;
    m.ground_truth_world_from_camera.t[1] = std::nan("");
    publish(wire::kFrameChannel, wire::Encode(m), true, false);
    // Malformed session messages: bad version, HELLO with a NaN camera, resync of nobody.
    session_control_t s{};
    s.version = 3;
    s.type = session_control_t::HELLO;
    s.camera = wire::ToMessage(Camera());
    publish(wire::kSessionChannel, wire::Encode(s), true, true);
    s.version = session_control_t::VERSION;
    s.camera.fy = std::nan("");
    publish(wire::kSessionChannel, wire::Encode(s), true, true);
    s.type = session_control_t::RESYNC_REQUEST;
    s.session_id = 999;
    publish(wire::kSessionChannel, wire::Encode(s), true, false);
    // A frame on the pose channel (wrong fingerprint there).
    publish(wire::kPoseChannel, wire::EncodeFeatureFrame(f), false, true);
    rounds_done->fetch_add(1);
  }
  return counts;
}

TEST(LcmNetworkTest, HostilePublisherIsCountedWhileARealClientKeepsTracking) {
  REQUIRE_NETWORK();
  const fs::path dir = TempDir("hostile");
  server_app::LcmServer server(ServerOptions());
  ASSERT_TRUE(server.Start().ok());
  lcm::LCM hostile_lcm(kUrl);
  ASSERT_TRUE(hostile_lcm.good());
  std::atomic<bool> stop{false};
  std::atomic<bool> session_up{false};
  std::atomic<int> rounds_done{0};
  HostileCounts counts;
  headless::HeadlessOptions options = ShortRun(dir, false);
  // The hostile publisher starts once the client's session is up (its first frame sent); the
  // client holds its 10th frame until a few hostile rounds went out, so they surely overlap
  // however fast either side runs.
  options.on_frame_sent = [&](int64_t k) {
    session_up = true;
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (k == 10 && rounds_done.load() < 3 && std::chrono::steady_clock::now() < give_up)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
  };
  std::thread hostile([&] {
    while (!session_up.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    counts = RunHostile(&hostile_lcm, &stop, &rounds_done);
  });
  auto result = headless::RunHeadless(options);
  session_up = true;  // the hostile thread must not wait forever when the run failed early
  hostile.join();
  EXPECT_GE(rounds_done.load(), 3);
  ASSERT_TRUE(result.ok()) << result.error();
  EXPECT_EQ(result->metrics.frames_processed, 20);
  EXPECT_GE(result->metrics.frames_tracked, 8);  // after initialisation (~1.2 s of 2 s)
  EXPECT_LT(result->metrics.ate_rmse, 0.05);
  // Every bad message is accounted for (loopback delivery is reliable at this rate).
  server_app::ServerCounters c = server.Counters();
  for (int i = 0; i < 100 && c.total_drops() < counts.server; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    c = server.Counters();
  }
  EXPECT_EQ(c.total_drops(), counts.server);
  EXPECT_GT(c.drops[static_cast<int>(wire::DropReason::kDuplicateId)], 0);
  EXPECT_GT(c.drops[static_cast<int>(wire::DropReason::kBadBytes)] +
                c.drops[static_cast<int>(wire::DropReason::kWrongFingerprint)],
            0);
  EXPECT_EQ(c.sessions_started, 1);
  // The client saw the junk sent while it ran (it stops before the publisher does) and
  // counted it without any effect on its session.
  EXPECT_GT(result->counters.bad_messages, 0);
  EXPECT_LE(result->counters.bad_messages, counts.client);
  server.Stop();
  fs::remove_all(dir);
}

TEST(LcmNetworkTest, ServerAndClientAsTwoProcessesOverUdpMulticast) {
  const fs::path bin = fs::path(M2S_BINARY_DIR) / "bin";
  const fs::path dir = TempDir("processes");
  const std::string script =
      "ip link set lo up && ip route add 224.0.0.0/4 dev lo && "
      "(" +
      (bin / "m2s_server").string() + " --lcm-url '" + kUrl + "' --stats-period 0 2> " +
      (dir / "server.log").string() + " & server=\\$!; sleep 0.5; " +
      (bin / "m2s_client").string() + " --lcm-url '" + kUrl +
      "' --fast --fps 10 --duration 1.5 --budget 2500 --projector cpu --no-map-png --out " +
      (dir / "out").string() + " > " + (dir / "client.log").string() +
      " 2>&1; rc=\\$?; kill -TERM \\$server; wait \\$server; exit \\$rc)";
  const std::string command = "unshare -n sh -c \"" + script + "\"";
  if (std::system("unshare -n true 2>/dev/null") != 0) {
    GTEST_SKIP() << "skipped: network namespaces not permitted here (unshare -n failed)";
  }
  ASSERT_EQ(std::system(command.c_str()), 0) << ReadFile(dir / "client.log");
  const nlohmann::json metrics = nlohmann::json::parse(ReadFile(dir / "out" / "metrics.json"));
  EXPECT_EQ(metrics["frames_total"].get<int>(), 16);
  EXPECT_EQ(metrics["frames_processed"].get<int>(), 16);
  EXPECT_EQ(metrics["transport"].get<std::string>(), "lcm");
  EXPECT_DOUBLE_EQ(metrics["bytes_per_feature"].get<double>(), 8.0);
  EXPECT_NE(ReadFile(dir / "server.log").find("SIGTERM"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace m2s
