// The server's session logic with a stand-in SLAM system: routing, per-reason drop counters,
// session lifecycle (bye, timeout, max sessions), resync and the latest-wins queue.
#include "m2s/server_app/session_manager.h"

#include <chrono>
#include <mutex>
#include <thread>

#include <gtest/gtest.h>

#include "fake_system.h"
#include "session_test_util.h"

namespace m2s::server_app {
namespace {

using wire::DropReason;

class SessionManagerTest : public ::testing::Test {
 protected:
  void Make(ServerOptions options) {
    manager_ = std::make_unique<SessionManager>(
        options, [this](const std::string& c, std::vector<uint8_t> b) { published_.Add(c, b); },
        &testing::FakeSystem::Create);
  }
  void Send(const std::string& channel, const std::vector<uint8_t>& bytes) {
    manager_->HandleMessage(channel, bytes.data(), bytes.size());
  }
  void SendFrame(const wire::FeatureFrame& f) {
    Send(wire::kFrameChannel, wire::EncodeFeatureFrame(f));
  }
  Published published_;
  std::unique_ptr<SessionManager> manager_;
};

TEST_F(SessionManagerTest, HelloThenFramesGivePosesAndDeltasInRevisionOrder) {
  Make(SyncOptions());
  Send(wire::kSessionChannel, Control(session_control_t::HELLO, 7));
  ASSERT_EQ(published_.control.size(), 1u);
  EXPECT_EQ(published_.control[0].type, +session_control_t::HELLO_ACK);
  EXPECT_EQ(published_.control[0].server_instance, manager_->server_instance());
  for (int seq = 1; seq <= 5; ++seq) SendFrame(Frame(7, seq));
  ASSERT_EQ(published_.poses.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(published_.poses[i].seq, i + 1);
    EXPECT_EQ(published_.poses[i].state, +pose_estimate_t::STATE_OK);
    EXPECT_DOUBLE_EQ(published_.poses[i].world_from_camera.t[0], i + 1);
  }
  ASSERT_EQ(published_.maps.size(), 5u);
  for (size_t i = 0; i < published_.maps.size(); ++i) {
    EXPECT_EQ(published_.maps[i].base_revision, static_cast<int64_t>(i));
    EXPECT_EQ(published_.maps[i].revision, static_cast<int64_t>(i + 1));
  }
  Send(wire::kSessionChannel, Control(session_control_t::RESYNC_REQUEST, 7));
  ASSERT_EQ(published_.maps.size(), 6u);
  EXPECT_TRUE(published_.maps.back().full);
  EXPECT_EQ(published_.maps.back().num_points, 5);
  const ServerCounters c = manager_->Counters();
  EXPECT_EQ(c.frames_in, 5);
  EXPECT_EQ(c.frames_processed, 5);
  EXPECT_EQ(c.total_drops(), 0);
}

TEST_F(SessionManagerTest, EveryBadMessageIsCountedUnderItsReason) {
  Make(SyncOptions());
  SendFrame(Frame(1, 5));
  std::vector<std::pair<DropReason, std::vector<uint8_t>>> bad;
  bad.push_back({DropReason::kBadBytes, {1, 2, 3}});
  bad.push_back({DropReason::kWrongFingerprint, Control(session_control_t::HELLO, 1)});
  feature_frame_t m = wire::ToMessage(Frame(1, 6));
  m.version = 9;
  bad.push_back({DropReason::kBadVersion, wire::Encode(m)});
  m = wire::ToMessage(Frame(1, 6));
  m.ids[1] = m.ids[0];
  bad.push_back({DropReason::kDuplicateId, wire::Encode(m)});
  m = wire::ToMessage(Frame(1, 6));
  m.ids[0] = -3;
  bad.push_back({DropReason::kNegativeId, wire::Encode(m)});
  m = wire::ToMessage(Frame(1, 6));
  m.u_q[0] = static_cast<int16_t>(640 * 64);
  bad.push_back({DropReason::kOutOfImage, wire::Encode(m)});
  m = wire::ToMessage(Frame(1, 6));
  m.ground_truth_world_from_camera.q[0] = std::nan("");
  bad.push_back({DropReason::kNonFinite, wire::Encode(m)});
  bad.push_back({DropReason::kSeqNotIncreasing, wire::EncodeFeatureFrame(Frame(1, 5))});
  bad.push_back({DropReason::kSeqNotIncreasing, wire::EncodeFeatureFrame(Frame(1, 4))});
  wire::FeatureFrame other_camera = Frame(1, 9);
  other_camera.camera.fx += 1;
  bad.push_back({DropReason::kCameraChanged, wire::EncodeFeatureFrame(other_camera)});
  for (const auto& [reason, bytes] : bad) Send(wire::kFrameChannel, bytes);
  // Session channel.
  Send(wire::kSessionChannel, wire::EncodeFeatureFrame(Frame(1, 10)));
  Send(wire::kSessionChannel, Control(99, 1));
  Send(wire::kSessionChannel, Control(session_control_t::RESYNC_REQUEST, 12345));
  const ServerCounters c = manager_->Counters();
  EXPECT_EQ(c.total_drops(), static_cast<int64_t>(bad.size()) + 3);
  for (const auto& [reason, bytes] : bad) {
    EXPECT_GE(c.drops[static_cast<int>(reason)], 1) << wire::ToString(reason);
  }
  EXPECT_EQ(c.drops[static_cast<int>(DropReason::kSeqNotIncreasing)], 2);
  EXPECT_EQ(c.drops[static_cast<int>(DropReason::kWrongFingerprint)], 2);
  EXPECT_EQ(c.drops[static_cast<int>(DropReason::kBadSessionMessage)], 1);
  EXPECT_EQ(c.drops[static_cast<int>(DropReason::kUnknownSession)], 1);
  EXPECT_EQ(c.frames_processed, 1);
  const server_stats_t stats = manager_->StatsMessage();
  EXPECT_EQ(stats.num_drop_reasons, wire::kNumDropReasons);
}

// A manual clock for session activity and timeouts.
TEST_F(SessionManagerTest, ByeMaxSessionsAndTimeout) {
  ServerOptions options = SyncOptions();
  options.session_timeout_s = 0.2;
  ManualClock clock;
  options.clock = [&clock] { return clock.now; };
  Make(options);
  SendFrame(Frame(1, 1));
  SendFrame(Frame(2, 1));
  SendFrame(Frame(3, 1));  // third session: refused
  EXPECT_EQ(manager_->Counters().drops[static_cast<int>(DropReason::kMaxSessions)], 1);
  Send(wire::kSessionChannel, Control(session_control_t::BYE, 1));
  SendFrame(Frame(1, 2));
  EXPECT_EQ(manager_->Counters().drops[static_cast<int>(DropReason::kEndedSession)], 1);
  SendFrame(Frame(3, 1));  // room again
  EXPECT_EQ(manager_->Counters().sessions_active, 2);
  clock.Advance(0.19);
  manager_->Tick();
  EXPECT_EQ(manager_->Counters().sessions_active, 2);
  clock.Advance(0.02);
  manager_->Tick();
  EXPECT_EQ(manager_->Counters().sessions_active, 0);
  EXPECT_EQ(manager_->Counters().sessions_ended, 3);
  int ended = 0, rejected = 0;
  for (const auto& m : published_.control) {
    ended += m.type == session_control_t::SESSION_ENDED;
    rejected += m.type == session_control_t::REJECTED;
  }
  EXPECT_EQ(ended, 3);
  EXPECT_EQ(rejected, 1);
}

TEST_F(SessionManagerTest, SequenceNumbersJumpOnlyWithinTheBound) {
  ServerOptions options = SyncOptions();
  options.max_seq_jump = 100;
  Make(options);
  SendFrame(Frame(1, 101));  // the first frame counts from 0
  EXPECT_EQ(manager_->Counters().drops[static_cast<int>(DropReason::kSeqJump)], 1);
  SendFrame(Frame(1, 1));
  SendFrame(Frame(1, INT64_MAX - 1));  // the frame that froze a session
  SendFrame(Frame(1, 102));
  EXPECT_EQ(manager_->Counters().drops[static_cast<int>(DropReason::kSeqJump)], 3);
  SendFrame(Frame(1, 2));    // the real client goes on
  SendFrame(Frame(1, 101));  // a jump of 99 (lost frames) is allowed
  const ServerCounters c = manager_->Counters();
  EXPECT_EQ(c.frames_processed, 3);
  EXPECT_EQ(c.drops[static_cast<int>(DropReason::kSeqNotIncreasing)], 0);
}

TEST_F(SessionManagerTest, RefusedFramesDoNotKeepASessionAlive) {
  ServerOptions options = SyncOptions();
  options.session_timeout_s = 1.0;
  ManualClock clock;
  options.clock = [&clock] { return clock.now; };
  Make(options);
  SendFrame(Frame(1, 5));
  for (int i = 0; i < 15; ++i) {  // 1.5 s of refused frames: replays and huge jumps
    clock.Advance(0.1);
    SendFrame(Frame(1, 5));
    SendFrame(Frame(1, INT64_MAX - 1));
    manager_->Tick();
  }
  EXPECT_EQ(manager_->Counters().sessions_active, 0);
  EXPECT_EQ(manager_->Counters().sessions_ended, 1);
}

TEST_F(SessionManagerTest, ASessionBelongsToTheSenderThatOpenedIt) {
  Make(SyncOptions());
  constexpr uint64_t kOwner = 17, kStranger = 99;
  auto send = [&](const std::string& channel, const std::vector<uint8_t>& b, uint64_t sender) {
    manager_->HandleMessage(channel, b.data(), b.size(), sender);
  };
  send(wire::kSessionChannel, Control(session_control_t::HELLO, 1), kOwner);
  send(wire::kFrameChannel, wire::EncodeFeatureFrame(Frame(1, 1)), kOwner);
  // A stranger's frame, reset, resync, bye and HELLO for the same session id change nothing.
  send(wire::kFrameChannel, wire::EncodeFeatureFrame(Frame(1, 2)), kStranger);
  for (int8_t type : {session_control_t::RESET, session_control_t::RESYNC_REQUEST,
                      session_control_t::BYE, session_control_t::HELLO}) {
    send(wire::kSessionChannel, Control(type, 1), kStranger);
  }
  EXPECT_EQ(manager_->Counters().drops[static_cast<int>(DropReason::kSpoofedSession)], 5);
  EXPECT_EQ(manager_->Counters().sessions_active, 1);
  send(wire::kFrameChannel, wire::EncodeFeatureFrame(Frame(1, 2)), kOwner);
  EXPECT_EQ(manager_->Counters().frames_processed, 2);
  send(wire::kSessionChannel, Control(session_control_t::BYE, 1), kOwner);
  EXPECT_EQ(manager_->Counters().sessions_active, 0);
  int acks = 0;
  for (const auto& m : published_.control) acks += m.type == session_control_t::HELLO_ACK;
  EXPECT_EQ(acks, 1);  // the stranger's HELLO got no acknowledgement
}

TEST_F(SessionManagerTest, WorkerModeTracksEveryFrameWhenPacedAndShutsDownCleanly) {
  ServerOptions options;
  options.queue_capacity = 1;
  Make(options);
  for (int seq = 1; seq <= 50; ++seq) {
    SendFrame(Frame(4, seq));
    manager_->Drain();
  }
  EXPECT_EQ(manager_->Counters().frames_processed, 50);
  EXPECT_EQ(manager_->Counters().frames_skipped, 0);
  // Unpaced: the latest-wins queue skips; every frame is processed or skipped.
  for (int seq = 51; seq <= 2050; ++seq) SendFrame(Frame(4, seq));
  manager_->Drain();
  const ServerCounters c = manager_->Counters();
  EXPECT_EQ(c.frames_processed + c.frames_skipped, 2050);
  manager_->Shutdown();
  manager_->Shutdown();
  EXPECT_EQ(manager_->Counters().sessions_active, 0);
}

}  // namespace
}  // namespace m2s::server_app
