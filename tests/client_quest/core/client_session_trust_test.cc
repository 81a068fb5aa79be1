// Whom the client session believes: only the server instance that acknowledged the session.
// The test plays the server through a scripted transport and injects what a stray publisher
// on the bus would send: poses, SESSION_ENDED and REJECTED from another instance.
#include <chrono>
#include <mutex>

#include <gtest/gtest.h>

#include "m2s/client/client_session.h"
#include "m2s/server_app/messages.h"

namespace m2s::client {
namespace {

constexpr int64_t kServer = 1000;
constexpr int64_t kStranger = 2000;

// Acknowledges every HELLO as server kServer and keeps what the client published.
class ScriptedTransport final : public Transport {
 public:
  Status Start(MessageHandler handler) override {
    handler_ = std::move(handler);
    return Status::Ok();
  }
  Status Publish(const std::string& channel, const std::vector<uint8_t>& bytes) override {
    std::optional<session_control_t> hello;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (channel == wire::kFrameChannel) {
        frames.push_back(*wire::DecodeFeatureFrame(bytes.data(), bytes.size(), {}));
      } else if (channel == wire::kSessionChannel) {
        auto m = wire::DecodeSessionControl(bytes.data(), bytes.size());
        if (m->type == session_control_t::HELLO) {
          ++hellos;
          map_group = m->map_group;
          if (hellos > lost_hellos) hello = *m;
        }
      }
    }
    if (hello) {
      Deliver(wire::kSessionChannel,
              wire::Encode(server_app::MakeSessionMessage(session_control_t::HELLO_ACK,
                                                          hello->session_id, kServer)));
    }
    return Status::Ok();
  }
  void Stop() override {}
  std::string_view name() const override { return "scripted"; }

  void Deliver(const std::string& channel, const std::vector<uint8_t>& bytes) {
    handler_(channel, bytes.data(), bytes.size());
  }
  void Pose(int64_t instance, int64_t session, int64_t seq) {
    pose_estimate_t p{};
    p.version = pose_estimate_t::VERSION;
    p.session_id = session;
    p.server_instance = instance;
    p.seq = seq;
    p.frame_send_wall_us = 0;  // a forger's echo must not decide the latency
    p.state = pose_estimate_t::STATE_OK;
    p.world_from_camera = wire::ToMessage(Pose3());
    Deliver(wire::kPoseChannel, wire::Encode(p));
  }
  void Control(int8_t type, int64_t instance, int64_t session) {
    Deliver(wire::kSessionChannel,
            wire::Encode(server_app::MakeSessionMessage(type, session, instance)));
  }

  std::mutex mutex_;
  std::vector<wire::FeatureFrame> frames;
  int hellos = 0;
  int lost_hellos = 0;    // the first HELLOs are not answered (lost, or another shard's)
  std::string map_group;  // of the last HELLO

 private:
  MessageHandler handler_;
};

wire::FeatureFrame Frame(int k) {
  wire::FeatureFrame frame;
  frame.capture_time_us = k * 10000;
  frame.features = {{static_cast<VertexId>(k), {5.f, 5.f}}};
  return frame;
}

TEST(ClientSessionTrustTest, MessagesFromAnotherInstanceChangeNothing) {
  ScriptedTransport transport;
  ClientSession session(&transport, {});
  ASSERT_TRUE(session.Start().ok());
  ASSERT_EQ(session.server_instance(), kServer);
  const int64_t id = session.session_id();
  const auto sent = std::chrono::steady_clock::now();
  ASSERT_TRUE(session.Send(Frame(0)).ok());
  transport.Pose(kStranger, id, 1);                                    // forged pose
  transport.Control(session_control_t::SESSION_ENDED, kStranger, id);  // forged end
  transport.Control(session_control_t::REJECTED, kServer, id);         // a refusal after the ack
  EXPECT_FALSE(session.Records()[0].answered);
  ASSERT_TRUE(session.Send(Frame(1)).ok());
  EXPECT_EQ(session.session_id(), id);  // the session goes on
  transport.Pose(kServer, id, 1);
  const double elapsed_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - sent).count();
  transport.Pose(kServer, id, 2);
  const auto records = session.Records();
  ASSERT_TRUE(records[0].answered && records[1].answered);
  // Latency on this client's steady clock: no longer than the interval the test measured
  // around Send and the pose (plus 1 us: whole-microsecond stamps), so not taken from the
  // forger's echoed 1970 stamp.
  EXPECT_LE(records[0].latency_ms, elapsed_ms + 1e-3);
  const ClientCounters c = session.Counters();
  EXPECT_EQ(c.foreign_server_messages, 2);
  EXPECT_EQ(c.sessions_started, 1);
  EXPECT_EQ(c.sessions_ended_by_server, 0);
  EXPECT_EQ(c.rejected, 0);
  EXPECT_EQ(c.poses_received, 2);
}

