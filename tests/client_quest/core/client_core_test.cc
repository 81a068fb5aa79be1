// Client core: the map replica's ordering rules, and a resync after dropped map deltas over
// the on-device transport (the server's session logic with a stand-in SLAM system).
#include <atomic>

#include <gtest/gtest.h>

#include "fake_system.h"
#include "m2s/client/client_session.h"
#include "m2s/client/map_replica.h"
#include "m2s/client/on_device_transport.h"

namespace m2s::client {
namespace {

map_delta_t Delta(int64_t session, int64_t base, int64_t revision, std::vector<int32_t> ids,
                  bool full = false) {
  map_delta_t d{};
  d.version = map_delta_t::VERSION;
  d.session_id = session;
  d.base_revision = base;
  d.revision = revision;
  d.full = full;
  d.num_keyframes = d.num_removed_keyframes = d.num_removed_points = 0;
  d.point_ids = ids;
  for (int32_t id : ids) d.point_xyz.push_back({static_cast<float>(id), 0.f, 0.f});
  d.num_points = static_cast<int32_t>(ids.size());
  return d;
}

TEST(MapReplicaTest, AppliesInOrderDetectsGapsAndTakesFullMaps) {
  MapReplica replica;
  replica.Reset(5);
  using R = MapReplica::ApplyResult;
  EXPECT_EQ(replica.Apply(Delta(5, 0, 1, {1, 2})), R::kApplied);
  EXPECT_EQ(replica.Apply(Delta(5, 1, 2, {3})), R::kApplied);
  EXPECT_EQ(replica.Apply(Delta(5, 1, 2, {3})), R::kStale);
  EXPECT_EQ(replica.Apply(Delta(5, 3, 4, {9})), R::kGap);
  EXPECT_EQ(replica.Apply(Delta(6, 2, 3, {9})), R::kOtherSession);
  EXPECT_EQ(replica.revision(), 2);
  EXPECT_EQ(replica.num_points(), 3u);
  map_delta_t removal = Delta(5, 2, 3, {});
  removal.removed_points = {1};
  removal.num_removed_points = 1;
  EXPECT_EQ(replica.Apply(removal), R::kApplied);
  EXPECT_EQ(replica.num_points(), 2u);
  EXPECT_EQ(replica.Apply(Delta(5, 0, 7, {4, 5, 6, 7}, true)), R::kFull);
  EXPECT_EQ(replica.revision(), 7);
  const MapSnapshot snapshot = replica.Snapshot();
  EXPECT_EQ(snapshot.point_ids, (std::vector<VertexId>{4, 5, 6, 7}));
  EXPECT_FLOAT_EQ(snapshot.points[2].x(), 6.f);
}

// Drops every third map delta on its way to the client.
class LossyTransport final : public Transport {
 public:
  explicit LossyTransport(std::unique_ptr<Transport> inner) : inner_(std::move(inner)) {}
  Status Start(MessageHandler handler) override {
    return inner_->Start([this, handler](const std::string& c, const uint8_t* d, size_t n) {
      if (c == wire::kMapChannel && !wire::DecodeMapDelta(d, n)->full && ++maps_ % 3 == 0) {
        ++dropped_;
        return;
      }
      handler(c, d, n);
    });
  }
  Status Publish(const std::string& c, const std::vector<uint8_t>& b) override {
    return inner_->Publish(c, b);
  }
  void Stop() override { inner_->Stop(); }
  std::string_view name() const override { return "lossy"; }
  std::atomic<int> maps_{0}, dropped_{0};

 private:
  std::unique_ptr<Transport> inner_;
};

TEST(ClientSessionTest, ResyncAfterDroppedDeltasRestoresTheWholeMap) {
  server_app::ServerOptions server;
  server.synchronous = true;  // a delta after every frame, deterministic
  LossyTransport transport(
      std::make_unique<OnDeviceTransport>(server, &m2s::testing::FakeSystem::Create));
  ClientSessionOptions options;
  options.resync_min_interval_s = 0;
  ClientSession session(&transport, options);
  ASSERT_TRUE(session.Start().ok());
  constexpr int kFrames = 60;
  for (int k = 0; k < kFrames; ++k) {
    wire::FeatureFrame frame;
    frame.capture_time_us = k * 10000;
    frame.features = {{static_cast<VertexId>(k), {5.f, 5.f}}};
    frame.ground_truth_world_from_camera = Pose3();
    auto seq = session.Send(frame);
    ASSERT_TRUE(seq.ok());
    ASSERT_TRUE(session.WaitForPose(*seq, 5.0));
  }
  ASSERT_TRUE(session.SyncMap(5.0));
  const ClientCounters c = session.Counters();
  EXPECT_GT(transport.dropped_.load(), 0);
  EXPECT_GT(c.map_gaps, 0);
  EXPECT_GE(c.full_maps, 1);
  EXPECT_EQ(c.poses_received, kFrames);
  // The stand-in adds point `seq` for every frame: the replica holds all of them.
  const MapSnapshot map = session.replica().Snapshot();
  ASSERT_EQ(map.point_ids.size(), static_cast<size_t>(kFrames));
  for (int k = 0; k < kFrames; ++k) EXPECT_EQ(map.point_ids[k], static_cast<VertexId>(k + 1));
  for (const FrameRecord& r : session.Records()) EXPECT_TRUE(r.answered);
  session.End();
}

}  // namespace
}  // namespace m2s::client
