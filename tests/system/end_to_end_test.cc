// End to end on the default scene with the real SLAM: the on-device client, a recorded run
// and its replay (identical trajectories), and the session logs in tests/data.
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "m2s/common/trajectory.h"
#include "m2s/headless/headless_run.h"
#include "m2s/replay/replay.h"
#include "test_files.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;

std::string ReadFile(const fs::path& path) { return testing::ReadFile(path); }
fs::path TempDir(const std::string& name) { return testing::TempDir("e2e", name); }

headless::HeadlessOptions ShortRun(const fs::path& out) {
  headless::HeadlessOptions o;
  o.fast = true;
  o.on_device = true;
  o.projector = "cpu";
  o.fps = 10;
  o.max_frames = 30;
  o.noise.budget = 3000;  // keeps the test quick
  o.render_map = false;
  o.out_dir = out.string();
  return o;
}

TEST(EndToEndTest, OnDeviceDefaultSceneTracksRecordsAndReplaysIdentically) {
  const fs::path dir = TempDir("ondevice");
  headless::HeadlessOptions options = ShortRun(dir / "live");
  options.record_log = (dir / "run.lcmlog").string();
  auto live = headless::RunHeadless(options);
  ASSERT_TRUE(live.ok()) << live.error();
  const headless::RunMetrics& m = live->metrics;
  EXPECT_EQ(m.frames_total, 30);
  EXPECT_EQ(m.frames_processed, 30);
  EXPECT_EQ(m.frames_skipped, 0);
  EXPECT_GE(m.frames_tracked, 15);  // initialisation needs 1.5 deg of parallax: ~1.2 s here
  EXPECT_GE(m.ate_rmse, 0.0);
  EXPECT_LT(m.ate_rmse, 0.05);  // metres, Sim3-aligned, on a 3 s walk through the room
  EXPECT_DOUBLE_EQ(m.bytes_per_feature, 8.0);
  EXPECT_GT(m.map_points, 100);
  for (const char* name :
       {"trajectory.tum", "keyframes.tum", "groundtruth.tum", "metrics.json", "trajectory.png"}) {
    EXPECT_TRUE(fs::exists(dir / "live" / name)) << name;
  }

  replay::ReplayOptions replay_options;
  replay_options.log_path = options.record_log;
  replay_options.out_dir = (dir / "replay").string();
  replay_options.render_map = false;
  auto replayed = replay::Replay(replay_options);
  ASSERT_TRUE(replayed.ok()) << replayed.error();
  EXPECT_TRUE(replayed->log_problem.empty()) << replayed->log_problem;
  EXPECT_EQ(replayed->frames, 30);
  // Same frames, same poses: the deterministic SLAM gives the live trajectory again.
  auto live_tum = ReadTum((dir / "live" / "trajectory.tum").string());
  auto replay_tum = ReadTum((dir / "replay" / "trajectory.tum").string());
  ASSERT_TRUE(live_tum.ok() && replay_tum.ok());
  ASSERT_EQ(live_tum->size(), replay_tum->size());
  EXPECT_EQ(ReadFile(dir / "live" / "trajectory.tum"), ReadFile(dir / "replay" / "trajectory.tum"));
  for (size_t i = 0; i < live_tum->size(); ++i) {
    EXPECT_EQ((*live_tum)[i].timestamp, (*replay_tum)[i].timestamp);
    const Pose3 delta =
        (*live_tum)[i].world_from_camera.Inverse() * (*replay_tum)[i].world_from_camera;
    EXPECT_LT(delta.translation().norm(), 1e-9) << i;
    EXPECT_LT(RotationAngle(delta.rotation()), 1e-9) << i;
  }
  EXPECT_EQ(ReadFile(dir / "live" / "groundtruth.tum"),
            ReadFile(dir / "replay" / "groundtruth.tum"));
  fs::remove_all(dir);
}

TEST(EndToEndTest, ReplaysTheLogsInTestData) {
  const fs::path data = fs::path(M2S_SOURCE_DIR) / "tests" / "data";
  for (const char* name : {"default_fast_10hz", "default_realtime_30hz"}) {
    const fs::path dir = TempDir(name);
    replay::ReplayOptions options;
    options.log_path = (data / (std::string(name) + ".lcmlog")).string();
    options.out_dir = dir.string();
    options.render_map = false;
    auto result = replay::Replay(options);
    ASSERT_TRUE(result.ok()) << result.error();
    EXPECT_TRUE(result->log_problem.empty()) << result->log_problem;
    EXPECT_GT(result->frames, 50);
    EXPECT_EQ(result->metrics.frames_processed, result->metrics.frames_total) << name;
    EXPECT_GE(result->metrics.frames_tracked, 3) << name;
    EXPECT_GE(result->metrics.ate_rmse, 0.0) << name;
    EXPECT_LT(result->metrics.ate_rmse, 0.3) << name;
    EXPECT_EQ(result->server.total_drops(), 0) << name;
    fs::remove_all(dir);
  }
}

TEST(EndToEndTest, TruncatedLogIsReportedWithItsOffsetAndTheStartIsUsed) {
  const fs::path data =
      fs::path(M2S_SOURCE_DIR) / "tests" / "data" / "default_realtime_30hz.lcmlog";
  const fs::path dir = TempDir("truncated");
  const std::string bytes = ReadFile(data);
  ASSERT_GT(bytes.size(), 300000u);
  {
    std::ofstream out(dir / "cut.lcmlog", std::ios::binary);
    out.write(bytes.data(), 300000);
  }
  replay::ReplayOptions options;
  options.log_path = (dir / "cut.lcmlog").string();
  options.out_dir = (dir / "out").string();
  options.render_map = false;
  auto result = replay::Replay(options);
  ASSERT_TRUE(result.ok()) << result.error();
  EXPECT_NE(result->log_problem.find("broken at byte"), std::string::npos) << result->log_problem;
  EXPECT_GT(result->frames, 10);
  EXPECT_EQ(result->metrics.frames_processed, result->metrics.frames_total);

  // Garbage in the middle: the events before it are used and the problem says where.
  std::string corrupt = bytes;
  for (size_t i = 200000; i < 230000; ++i) corrupt[i] = '\x5a';
  {
    std::ofstream out(dir / "corrupt.lcmlog", std::ios::binary);
    out.write(corrupt.data(), static_cast<std::streamsize>(corrupt.size()));
  }
  options.log_path = (dir / "corrupt.lcmlog").string();
  auto corrupted = replay::Replay(options);
  ASSERT_TRUE(corrupted.ok()) << corrupted.error();
  EXPECT_FALSE(corrupted->log_problem.empty());
  EXPECT_GT(corrupted->frames, 10);
  fs::remove_all(dir);
}

TEST(EndToEndTest, MissingLogIsAClearError) {
  replay::ReplayOptions options;
  options.log_path = "/nonexistent/run.lcmlog";
  auto result = replay::Replay(options);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().find("/nonexistent/run.lcmlog"), std::string::npos);
}

}  // namespace
}  // namespace m2s
