// A server that vanishes mid-session without a word, seen by a client over LCM (private network
// namespace, see lcm_test_bus.h): the client notices only by the wall-clock timeout of its
// unanswered frames, so this runs in real time (ctest label `realtime`). The clean restart,
// announced by SESSION_ENDED, is in lcm_network_test.cc.
#include <gtest/gtest.h>

#include "fake_system.h"
#include "lcm_test_bus.h"
#include "m2s/client/client_session.h"
#include "m2s/server_app/lcm_server.h"

namespace m2s {
namespace {

TEST(LcmNetworkRealtimeTest, AServerThatVanishedIsNoticedAndANewSessionStarted) {
  M2S_REQUIRE_NETWORK();
  auto server = std::make_unique<server_app::LcmServer>(testing::TestServerOptions(),
                                                        &testing::FakeSystem::Create);
  ASSERT_TRUE(server->Start().ok());
  // The stopping server's SESSION_ENDED never reaches the session: as if it had crashed.
  testing::SessionEndTransport transport(testing::kTestLcmUrl, /*drop_session_ends=*/true);
  // The session is given up after 0.5 s without an answer; each send below waits 1 s for its
  // pose: whatever the scheduling, the first frame after the restart (sent in the old
  // session, which the new server does not own) is the only one not answered.
  client::ClientSessionOptions options;
  options.unanswered_timeout_s = 0.5;
  constexpr double kPoseWaitS = 1.0;
  client::ClientSession session(&transport, options);
  ASSERT_TRUE(session.Start().ok());
  EXPECT_EQ(session.server_instance(), server->server_instance());
  auto send = [&](int k) {
    wire::FeatureFrame frame;
    frame.capture_time_us = k * 10000;
    frame.features = {{static_cast<VertexId>(k), {5.f, 5.f}}};
    frame.ground_truth_world_from_camera = Pose3();
    auto seq = session.Send(frame);
    return seq.ok() && session.WaitForPose(*seq, kPoseWaitS);
  };
  for (int k = 0; k < 10; ++k) EXPECT_TRUE(send(k)) << k;
  const int64_t first_session = session.session_id();
  server->Stop();
  ASSERT_TRUE(transport.session_ends.WaitAtLeast(1));  // sent, and dropped
  server = std::make_unique<server_app::LcmServer>(testing::TestServerOptions(),
                                                   &testing::FakeSystem::Create);
  ASSERT_TRUE(server->Start().ok());
  constexpr int kFramesAfter = 30;
  int answered_after = 0;
  for (int k = 10; k < 10 + kFramesAfter; ++k) answered_after += send(k);
  EXPECT_EQ(answered_after, kFramesAfter - 1);
  const client::ClientCounters c = session.Counters();
  EXPECT_EQ(c.server_restarts, 1);
  EXPECT_EQ(c.sessions_ended_by_server, 0);
  EXPECT_EQ(c.sessions_started, 2);
  EXPECT_GE(c.foreign_server_messages, 1);  // the new server's answer to the old session
  EXPECT_NE(session.session_id(), first_session);
  EXPECT_EQ(session.server_instance(), server->server_instance());
  session.End();
  server->Stop();
}

}  // namespace
}  // namespace m2s
