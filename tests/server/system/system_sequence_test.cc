// End-to-end: the whole pipeline on generated head motion through the default scene.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>

#include "m2s/common/logging.h"

#include <gtest/gtest.h>

#include "slam_sim.h"

namespace m2s::slam {
namespace {

using testing::ComputeAte;
using testing::DefaultOptions;
using testing::MakeSequence;
using testing::SimOptions;

TEST(SystemSequence, TracksNoiseFreeSequenceWithSmallAte) {
  if (std::getenv("M2S_DEBUG")) SetMinLogLevel(LogLevel::kDebug);
  SimOptions sim;
  sim.duration_s = 10.0;
  sim.budget = 0;
  const auto t0 = std::chrono::steady_clock::now();
  const auto seq = MakeSequence(sim);
  std::printf("generation %.1f s, %zu frames, %zu features in frame 100\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
              seq.frames.size(), seq.frames[100].features.size());
  double total_ms = 0, init_ms = 0;
  std::vector<double> track_ms;
  auto system = System::Create(DefaultOptions(seq.camera));
  ASSERT_TRUE(system.ok()) << system.error();
  int lost = 0, initialised_at = -1;
  for (const Frame& f : seq.frames) {
    const TrackResult r = (*system)->Track(f);
    if (r.state == TrackingState::kLost) ++lost;
    total_ms += r.tracking_ms;
    if (r.state == TrackingState::kNotInitialized) init_ms += r.tracking_ms;
    if (r.state == TrackingState::kOk && !r.keyframe_created) track_ms.push_back(r.tracking_ms);
    if (initialised_at < 0 && r.state == TrackingState::kOk)
      initialised_at = static_cast<int>(f.seq);
  }
  std::sort(track_ms.begin(), track_ms.end());
  std::printf("total %.0f ms, init %.0f ms, median tracking %.3f ms\n", total_ms, init_ms,
              track_ms.empty() ? 0.0 : track_ms[track_ms.size() / 2]);
  const auto ate = ComputeAte((*system)->Trajectory());
  const SystemStats stats = (*system)->Stats();
  std::printf(
      "initialised at frame %d, lost %d, ATE %.9f m over %zu poses, %d keyframes, %d points\n",
      initialised_at, lost, ate.rmse, ate.num_poses, stats.keyframes, stats.map_points);
  EXPECT_GE(initialised_at, 0);
  EXPECT_EQ(lost, 0);
  EXPECT_LT(ate.rmse, 0.02);
  EXPECT_GT(ate.num_poses, seq.frames.size() * 9 / 10);
}

}  // namespace
}  // namespace m2s::slam
