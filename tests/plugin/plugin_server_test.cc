// A plug-in behind the server's session logic (server_app::SessionManager, as m2s_server and
// the on-device client run it): poses reach the client, and a HELLO naming a map group is
// REJECTED with the reason.
#include <string>

#include <gtest/gtest.h>

#include "m2s/plugin/plugin_system.h"
#include "m2s/server_app/messages.h"
#include "session_test_util.h"

namespace m2s::server_app {
namespace {

const std::string kFaulty =
    std::string(M2S_BINARY_DIR) + "/test_plugins/" + plugin::PluginFileName("faulty");

std::vector<uint8_t> Hello(int64_t session, const std::string& group) {
  session_control_t m = MakeSessionMessage(session_control_t::HELLO, session, 0);
  m.camera = wire::ToMessage(Camera());
  m.map_group = group;
  return wire::Encode(m);
}

TEST(PluginServer, ServesAPluginAndRefusesMapGroups) {
  auto method = plugin::LoadMethod(kFaulty, "");
  ASSERT_TRUE(method.ok()) << method.error();
  Published published;
  SessionManager manager(
      SyncOptions(), [&](const std::string& c, std::vector<uint8_t> b) { published.Add(c, b); },
      method->system, method->group);
  auto send = [&](const std::string& channel, const std::vector<uint8_t>& bytes) {
    manager.HandleMessage(channel, bytes.data(), bytes.size());
  };

  send(wire::kSessionChannel, Hello(1, "room"));
  ASSERT_EQ(published.control.size(), 1u);
  EXPECT_EQ(published.control[0].type, +session_control_t::REJECTED);
  EXPECT_EQ(published.control[0].reason,
            "map group room not created: map groups need the built-in SLAM (vertex_slam); this "
            "server runs plug-in faulty");

  send(wire::kSessionChannel, Hello(2, ""));
  ASSERT_EQ(published.control.size(), 2u);
  EXPECT_EQ(published.control[1].type, +session_control_t::HELLO_ACK);
  // The faulty plug-in: seq 2 a NaN pose (lost), seq 3 at x = 3 (tracked).
  send(wire::kFrameChannel, wire::EncodeFeatureFrame(Frame(2, 2)));
  send(wire::kFrameChannel, wire::EncodeFeatureFrame(Frame(2, 3)));
  manager.Drain();
  ASSERT_EQ(published.poses.size(), 2u);
  EXPECT_EQ(published.poses[0].seq, 2);
  EXPECT_EQ(published.poses[0].state, static_cast<int8_t>(slam::TrackingState::kLost));
  EXPECT_EQ(published.poses[1].seq, 3);
  EXPECT_EQ(published.poses[1].state, static_cast<int8_t>(slam::TrackingState::kOk));
  manager.Shutdown();
}

}  // namespace
}  // namespace m2s::server_app
