// PluginSystem over the "faulty" test plug-in (test_plugins.c): a plug-in that fails or returns
// NaN poses costs those frames (rejected / lost, counted), never the process; map deltas follow
// its map_points; the instance is destroyed exactly once.
#include <dlfcn.h>

#include <cmath>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "m2s/plugin/plugin_system.h"

namespace m2s::plugin {
namespace {

using slam::TrackingState;

const std::string kFaulty =
    std::string(M2S_BINARY_DIR) + "/test_plugins/" + PluginFileName("faulty");

slam::Frame MakeFrame(int64_t seq) {
  slam::Frame f;
  f.seq = seq;
  f.timestamp = 0.1 * static_cast<double>(seq);
  for (uint32_t id = 0; id < 20; ++id) f.features.push_back({id, Eigen::Vector2f(10.0f * id, 50)});
  f.ground_truth_world_from_camera =
      Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, seq, 0));
  return f;
}

// The test plug-in's instance counters (functions it exports besides the entry).
int Counter(const char* symbol) {
  void* handle = dlopen(kFaulty.c_str(), RTLD_NOW | RTLD_NOLOAD);
  EXPECT_NE(handle, nullptr);
  if (handle == nullptr) return -1;
  auto fn = reinterpret_cast<int (*)()>(dlsym(handle, symbol));
  const int value = fn != nullptr ? fn() : -1;
  dlclose(handle);
  return value;
}

class PluginSystemTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto loaded = LoadPlugin(kFaulty);
    ASSERT_TRUE(loaded.ok()) << loaded.error();
    plugin_ = *loaded;
    options_.camera = Camera();
    auto system = CreatePluginSystem(plugin_, options_, "{}");
    ASSERT_TRUE(system.ok()) << system.error();
    system_ = std::move(*system);
  }
  std::shared_ptr<const LoadedPlugin> plugin_;
  slam::Options options_;
  std::unique_ptr<slam::System> system_;
};

TEST_F(PluginSystemTest, ErrorsAndNanPosesCostOnlyTheirFrames) {
  // The plug-in fails on seq % 4 == 1 and returns a NaN translation on seq % 4 == 2.
  for (int64_t seq = 1; seq <= 8; ++seq) {
    const slam::TrackResult r = system_->Track(MakeFrame(seq));
    EXPECT_EQ(r.seq, seq);
    switch (seq % 4) {
      case 1:
        EXPECT_EQ(r.state, TrackingState::kRejected) << seq;
        EXPECT_EQ(r.reject_reason, "plugin_error");
        break;
      case 2:
        EXPECT_EQ(r.state, TrackingState::kLost) << seq;
        break;
      default:
        EXPECT_EQ(r.state, TrackingState::kOk) << seq;
        EXPECT_EQ(r.world_from_camera.translation(), Eigen::Vector3d(seq, 0, 0));
        EXPECT_EQ(r.num_inliers, 20);
    }
  }
  // A frame the host's validation refuses never reaches the plug-in.
  slam::Frame bad = MakeFrame(9);
  bad.features[3].uv.x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(system_->Track(bad).reject_reason, "non_finite_uv");

  const slam::SystemStats stats = system_->Stats();
  EXPECT_EQ(stats.frames_processed, 9);
  EXPECT_EQ(stats.frames_rejected, 3);
  EXPECT_EQ(stats.rejected_by_reason.at("plugin_error"), 2);
  EXPECT_EQ(stats.rejected_by_reason.at("non_finite_uv"), 1);
  EXPECT_EQ(stats.frames_lost, 2);
  EXPECT_EQ(stats.frames_tracked, 4);

  // Without a trajectory() the trajectory is each accepted frame's result, with ground truth.
  const auto trajectory = system_->Trajectory();
  ASSERT_EQ(trajectory.size(), 6u);  // seq 2, 3, 4, 6, 7, 8
  EXPECT_EQ(trajectory[0].seq, 2);
  EXPECT_EQ(trajectory[0].state, TrackingState::kLost);
  EXPECT_EQ(trajectory[1].seq, 3);
  EXPECT_EQ(trajectory[1].world_from_camera.translation().x(), 3.0);
  ASSERT_TRUE(trajectory[1].ground_truth_world_from_camera);
  EXPECT_EQ(trajectory[1].ground_truth_world_from_camera->translation().y(), 3.0);
}

