// Client and server over LCM UDP multicast on the loopback of a private network namespace
// (this test process enters its own with unshare(CLONE_NEWNET); the two-process test starts
// the real executables in another one). Skipped, with one line, where namespaces are not
// permitted. A server that vanishes without ending its sessions is noticed by a wall-clock
// timeout: that case is in lcm_network_realtime_test.cc.
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "fake_system.h"
#include "lcm_test_bus.h"
#include "m2s/client/client_session.h"
#include "m2s/headless/headless_run.h"
#include "m2s/server_app/lcm_server.h"
#include "server_script.h"
#include "test_files.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;
constexpr const char* kUrl = testing::kTestLcmUrl;
using Count = testing::WaitableCount;
using testing::kGiveUp;

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
  o.send_budget = 2500;
  o.render_map = false;
  o.out_dir = out.string();
  return o;
}

server_app::LcmServerOptions ServerOptions() { return testing::TestServerOptions(); }

// Total drops in the server's periodic M2S_STATS messages: waits for them (each wake-up is a
// message) until one counts at least `expected`, or kGiveUp passed; returns the last total
// seen (-1: no statistics at all).
int64_t WaitForServerStatsDrops(int64_t expected) {
  struct Watcher {
    int64_t drops = -1;
    void OnRaw(const lcm::ReceiveBuffer* buffer, const std::string&) {
      auto stats = wire::DecodeServerStats(buffer->data, buffer->data_size);
      if (!stats) return;
      int64_t total = 0;
      for (int64_t n : stats->drop_counts) total += n;
      drops = total;
    }
  } watcher;
  lcm::LCM lcm(kUrl);
  if (!lcm.good()) return -1;
  lcm.subscribe(wire::kStatsChannel, &Watcher::OnRaw, &watcher);
  const auto deadline = std::chrono::steady_clock::now() + kGiveUp;
  while (watcher.drops < expected) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0 || lcm.handleTimeout(static_cast<int>(left.count())) < 0) break;
  }
  return watcher.drops;
}

TEST(LcmNetworkTest, TwoClientsAtOnceGetTheResultsTheyGetAlone) {
  M2S_REQUIRE_NETWORK();
  const fs::path dir = TempDir("two");
  // Alone, on-device (deterministic): the references.
  headless::HeadlessOptions a = ShortRun(dir / "a_alone", true);
  headless::HeadlessOptions b = ShortRun(dir / "b_alone", true);
  b.noise.pixel_noise_sigma = 0.3;
  b.noise.seed = 5;
  ASSERT_TRUE(headless::RunHeadless(a).ok());
  ASSERT_TRUE(headless::RunHeadless(b).ok());
  // Together on one LCM server. The two runs meet twice: once both sent frame 0 (both are
  // subscribed before either sends frame 1), and once both received the pose of frame 1 (the
  // other's socket got that datagram at the same moment, ahead of the pose of its own frame
  // 3): each then surely counts a message of the other's session, however the threads run.
  server_app::LcmServer server(ServerOptions());
  ASSERT_TRUE(server.Start().ok());
  a.on_device = b.on_device = false;
  a.out_dir = (dir / "a").string();
  b.out_dir = (dir / "b").string();
  Count reached_frame_0, reached_frame_2;
  bool met[2] = {true, true};
  auto meet = [&](int run) {
    return [&, run](int64_t k) {
      if (k != 0 && k != 2) return;
      Count& reached = k == 0 ? reached_frame_0 : reached_frame_2;
      reached.Add();
      met[run] = reached.WaitAtLeast(2) && met[run];
    };
  };
  a.on_frame_sent = meet(0);
  b.on_frame_sent = meet(1);
  Expected<headless::HeadlessResult> ra = Status::Error("not run"), rb = Status::Error("not run");
  std::thread ta([&] { ra = headless::RunHeadless(a); });
  std::thread tb([&] { rb = headless::RunHeadless(b); });
  ta.join();
  tb.join();
  ASSERT_TRUE(ra.ok()) << ra.error();
  ASSERT_TRUE(rb.ok()) << rb.error();
  EXPECT_TRUE(met[0] && met[1]) << "the runs did not meet";
  EXPECT_EQ(ra->metrics.frames_processed, 20);
  EXPECT_EQ(rb->metrics.frames_processed, 20);
  EXPECT_GT(ra->counters.other_session_messages, 0);  // they did share the channels
  EXPECT_GT(rb->counters.other_session_messages, 0);
  EXPECT_EQ(ReadFile(dir / "a" / "trajectory.tum"), ReadFile(dir / "a_alone" / "trajectory.tum"));
  EXPECT_EQ(ReadFile(dir / "b" / "trajectory.tum"), ReadFile(dir / "b_alone" / "trajectory.tum"));
  EXPECT_NE(ReadFile(dir / "a" / "trajectory.tum"), ReadFile(dir / "b" / "trajectory.tum"));
  EXPECT_EQ(server.Counters().sessions_started, 2);
  EXPECT_EQ(server.Counters().total_drops(), 0);
  server.Stop();
  fs::remove_all(dir);
}

