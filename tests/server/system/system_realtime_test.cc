// The System's asynchronous mode (the paper's) fed at the camera rate: frames arrive paced by
// the wall clock while tracking and mapping run in their own threads. Real time: labelled
// `realtime`.
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

#include "point_room_system.h"

namespace m2s::slam {
namespace {

using testing::ComputeAte;
using testing::SimSequence;

const SimSequence& Sequence() { return testing::PointRoomSequence(); }

std::unique_ptr<System> MakeSystem(bool deterministic = true) {
  return testing::MakePointRoomSystem(deterministic);
}

TEST(SystemRealtime, AsynchronousModeWithMappingThread) {
  auto system = MakeSystem(/*deterministic=*/false);
  const auto& frames = Sequence().frames;
  // Frames arrive at the camera rate (the producer is paced like a camera, results are read
  // by this thread in between).
  const size_t n = std::min<size_t>(frames.size(), 240);
  const auto start = std::chrono::steady_clock::now();
  const double t0 = frames[0].timestamp;
  std::vector<TrackResult> results;
  for (size_t i = 0; i < n; ++i) {
    std::this_thread::sleep_until(start + std::chrono::duration<double>(frames[i].timestamp - t0));
    system->Submit(frames[i]);
    TrackResult r;
    while (system->WaitForResult(&r, 0.0)) results.push_back(r);
  }
  TrackResult r;
  while (results.size() + system->Stats().frames_dropped_queue < n &&
         system->WaitForResult(&r, 5.0)) {
    results.push_back(r);
  }
  const SystemStats stats = system->Stats();
  EXPECT_EQ(results.size() + stats.frames_dropped_queue, n);
  int lost = 0;
  for (size_t i = 0; i < results.size(); ++i) {
    lost += results[i].state == TrackingState::kLost ? 1 : 0;
    if (i > 0) {
      EXPECT_GT(results[i].seq, results[i - 1].seq);  // in order
    }
  }
  EXPECT_EQ(lost, 0);
  EXPECT_LT(ComputeAte(system->Trajectory()).rmse, 1e-3);  // noise-free, < 1 mm
  const MapDelta delta = system->TakeMapDelta();
  EXPECT_GT(delta.point_ids.size(), 100u);
  system->Shutdown();
  EXPECT_FALSE(system->WaitForResult(&r, 0.01));
}

}  // namespace
}  // namespace m2s::slam