TEST(ClientSessionTrustTest, SequenceNumbersRestartInEverySession) {
  ScriptedTransport transport;
  ClientSession session(&transport, {});
  ASSERT_TRUE(session.Start().ok());
  const int64_t first = session.session_id();
  ASSERT_TRUE(session.Send(Frame(0)).ok());
  ASSERT_TRUE(session.Send(Frame(1)).ok());
  transport.Control(session_control_t::SESSION_ENDED, kServer, first);  // by its owner
  auto third = session.Send(Frame(2));
  ASSERT_TRUE(third.ok());
  EXPECT_EQ(*third, 3);  // client-wide record number
  const int64_t second = session.session_id();
  EXPECT_NE(second, first);
  ASSERT_EQ(transport.frames.size(), 3u);
  EXPECT_EQ(transport.frames[1].seq, 2);
  EXPECT_EQ(transport.frames[2].seq, 1);  // what the new session's server sees
  EXPECT_EQ(transport.frames[2].session_id, second);
  transport.Pose(kServer, second, 1);
  const auto records = session.Records();
  EXPECT_TRUE(records[2].answered);
  EXPECT_FALSE(records[0].answered);
  EXPECT_EQ(records[2].wire_seq, 1);
  EXPECT_EQ(session.Counters().sessions_ended_by_server, 1);
}

TEST(ClientSessionTrustTest, ASessionTheServerStopsAnsweringIsRenewed) {
  ScriptedTransport transport;
  ClientSessionOptions options;
  options.unanswered_timeout_s = 0.05;
  double now_s = 100.0;
  options.clock_s = [&now_s] { return now_s; };
  ClientSession session(&transport, options);
  ASSERT_TRUE(session.Start().ok());
  const int64_t first = session.session_id();
  ASSERT_TRUE(session.Send(Frame(0)).ok());
  transport.Pose(kServer, first, 1);
  ASSERT_TRUE(session.Send(Frame(1)).ok());  // never answered
  now_s += 0.049;                            // just inside the timeout: the session goes on
  ASSERT_TRUE(session.Send(Frame(2)).ok());
  EXPECT_EQ(session.session_id(), first);
  now_s += 0.002;  // past it
  ASSERT_TRUE(session.Send(Frame(3)).ok());
  EXPECT_NE(session.session_id(), first);
  EXPECT_EQ(transport.hellos, 2);
  const ClientCounters c = session.Counters();
  EXPECT_EQ(c.server_restarts, 1);
  EXPECT_EQ(c.sessions_started, 2);
}

// A sharded server opens a session only from its HELLO: the client repeats it every
// hello_resend_s (on its clock) until acknowledged or refused, with the map group.
TEST(ClientSessionTrustTest, HelloIsRepeatedUntilAnsweredAndNamesTheMapGroup) {
  ScriptedTransport transport;
  transport.lost_hellos = 2;
  ClientSessionOptions options;
  options.map_group = "room-a";
  options.hello_timeout_s = 0.0;  // Start() does not wait
  options.hello_resend_s = 0.25;
  double now_s = 100.0;
  options.clock_s = [&now_s] { return now_s; };
  ClientSession session(&transport, options);
  ASSERT_TRUE(session.Start().ok());
  EXPECT_EQ(transport.hellos, 1);
  ASSERT_TRUE(session.Send(Frame(0)).ok());  // not due yet
  EXPECT_EQ(transport.hellos, 1);
  now_s += 0.25;
  ASSERT_TRUE(session.Send(Frame(1)).ok());  // repeated, lost again
  EXPECT_EQ(transport.hellos, 2);
  EXPECT_EQ(session.server_instance(), 0);
  now_s += 0.25;
  ASSERT_TRUE(session.Send(Frame(2)).ok());  // repeated, acknowledged
  EXPECT_EQ(transport.hellos, 3);
  EXPECT_EQ(session.server_instance(), kServer);
  now_s += 1.0;
  ASSERT_TRUE(session.Send(Frame(3)).ok());  // no repeats once acknowledged
  EXPECT_EQ(transport.hellos, 3);
  EXPECT_EQ(transport.map_group, "room-a");
  // The frames before the acknowledgement were held back (a group session's frames must not
  // reach a server before its HELLO).
  ASSERT_EQ(transport.frames.size(), 2u);
  EXPECT_EQ(transport.frames[0].seq, 3);
  EXPECT_FALSE(session.Records()[0].answered);
  const ClientCounters c = session.Counters();
  EXPECT_EQ(c.frames_held, 2);
  EXPECT_EQ(c.hellos_sent, 3);
  EXPECT_EQ(c.servers_seen, 1);
  EXPECT_EQ(c.sessions_started, 1);

  // A refusal stops the repeats too.
  ScriptedTransport refusing;
  refusing.lost_hellos = 100;
  ClientSession refused(&refusing, options);
  ASSERT_TRUE(refused.Start().ok());
  refusing.Control(session_control_t::REJECTED, kServer, refused.session_id());
  now_s += 1.0;
  ASSERT_TRUE(refused.Send(Frame(0)).ok());
  EXPECT_EQ(refusing.hellos, 1);
  EXPECT_EQ(refused.Counters().rejected, 1);

  ClientSessionOptions bad = options;
  bad.map_group = "room a";
  ScriptedTransport unused;
  EXPECT_EQ(ClientSession(&unused, bad).Start().reason(), DropReason::kBadGroupName);
}

}  // namespace
}  // namespace m2s::client