TEST(LcmNetworkTest, ServerRestartMidSessionStartsANewSession) {
  M2S_REQUIRE_NETWORK();
  auto server =
      std::make_unique<server_app::LcmServer>(ServerOptions(), &testing::FakeSystem::Create);
  ASSERT_TRUE(server->Start().ok());
  testing::SessionEndTransport transport(kUrl, /*drop_session_ends=*/false);
  client::ClientSession session(&transport, {});
  ASSERT_TRUE(session.Start().ok());
  EXPECT_EQ(session.server_instance(), server->server_instance());
  auto send = [&](int k) {
    wire::FeatureFrame frame;
    frame.capture_time_us = k * 10000;
    frame.features = {{static_cast<VertexId>(k), {5.f, 5.f}}};
    frame.ground_truth_world_from_camera = Pose3();
    auto seq = session.Send(frame);
    return seq.ok() && session.WaitForPose(*seq, 10.0);
  };
  for (int k = 0; k < 10; ++k) EXPECT_TRUE(send(k)) << k;
  const int64_t first_session = session.session_id();
  // A stopping server ends its sessions (SESSION_ENDED); once the client has handled that, it
  // starts a new session with its next frame, which the restarted server answers.
  server->Stop();
  ASSERT_TRUE(transport.session_ends.WaitAtLeast(1));
  server = std::make_unique<server_app::LcmServer>(ServerOptions(), &testing::FakeSystem::Create);
  ASSERT_TRUE(server->Start().ok());
  for (int k = 10; k < 40; ++k) EXPECT_TRUE(send(k)) << k;
  const client::ClientCounters c = session.Counters();
  EXPECT_EQ(c.sessions_ended_by_server, 1);
  EXPECT_EQ(c.server_restarts, 0);
  EXPECT_EQ(c.sessions_started, 2);
  EXPECT_EQ(c.poses_received, 40);
  EXPECT_NE(session.session_id(), first_session);
  EXPECT_EQ(session.server_instance(), server->server_instance());
  session.End();
  server->Stop();
}

// Two servers on one bus, shards 0/2 and 1/2, and six clients, three of them in map groups
// (two share one): every client is acknowledged and answered by exactly one server, a group's
// clients by the same one, and nothing is dropped.
TEST(LcmNetworkTest, ShardedServersAnswerEveryClientExactlyOnce) {
  M2S_REQUIRE_NETWORK();
  const server_app::MapGroupFactory group_factory =
      [](const slam::Options& o) -> Expected<std::shared_ptr<slam::MapGroup>> {
    return std::shared_ptr<slam::MapGroup>(std::make_shared<testing::FakeMapGroup>(o));
  };
  std::vector<std::unique_ptr<server_app::LcmServer>> servers;
  for (int k = 0; k < 2; ++k) {
    server_app::LcmServerOptions options = ServerOptions();
    options.server.shard = {k, 2};
    servers.push_back(std::make_unique<server_app::LcmServer>(options, &testing::FakeSystem::Create,
                                                              group_factory));
    ASSERT_TRUE(servers.back()->Start().ok());
  }
  constexpr int kClients = 6, kFrames = 5;
  std::vector<std::unique_ptr<client::LcmTransport>> transports;
  std::vector<std::unique_ptr<client::ClientSession>> sessions;
  for (int i = 0; i < kClients; ++i) {
    transports.push_back(std::make_unique<client::LcmTransport>(kUrl));
    client::ClientSessionOptions options;
    options.session_seed = 1000 + i;
    options.map_group = i % 2 == 0 ? "" : (i < 5 ? "room-a" : "room-b");
    sessions.push_back(std::make_unique<client::ClientSession>(transports.back().get(), options));
    ASSERT_TRUE(sessions.back()->Start().ok());
  }
  for (int k = 0; k < kFrames; ++k) {
    for (auto& session : sessions) {
      wire::FeatureFrame frame;
      frame.capture_time_us = k * 10000;
      frame.features = {{static_cast<VertexId>(k), {5.f, 5.f}}};
      auto seq = session->Send(frame);
      ASSERT_TRUE(seq.ok());
      EXPECT_TRUE(session->WaitForPose(*seq, 10.0)) << k;
    }
  }
  for (auto& session : sessions) {
    const client::ClientCounters c = session->Counters();
    EXPECT_EQ(c.servers_seen, 1);
    EXPECT_EQ(c.sessions_started, 1);
    EXPECT_EQ(c.poses_received, kFrames);
    EXPECT_EQ(c.foreign_server_messages, 0);
  }
  EXPECT_EQ(sessions[1]->server_instance(), sessions[3]->server_instance());  // room-a
  for (auto& session : sessions) session->End();
  int64_t started = 0;
  for (auto& server : servers) {
    server->Stop();
    const server_app::ServerCounters c = server->Counters();
    started += c.sessions_started;
    EXPECT_EQ(c.total_drops(), 0);
    EXPECT_GE(c.other_shard_hellos, 1);  // each server saw the other's HELLOs
  }
  EXPECT_EQ(started, kClients);
}