TEST_F(PluginSystemTest, MapDeltasAreTheChangesOfMapPoints) {
  // The plug-in's points: ids 0..min(frames, 5)-1 at (id, frames processed, 1).
  for (int64_t seq = 2; seq <= 4; ++seq) system_->Track(MakeFrame(seq));  // 3 frames processed
  const slam::MapDelta first = system_->TakeMapDelta();
  EXPECT_EQ(first.base_revision, 0u);
  EXPECT_EQ(first.revision, 1u);
  ASSERT_EQ(first.point_ids, (std::vector<VertexId>{0, 1, 2}));
  EXPECT_EQ(first.point_positions[2], Eigen::Vector3f(2, 3, 1));
  const slam::MapDelta none = system_->TakeMapDelta();
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.revision, 1u);

  system_->Track(MakeFrame(6));  // NaN pose, but processed: 4 frames, points move and grow
  const slam::MapDelta second = system_->TakeMapDelta();
  EXPECT_EQ(second.base_revision, 1u);
  EXPECT_EQ(second.revision, 2u);
  EXPECT_EQ(second.point_ids.size(), 4u);
  const slam::MapDelta full = system_->FullMap();
  EXPECT_TRUE(full.full);
  EXPECT_EQ(full.revision, 2u);
  EXPECT_EQ(full.point_ids.size(), 4u);
  EXPECT_EQ(system_->Stats().map_points, 4);

  // Reset (the plug-in has no reset: a new instance) empties the map: the next delta removes.
  const int destroyed = Counter("m2s_test_destroyed");
  system_->Reset();
  EXPECT_EQ(Counter("m2s_test_destroyed"), destroyed + 1);
  EXPECT_EQ(Counter("m2s_test_live_instances"), 1);
  EXPECT_TRUE(system_->Trajectory().empty());
  EXPECT_EQ(system_->TakeMapDelta().removed_points.size(), 4u);
}

TEST_F(PluginSystemTest, SubmittedFramesComeBackInOrder) {
  for (int64_t seq = 1; seq <= 3; ++seq) {
    system_->Submit(MakeFrame(seq));
    slam::TrackResult r;
    ASSERT_TRUE(system_->WaitForResult(&r, 10.0));
    EXPECT_EQ(r.seq, seq);
  }
  EXPECT_EQ(system_->Stats().frames_submitted, 3);
}

TEST_F(PluginSystemTest, RefusesMapFilesNamingThePlugin) {
  const Status saved = system_->SaveMap("/tmp/never_written.m2smap");
  EXPECT_FALSE(saved.ok());
  EXPECT_EQ(saved.message(), "saving maps is not supported by plug-in faulty");
  EXPECT_EQ(system_->LoadMap("/tmp/x.m2smap").message(),
            "loading maps is not supported by plug-in faulty");
}

TEST_F(PluginSystemTest, ShutdownDestroysTheInstanceOnce) {
  const int destroyed = Counter("m2s_test_destroyed");
  system_->Shutdown();
  EXPECT_EQ(Counter("m2s_test_destroyed"), destroyed + 1);
  system_->Shutdown();
  EXPECT_EQ(system_->Track(MakeFrame(3)).reject_reason, "shut_down");
  system_.reset();
  EXPECT_EQ(Counter("m2s_test_destroyed"), destroyed + 1);
  EXPECT_EQ(Counter("m2s_test_live_instances"), 0);
}

