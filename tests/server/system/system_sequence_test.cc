// End-to-end: the whole pipeline on generated head motion through the default scene (CPU
// projector with occlusion, every visible vertex), deterministic mode. The ATE bound is far
// above the benchmark's target so the test is stable, but catches a broken pipeline.
#include <algorithm>
#include <cstdio>
#include <vector>

#include <gtest/gtest.h>

#include "slam_sim.h"

namespace m2s::slam {
namespace {

using testing::ComputeAte;
using testing::DefaultOptions;
using testing::MakeSequence;
using testing::SimOptions;

TEST(SystemSequence, TracksANoiseFreeSequenceOfTheDefaultScene) {
  SimOptions sim;
  sim.duration_s = 8.0;
  sim.budget = 0;
  const auto seq = MakeSequence(sim);
  auto system = System::Create(DefaultOptions(seq.camera));
  ASSERT_TRUE(system.ok()) << system.error();
  int lost = 0, initialised_at = -1, keyframes_created = 0;
  for (const Frame& f : seq.frames) {
    const TrackResult r = (*system)->Track(f);
    lost += r.state == TrackingState::kLost ? 1 : 0;
    keyframes_created += r.keyframe_created ? 1 : 0;
    if (initialised_at < 0 && r.state == TrackingState::kOk)
      initialised_at = static_cast<int>(f.seq);
  }
  const auto ate = ComputeAte((*system)->Trajectory());
  const SystemStats stats = (*system)->Stats();
  std::printf(
      "initialised at frame %d, lost %d, ATE %.3g m over %zu poses, %d keyframes (%d made), %d "
      "points\n",
      initialised_at, lost, ate.rmse, ate.num_poses, stats.keyframes, keyframes_created,
      stats.map_points);
  EXPECT_GE(initialised_at, 0);
  EXPECT_LT(initialised_at, 60);  // within two seconds
  EXPECT_EQ(lost, 0);
  EXPECT_LT(ate.rmse, 1e-5);  // noise-free: measured 1.1e-7 m
  EXPECT_EQ(ate.num_poses, seq.frames.size() - static_cast<size_t>(initialised_at) +
                               (initialised_at > 0 ? 1 : 0));  // every frame from the reference
  EXPECT_EQ(stats.frames_lost, 0);

  // The map delta stream: a full first delta... then nothing until the map changes.
  const MapDelta first = (*system)->TakeMapDelta();
  EXPECT_EQ(static_cast<int>(first.point_ids.size()), stats.map_points);
  EXPECT_TRUE((*system)->TakeMapDelta().empty());
}

}  // namespace
}  // namespace m2s::slam
