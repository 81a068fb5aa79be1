// The server's map groups and shards, with stand-in SLAM (fake_system.h): sessions naming a
// group are agents of one group object, frames stay within their group, a camera other than
// the group's is refused, groups outlive their sessions and are bounded, group maps are saved
// and loaded, two sharded servers on one bus serve every session exactly once, and the stats
// JSON holds all of it.
#include <filesystem>
#include <map>
#include <memory>
#include <set>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "fake_system.h"
#include "m2s/server_app/messages.h"
#include "m2s/server_app/session_manager.h"
#include "session_test_util.h"

namespace m2s::server_app {
namespace {

using testing::FakeMapGroup;
using wire::DropReason;

std::vector<uint8_t> Hello(int64_t session, const std::string& group,
                           const Camera& camera = Camera()) {
  session_control_t m = MakeSessionMessage(session_control_t::HELLO, session, 0);
  m.camera = wire::ToMessage(camera);
  m.map_group = group;
  return wire::Encode(m);
}

// A frame whose capture time names its session: session * 1000 + seq (milliseconds).
wire::FeatureFrame GroupFrame(int64_t session, int64_t seq) {
  wire::FeatureFrame f = Frame(session, seq);
  f.capture_time_us = (session * 1000 + seq) * 1000;
  return f;
}

int64_t SessionOf(double timestamp) { return std::llround(timestamp * 1000) / 1000; }

// A manager whose map groups are FakeMapGroups, kept by name for inspection.
class Server {
 public:
  explicit Server(ServerOptions options) {
    manager_ = std::make_unique<SessionManager>(
        options, [this](const std::string& c, std::vector<uint8_t> b) { published.Add(c, b); },
        &testing::FakeSystem::Create,
        [this](const slam::Options& o) -> Expected<std::shared_ptr<slam::MapGroup>> {
          auto group = std::make_shared<FakeMapGroup>(o);
          created.push_back(group);
          return std::shared_ptr<slam::MapGroup>(group);
        });
  }
  void Send(const std::string& channel, const std::vector<uint8_t>& bytes) {
    manager_->HandleMessage(channel, bytes.data(), bytes.size());
  }
  void SendFrame(const wire::FeatureFrame& f) {
    Send(wire::kFrameChannel, wire::EncodeFeatureFrame(f));
  }
  // Session control messages published of one type, by session id.
  std::map<int64_t, int> ControlCount(int8_t type) {
    std::lock_guard<std::mutex> lock(published.mutex);
    std::map<int64_t, int> count;
    for (const auto& m : published.control) {
      if (m.type == type) ++count[m.session_id];
    }
    return count;
  }
  std::map<int64_t, int> PoseCount() {
    std::lock_guard<std::mutex> lock(published.mutex);
    std::map<int64_t, int> count;
    for (const auto& p : published.poses) ++count[p.session_id];
    return count;
  }
  SessionManager& manager() { return *manager_; }

  Published published;
  std::vector<std::shared_ptr<FakeMapGroup>> created;