// Sends junk on every channel: random bytes, other types' fingerprints, and well-formed
// messages with bad contents. Returns how many messages each side must count as bad.
struct HostileCounts {
  int server = 0;  // on M2S_FRAME and M2S_SESSION
  int client = 0;  // undecodable on M2S_POSE, M2S_MAP, M2S_STATS, M2S_SESSION
};
HostileCounts RunHostile(lcm::LCM* lcm, Count* rounds_done) {
  HostileCounts counts;
  std::mt19937 rng(11);
  const char* channels[] = {wire::kFrameChannel, wire::kSessionChannel, wire::kPoseChannel,
                            wire::kMapChannel, wire::kStatsChannel};
  auto publish = [&](const char* channel, const std::vector<uint8_t>& bytes, bool server_bad,
                     bool client_bad) {
    lcm->publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
    counts.server += server_bad;
    counts.client += client_bad;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));  // paces the publisher
  };
  for (int round = 0; round < 40; ++round) {
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
    rounds_done->Add();
  }
  return counts;
}

TEST(LcmNetworkTest, HostilePublisherIsCountedWhileARealClientKeepsTracking) {
  M2S_REQUIRE_NETWORK();
  const fs::path dir = TempDir("hostile");
  // The undisturbed run (on-device, deterministic): what the client must still get.
  auto alone = headless::RunHeadless(ShortRun(dir / "alone", true));
  ASSERT_TRUE(alone.ok()) << alone.error();
  server_app::LcmServer server(ServerOptions());
  ASSERT_TRUE(server.Start().ok());
  lcm::LCM hostile_lcm(kUrl);
  ASSERT_TRUE(hostile_lcm.good());
  Count frames_sent, rounds_done;
  bool overlapped = false;
  HostileCounts counts;
  headless::HeadlessOptions options = ShortRun(dir / "attacked", false);
  // The hostile publisher starts once the client's session is up (its first frame sent); the
  // client holds its 10th frame until three hostile rounds went out, so they surely overlap
  // however fast either side runs.
  options.on_frame_sent = [&](int64_t k) {
    frames_sent.Add();
    if (k == 10) overlapped = rounds_done.WaitAtLeast(3);
  };
  std::thread hostile([&] {
    if (frames_sent.WaitAtLeast(1)) counts = RunHostile(&hostile_lcm, &rounds_done);
  });
  auto result = headless::RunHeadless(options);
  frames_sent.Add();  // the hostile thread must not wait when the run failed early
  hostile.join();
  EXPECT_TRUE(overlapped);
  ASSERT_TRUE(result.ok()) << result.error();
  EXPECT_EQ(result->metrics.frames_processed, 20);
  // Tracking went on untouched: the same poses as the undisturbed run.
  EXPECT_EQ(result->metrics.frames_tracked, alone->metrics.frames_tracked);
  EXPECT_EQ(ReadFile(dir / "attacked" / "trajectory.tum"),
            ReadFile(dir / "alone" / "trajectory.tum"));
  // Every bad message is accounted for (loopback delivery is reliable at this rate): the
  // server's statistics say when it has counted them all.
  EXPECT_EQ(WaitForServerStatsDrops(counts.server), counts.server);
  const server_app::ServerCounters c = server.Counters();
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
  if (std::system("unshare -n true 2>/dev/null") != 0) {
    GTEST_SKIP() << "skipped: network namespaces not permitted here (unshare -n failed)";
  }
  const fs::path bin = fs::path(M2S_BINARY_DIR) / "bin";
  const fs::path dir = TempDir("processes");
  std::ofstream(dir / "run.sh")
      << "ip link set lo up && ip route add 224.0.0.0/4 dev lo || exit 90\n"
      << testing::StartServerLines(
             (bin / "m2s_server").string() + " --lcm-url '" + kUrl + "' --stats-period 0", dir)
      << (bin / "m2s_client").string() << " --lcm-url '" << kUrl
      << "' --fast --fps 10 --duration 1.5 --budget 2500 --projector cpu --no-map-png --out "
      << (dir / "out").string() << " > " << (dir / "client.log").string() << " 2>&1\n"
      << "rc=$?\n"
      << testing::StopServerLines() << "exit $rc\n";
  const std::string command = "unshare -n sh " + (dir / "run.sh").string();
  ASSERT_EQ(std::system(command.c_str()), 0)
      << ReadFile(dir / "client.log") << ReadFile(dir / "server.log");
  const nlohmann::json metrics = nlohmann::json::parse(ReadFile(dir / "out" / "metrics.json"));
  EXPECT_EQ(metrics["frames_total"].get<int>(), 16);  // 1.5 s at 10 fps, both ends included
  EXPECT_EQ(metrics["frames_processed"].get<int>(), 16);
  EXPECT_EQ(metrics["transport"].get<std::string>(), "lcm");
  EXPECT_DOUBLE_EQ(metrics["bytes_per_feature"].get<double>(), 8.0);
  EXPECT_NE(ReadFile(dir / "server.log").find("SIGTERM"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace m2s