TEST(PluginSystem, APluginRefusingItsConfigSaysWhy) {
  auto loaded = LoadPlugin(kFaulty);
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  auto system = CreatePluginSystem(*loaded, slam::Options(), R"({"speed": 2})");
  ASSERT_FALSE(system.ok());
  EXPECT_EQ(system.error(),
            "plug-in faulty refused to start: config: unknown key (this plug-in takes none)");
  // LoadMethod checks the config at load time.
  auto method = LoadMethod(kFaulty, R"({"speed": 2})");
  ASSERT_FALSE(method.ok());
  EXPECT_NE(method.error().find("refused to start"), std::string::npos);
}

TEST(PluginSystem, CppExceptionsStopAtTheAbiBoundary) {
  const std::string path =
      std::string(M2S_BINARY_DIR) + "/test_plugins/" + PluginFileName("throwing");
  auto loaded = LoadPlugin(path);
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ((*loaded)->table().trajectory, nullptr);  // kHasTrajectory is false
  auto refused = CreatePluginSystem(*loaded, slam::Options(), R"({"x": 1})");
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error(), "plug-in throwing refused to start: config: no options here");

  auto system = CreatePluginSystem(*loaded, slam::Options(), "{}");
  ASSERT_TRUE(system.ok()) << system.error();
  EXPECT_EQ((*system)->Track(MakeFrame(1)).world_from_camera.translation().x(), 1.0);
  EXPECT_EQ((*system)->Track(MakeFrame(2)).world_from_camera.translation().x(), 2.0);
  EXPECT_EQ((*system)->Track(MakeFrame(3)).reject_reason, "plugin_error");
  EXPECT_EQ((*system)->Track(MakeFrame(4)).reject_reason, "plugin_error");
  // The default Reset() recreates the method: its own frame count starts again.
  (*system)->Reset();
  EXPECT_EQ((*system)->Track(MakeFrame(5)).world_from_camera.translation().x(), 1.0);

  // The messages themselves, through the C table: one line each.
  const m2s_plugin& table = (*loaded)->table();
  const m2s_camera camera{640, 480, 500, 500, 320, 240, 0.05, 50};
  char error[128] = "";
  void* instance = table.create(&camera, "{}", error, sizeof(error));
  ASSERT_NE(instance, nullptr);
  m2s_frame frame{3, 0.3, nullptr, 0};
  m2s_track_result result{};
  EXPECT_NE(table.process_frame(instance, &frame, &result, error, sizeof(error)), 0);
  EXPECT_STREQ(error, "bad frame 3");
  frame.seq = 4;
  EXPECT_NE(table.process_frame(instance, &frame, &result, error, sizeof(error)), 0);
  EXPECT_STREQ(error, "unknown C++ exception");
  char tiny[5] = "";
  frame.seq = 3;
  EXPECT_NE(table.process_frame(instance, &frame, &result, tiny, sizeof(tiny)), 0);
  EXPECT_STREQ(tiny, "bad ");  // cut to the buffer, NUL-terminated
  EXPECT_NE(table.relocalise(instance, error, sizeof(error)), 0);
  EXPECT_STREQ(error, "relocalise is not supported");
  table.destroy(instance);
}

TEST(PluginSystem, LoadMethodRefusesMapGroupsForAPlugin) {
  auto method = LoadMethod(kFaulty, "");
  ASSERT_TRUE(method.ok()) << method.error();
  EXPECT_EQ(method->name, "faulty");
  auto group = method->group(slam::Options());
  ASSERT_FALSE(group.ok());
  EXPECT_EQ(group.error(),
            "map groups need the built-in SLAM (vertex_slam); this server runs plug-in faulty");
  auto builtin = LoadMethod("", "");
  ASSERT_TRUE(builtin.ok());
  EXPECT_EQ(builtin->name, "vertex_slam");
  EXPECT_TRUE(builtin->path.empty());
  EXPECT_FALSE(LoadMethod("vertex_slam", R"({"a": 1})").ok());
}

}  // namespace
}  // namespace m2s::plugin