 private:
  std::unique_ptr<SessionManager> manager_;
};

ServerOptions GroupOptions() {
  ServerOptions options = SyncOptions();
  options.max_sessions = 64;
  return options;
}

TEST(MapGroupRoutingTest, SessionsOfAGroupAreAgentsOfOneGroupAndFramesStayInIt) {
  Server server(GroupOptions());
  server.Send(wire::kSessionChannel, Hello(1, "room-a"));
  server.Send(wire::kSessionChannel, Hello(2, "room-a"));
  server.Send(wire::kSessionChannel, Hello(3, "room-b"));
  server.Send(wire::kSessionChannel, Hello(4, ""));
  EXPECT_EQ(server.ControlCount(session_control_t::HELLO_ACK).size(), 4u);
  for (int seq = 1; seq <= 3; ++seq) {
    for (int64_t session = 1; session <= 4; ++session) server.SendFrame(GroupFrame(session, seq));
  }
  ASSERT_EQ(server.created.size(), 2u);  // room-a, then room-b; session 4 has its own System
  const FakeMapGroup& a = *server.created[0];
  const FakeMapGroup& b = *server.created[1];
  EXPECT_EQ(a.joined(), 2);
  EXPECT_EQ(b.joined(), 1);
  std::multiset<int64_t> sessions_a, sessions_b;
  for (double t : a.tracked()) sessions_a.insert(SessionOf(t));
  for (double t : b.tracked()) sessions_b.insert(SessionOf(t));
  EXPECT_EQ(sessions_a, (std::multiset<int64_t>{1, 1, 1, 2, 2, 2}));
  EXPECT_EQ(sessions_b, (std::multiset<int64_t>{3, 3, 3}));
  EXPECT_EQ(server.PoseCount(), (std::map<int64_t, int>{{1, 3}, {2, 3}, {3, 3}, {4, 3}}));
  const ServerCounters c = server.manager().Counters();
  EXPECT_EQ(c.groups, 2);
  EXPECT_EQ(c.groups_created, 2);
  EXPECT_EQ(c.total_drops(), 0);
}

TEST(MapGroupRoutingTest, ACameraOtherThanTheGroupsIsRejected) {
  Server server(GroupOptions());
  server.Send(wire::kSessionChannel, Hello(1, "room-a"));
  const Camera other = Camera::FromHorizontalFov(640, 480, 70.0);
  server.Send(wire::kSessionChannel, Hello(2, "room-a", other));
  EXPECT_EQ(server.ControlCount(session_control_t::HELLO_ACK), (std::map<int64_t, int>{{1, 1}}));
  EXPECT_EQ(server.ControlCount(session_control_t::REJECTED), (std::map<int64_t, int>{{2, 1}}));
  {
    std::lock_guard<std::mutex> lock(server.published.mutex);
    EXPECT_NE(server.published.control.back().reason.find("camera differs from map group room-a"),
              std::string::npos)
        << server.published.control.back().reason;
  }
  // Its frames open nothing: the refusal is final for that session id.
  wire::FeatureFrame frame = GroupFrame(2, 1);
  frame.camera = other;
  server.SendFrame(frame);
  const ServerCounters c = server.manager().Counters();
  EXPECT_EQ(c.drops[static_cast<int>(DropReason::kGroupCamera)], 1);
  EXPECT_EQ(c.drops[static_cast<int>(DropReason::kEndedSession)], 1);
  EXPECT_EQ(c.sessions_started, 1);
  EXPECT_EQ(server.created[0]->joined(), 1);
  EXPECT_STREQ(wire::ToString(DropReason::kGroupCamera), "group_camera_mismatch");
}

TEST(MapGroupRoutingTest, GroupsOutliveTheirSessionsAndAreBounded) {
  ServerOptions options = GroupOptions();
  options.max_groups = 2;
  Server server(options);
  server.Send(wire::kSessionChannel, Hello(1, "room-a"));
  server.SendFrame(GroupFrame(1, 1));
  server.Send(wire::kSessionChannel, Control(session_control_t::BYE, 1));
  server.Send(wire::kSessionChannel, Hello(2, "room-a"));  // the agent comes back
  server.SendFrame(GroupFrame(2, 1));
  ASSERT_EQ(server.created.size(), 1u);
  EXPECT_EQ(server.created[0]->joined(), 2);
  EXPECT_EQ(server.created[0]->tracked().size(), 2u);
  server.Send(wire::kSessionChannel, Hello(3, "room-b"));
  server.Send(wire::kSessionChannel, Hello(4, "room-c"));  // a third group: refused
  EXPECT_EQ(server.ControlCount(session_control_t::REJECTED), (std::map<int64_t, int>{{4, 1}}));
  const ServerCounters c = server.manager().Counters();
  EXPECT_EQ(c.groups, 2);
  EXPECT_EQ(c.groups_refused, 1);
  EXPECT_EQ(c.drops[static_cast<int>(DropReason::kMaxGroups)], 1);
  // Existing groups still take agents.
  server.Send(wire::kSessionChannel, Hello(5, "room-b"));
  EXPECT_EQ(server.created[1]->joined(), 2);
}

// An empty map file made with `camera` (a real one: the server reads its camera).
void WriteEmptyMap(const std::filesystem::path& path, const Camera& camera = Camera()) {
  slam::Options options;
  options.camera = camera;
  auto group = slam::MapGroup::Create(options);
  ASSERT_TRUE(group.ok()) << group.error();
  ASSERT_TRUE((*group)->SaveMap(path.string()).ok());
}

std::filesystem::path FreshDir(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

TEST(MapGroupRoutingTest, GroupMapsAreSavedAtShutdownAndLoadedByName) {
  const std::filesystem::path dir = FreshDir("m2s_group_maps");
  const std::filesystem::path anchor = dir / "anchor.m2smap";
  WriteEmptyMap(anchor);
  ServerOptions options = GroupOptions();
  options.save_maps_dir = dir.string();
  Server server(options);
  ASSERT_TRUE(server.manager().LoadGroupMap("anchor", anchor.string()).ok());
  const std::string bad_path = (dir / "bad.m2smap").string();
  const Status bad = server.manager().LoadGroupMap("other", bad_path);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find(bad_path), std::string::npos) << bad.message();
  EXPECT_FALSE(server.manager().LoadGroupMap("anchor", anchor.string()).ok());  // twice
  EXPECT_FALSE(server.manager().LoadGroupMap("no spaces", anchor.string()).ok());
  server.Send(wire::kSessionChannel, Hello(1, "anchor"));
  server.Send(wire::kSessionChannel, Hello(2, "room-a"));
  ASSERT_EQ(server.created.size(), 2u);       // anchor, room-a
  EXPECT_EQ(server.created[0]->joined(), 1);  // the loaded group took the agent
  server.manager().Shutdown();
  // The loaded anchor is localisation-only: it never changes and is not saved again. room-a
  // is written aside and renamed into place.
  EXPECT_TRUE(server.created[0]->saved().empty());
  EXPECT_EQ(server.created[1]->saved(),
            std::vector<std::string>{(dir / "group-room-a.m2smap.partial").string()});
  EXPECT_TRUE(std::filesystem::exists(dir / "group-room-a.m2smap"));
  EXPECT_FALSE(std::filesystem::exists(dir / "group-room-a.m2smap.partial"));
  std::filesystem::remove_all(dir);
}

TEST(MapGroupRoutingTest, GroupMapsAreSavedEverySavePeriodSoAKilledServerLosesAtMostThat) {
  const std::filesystem::path dir = FreshDir("m2s_group_periodic");
  ManualClock clock;
  ServerOptions options = GroupOptions();
  options.save_maps_dir = dir.string();
  options.save_period_s = 5.0;
  options.session_timeout_s = 1000.0;
  options.clock = [&clock] { return clock.now; };
  Server server(options);
  server.Send(wire::kSessionChannel, Hello(1, "room-a"));
  ASSERT_EQ(server.created.size(), 1u);
  server.manager().Tick();  // the period starts
  clock.Advance(4.9);
  server.manager().Tick();
  EXPECT_TRUE(server.created[0]->saved().empty());
  clock.Advance(0.2);
  server.manager().Tick();
  EXPECT_EQ(server.created[0]->saved().size(), 1u);
  EXPECT_TRUE(std::filesystem::exists(dir / "group-room-a.m2smap"));
  clock.Advance(5.0);
  server.manager().Tick();
  EXPECT_EQ(server.created[0]->saved().size(), 2u);
  std::filesystem::remove_all(dir);
}

TEST(MapGroupRoutingTest, ARestartedServerResumesItsShardsGroupMapsWithTheirCameras) {
  const std::filesystem::path dir = FreshDir("m2s_group_resume");
  const Camera wide = Camera::FromHorizontalFov(800, 600, 100.0);
  const std::vector<std::string> names = {"room-a", "room-b", "room-c", "room-d"};
  for (const std::string& name : names) WriteEmptyMap(dir / ("group-" + name + ".m2smap"), wide);
  WriteEmptyMap(dir / "session_7.m2smap");        // a session's map: not a group
  WriteEmptyMap(dir / "group-no spaces.m2smap");  // not a valid group name
  ServerOptions options = GroupOptions();
  options.save_maps_dir = dir.string();
  options.shard = {1, 2};
  Server server(options);
  const Expected<int> resumed = server.manager().ResumeGroupMaps();
  ASSERT_TRUE(resumed.ok()) << resumed.error();
  int owned = 0;
  for (const std::string& name : names) owned += options.shard.Owns(ShardKeyOfGroup(name));
  EXPECT_EQ(*resumed, owned);
  ASSERT_EQ(server.created.size(), static_cast<size_t>(owned));
  for (const auto& group : server.created) {
    EXPECT_NE(group->resumed(), "");
    EXPECT_EQ(group->options().camera.width, 800);  // the map's camera
  }
  // A HELLO of a resumed group with the map's camera joins it; with another camera, refused.
  for (const std::string& name : names) {
    if (!options.shard.Owns(ShardKeyOfGroup(name))) continue;
    server.Send(wire::kSessionChannel, Hello(11, name, wide));
    server.Send(wire::kSessionChannel, Hello(12, name));
    EXPECT_EQ(server.created.size(), static_cast<size_t>(owned));  // no new group
    EXPECT_EQ(server.manager().Counters().drops[static_cast<int>(DropReason::kGroupCamera)], 1);
    break;
  }
  std::filesystem::remove_all(dir);
}

// Two servers, shards 0/2 and 1/2, see the same bus: HELLOs then frames of 40 sessions, half
// of them in 5 map groups. Every session is acknowledged and answered by exactly one, a
// group's sessions by the same one, and the other's traffic is ignored, not dropped.
TEST(MapGroupRoutingTest, TwoShardsServeEverySessionExactlyOnce) {
  ServerOptions options = GroupOptions();
  options.shard = {0, 2};
  Server first(options);
  options.shard = {1, 2};
  Server second(options);
  std::vector<Server*> servers = {&first, &second};
  auto to_both = [&](const std::string& channel, const std::vector<uint8_t>& bytes) {
    for (Server* s : servers) s->Send(channel, bytes);
  };
  constexpr int kSessions = 40, kFrames = 3;
  std::map<int64_t, std::string> group_of;
  for (int64_t id = 101; id < 101 + kSessions; ++id) {
    group_of[id] = id % 2 ? "" : "group-" + std::to_string(id % 5);
    // A frame before the HELLO opens nothing on a sharded server.
    to_both(wire::kFrameChannel, wire::EncodeFeatureFrame(GroupFrame(id, 1)));
    to_both(wire::kSessionChannel, Hello(id, group_of[id]));
    for (int seq = 2; seq <= kFrames + 1; ++seq) {
      to_both(wire::kFrameChannel, wire::EncodeFeatureFrame(GroupFrame(id, seq)));
    }
  }
  const auto acks0 = first.ControlCount(session_control_t::HELLO_ACK);
  const auto acks1 = second.ControlCount(session_control_t::HELLO_ACK);
  const auto poses0 = first.PoseCount(), poses1 = second.PoseCount();
  std::map<std::string, std::set<int>> servers_of_group;
  for (const auto& [id, group] : group_of) {
    const int acked = static_cast<int>(acks0.count(id)) + static_cast<int>(acks1.count(id));
    EXPECT_EQ(acked, 1) << "session " << id;
    const int served_by = acks0.count(id) ? 0 : 1;
    EXPECT_EQ((served_by == 0 ? poses0 : poses1).at(id), kFrames) << id;
    EXPECT_EQ((served_by == 0 ? poses1 : poses0).count(id), 0u) << id;
    const uint64_t key = group.empty() ? ShardKeyOfSession(id) : ShardKeyOfGroup(group);
    EXPECT_EQ(static_cast<uint64_t>(served_by), key % 2) << id;
    if (!group.empty()) servers_of_group[group].insert(served_by);
  }
  for (const auto& [group, by] : servers_of_group) EXPECT_EQ(by.size(), 1u) << group;
  const ServerCounters c0 = first.manager().Counters(), c1 = second.manager().Counters();
  EXPECT_EQ(c0.sessions_started + c1.sessions_started, kSessions);
  EXPECT_EQ(c0.other_shard_hellos + c1.other_shard_hellos, kSessions);
  // Each server ignores the other's frames and every frame sent before its HELLO.
  EXPECT_EQ(c0.other_shard_messages + c1.other_shard_messages, kSessions * (kFrames + 2));
  EXPECT_EQ(c0.total_drops() + c1.total_drops(), 0);
  EXPECT_GT(c0.sessions_started, 0);
  EXPECT_GT(c1.sessions_started, 0);
}

TEST(MapGroupRoutingTest, StatsJsonHoldsCountersGroupsDropsAndShard) {
  ServerOptions options = GroupOptions();
  options.shard = {0, 1};
  options.server_instance = 4242;
  Server server(options);
  server.Send(wire::kSessionChannel, Hello(1, "room-a"));
  server.SendFrame(GroupFrame(1, 1));
  server.SendFrame(GroupFrame(1, 1));  // repeated seq: a drop
  const nlohmann::json j = nlohmann::json::parse(server.manager().StatsJson(true));
  EXPECT_EQ(j.at("server_instance"), 4242);
  EXPECT_EQ(j.at("shard"), "0/1");
  EXPECT_EQ(j.at("shard_index"), 0);
  EXPECT_EQ(j.at("shard_count"), 1);
  EXPECT_EQ(j.at("messages_in"), 3);
  EXPECT_EQ(j.at("frames_in"), 1);
  EXPECT_EQ(j.at("frames_processed"), 1);
  EXPECT_EQ(j.at("sessions_started"), 1);
  EXPECT_EQ(j.at("sessions_ended"), 0);
  EXPECT_EQ(j.at("groups_created"), 1);
  EXPECT_EQ(j.at("authenticated"), true);
  EXPECT_EQ(j.at("drops_total"), 1);
  EXPECT_EQ(j.at("drops").at("seq_not_increasing"), 1);
  EXPECT_EQ(j.at("drops").size(), static_cast<size_t>(wire::kNumDropReasons));
  ASSERT_EQ(j.at("groups").size(), 1u);
  const nlohmann::json& g = j.at("groups")[0];
  EXPECT_EQ(g.at("name"), "room-a");
  EXPECT_EQ(g.at("agents_joined"), 1);
  EXPECT_EQ(g.at("merges"), 2);
  EXPECT_EQ(g.at("merge_ms"), nlohmann::json::array({12.5, 40.0}));
  EXPECT_EQ(g.at("keyframes"), 3);
  EXPECT_EQ(g.at("map_points"), 70);
  EXPECT_EQ(g.at("localization_only"), false);
  for (const char* key : {"frames_skipped", "session_messages", "sessions_active",
                          "other_shard_hellos", "other_shard_messages", "groups_refused"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
}

TEST(MapGroupRoutingTest, KeyframeOwnershipReachesTheWire) {
  slam::MapDelta delta;
  delta.keyframes.push_back({.id = 1, .timestamp = 0.5, .world_from_camera = Pose3(), .own = true});
  delta.keyframes.push_back(
      {.id = 2, .timestamp = 0.6, .world_from_camera = Pose3(), .own = false});
  const std::vector<uint8_t> bytes = wire::Encode(ToMapMessage(delta, 7, 1, 0, 1));
  const auto decoded = wire::DecodeMapDelta(bytes.data(), bytes.size());
  ASSERT_TRUE(decoded.ok()) << decoded.error();
  ASSERT_EQ(decoded->keyframes.size(), 2u);
  EXPECT_TRUE(decoded->keyframes[0].own);
  EXPECT_FALSE(decoded->keyframes[1].own);
}

}  // namespace
}  // namespace m2s::server_app
