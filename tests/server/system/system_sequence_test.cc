// End-to-end: the whole pipeline on generated head motion through the default scene.
#include <gtest/gtest.h>

#include "slam_sim.h"

namespace m2s::slam {
namespace {

using testing::ComputeAte;
using testing::DefaultOptions;
using testing::MakeSequence;
using testing::SimOptions;

TEST(SystemSequence, TracksNoiseFreeSequenceWithSmallAte) {
  SimOptions sim;
  sim.duration_s = 20.0;
  const auto seq = MakeSequence(sim);
  auto system = System::Create(DefaultOptions(seq.camera));
  ASSERT_TRUE(system.ok()) << system.error();
  int lost = 0, initialised_at = -1;
  for (const Frame& f : seq.frames) {
    const TrackResult r = (*system)->Track(f);
    if (r.state == TrackingState::kLost) ++lost;
    if (initialised_at < 0 && r.state == TrackingState::kOk)
      initialised_at = static_cast<int>(f.seq);
  }
  const auto ate = ComputeAte((*system)->Trajectory());
  const SystemStats stats = (*system)->Stats();
  std::printf(
      "initialised at frame %d, lost %d, ATE %.6f m over %zu poses, %d keyframes, %d points\n",
      initialised_at, lost, ate.rmse, ate.num_poses, stats.keyframes, stats.map_points);
  EXPECT_GE(initialised_at, 0);
  EXPECT_EQ(lost, 0);
  EXPECT_LT(ate.rmse, 0.02);
  EXPECT_GT(ate.num_poses, seq.frames.size() * 9 / 10);
}

}  // namespace
}  // namespace m2s::slam
