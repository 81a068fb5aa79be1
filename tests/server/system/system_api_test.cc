// The System API on a light synthetic room: bad frames, loss and relocalisation, reset,
// save / load with localisation-only tracking, and shutdown (system_realtime_test runs the
// asynchronous mode at the camera rate).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

#include <gtest/gtest.h>

#include "point_room_system.h"

namespace m2s::slam {
namespace {

using testing::ComputeAte;
using testing::DefaultOptions;
using testing::SimSequence;

const SimSequence& Sequence() { return testing::PointRoomSequence(); }

std::unique_ptr<System> MakeSystem(bool deterministic = true) {
  return testing::MakePointRoomSystem(deterministic);
}

TEST(SystemApi, CreateRejectsBadOptions) {
  Options options;
  options.camera.fx = -1.0;
  EXPECT_FALSE(System::Create(options).ok());
  options = Options();
  options.tracker.keyframe_tracked_ratio = 2.0;
  const auto s = System::Create(options);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("keyframe_tracked_ratio"), std::string::npos);
}

TEST(SystemApi, BadFramesAreCountedAndRejectedWithoutHarm) {
  auto system = MakeSystem();
  const auto& frames = Sequence().frames;
  int64_t seq = 0;
  auto with_seq = [&](Frame f) {
    f.seq = seq;
    return f;
  };
  auto expect_rejected = [&](Frame f, const std::string& reason) {
    const TrackResult r = system->Track(f);
    EXPECT_EQ(r.state, TrackingState::kRejected) << reason;
    EXPECT_EQ(r.reject_reason, reason);
  };
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (size_t i = 0; i < 200; ++i) {
    Frame f = frames[i];
    seq = f.seq;
    if (i == 20) {
      Frame bad = f;
      bad.features[3].uv.x() = nan;
      expect_rejected(bad, "non_finite_uv");
    } else if (i == 40) {
      Frame bad = f;
      bad.features.push_back(bad.features[0]);
      expect_rejected(bad, "duplicate_id");
    } else if (i == 60) {
      expect_rejected(with_seq(Frame{}), "empty");
    } else if (i == 80) {
      Frame bad = f;
      bad.features.resize(1000000, bad.features[0]);
      for (size_t k = 0; k < bad.features.size(); ++k)
        bad.features[k].id = static_cast<VertexId>(k);
      expect_rejected(bad, "too_many_features");
    } else if (i == 100) {
      Frame bad = f;
      bad.timestamp = frames[i - 50].timestamp;  // going back
      expect_rejected(bad, "timestamp_going_back");
    } else if (i == 120) {
      Frame bad = frames[i - 1];  // seq not increasing
      expect_rejected(bad, "seq_not_increasing");
    }
    const TrackResult r = system->Track(f);
    EXPECT_NE(r.state, TrackingState::kRejected) << "frame " << i << ": " << r.reject_reason;
    EXPECT_NE(r.state, TrackingState::kLost) << "frame " << i;
  }
  const SystemStats stats = system->Stats();
  EXPECT_EQ(stats.frames_rejected, 6);
  for (const char* reason : {"non_finite_uv", "duplicate_id", "empty", "too_many_features",
                             "timestamp_going_back", "seq_not_increasing"}) {
    EXPECT_EQ(stats.rejected_by_reason.count(reason), 1u) << reason;
  }
  EXPECT_EQ(stats.frames_lost, 0);
  const auto ate = ComputeAte(system->Trajectory());
  std::printf("ATE %.3g m\n", ate.rmse);
  EXPECT_LT(ate.rmse, 1e-5);  // noise-free: measured 6e-8 m
}

TEST(SystemApi, LosesTrackWhenFeaturesAreCutAndRelocalises) {
  auto system = MakeSystem();
  const auto& frames = Sequence().frames;
  int lost = 0, relocalised = 0, ok_after = 0;
  const size_t cut_begin = 150, cut_end = 180;  // one second at 30 fps
  for (size_t i = 0; i < 260; ++i) {
    Frame f = frames[i];
    // 5 features: under the 8 inliers any pose needs.
    if (i >= cut_begin && i < cut_end) f.features.resize(std::min<size_t>(f.features.size(), 5));
    const TrackResult r = system->Track(f);
    if (i >= cut_begin && i < cut_end) {
      lost += r.state == TrackingState::kLost ? 1 : 0;
    } else if (i >= cut_end) {
      relocalised += r.state == TrackingState::kRelocalized ? 1 : 0;
      ok_after += r.state == TrackingState::kOk ? 1 : 0;
    }
  }
  EXPECT_EQ(lost, static_cast<int>(cut_end - cut_begin));
  EXPECT_EQ(relocalised, 1);
  EXPECT_EQ(ok_after, static_cast<int>(260 - cut_end - 1));
  const SystemStats stats = system->Stats();
  EXPECT_EQ(stats.relocalisations, 1);
  EXPECT_EQ(stats.frames_lost, static_cast<int64_t>(cut_end - cut_begin));
  const double ate = ComputeAte(system->Trajectory()).rmse;
  std::printf("ATE %.3g m\n", ate);
  EXPECT_LT(ate, 1e-5);  // noise-free: measured 6e-8 m
}

TEST(SystemApi, ResetForgetsTheMapAndInitialisesAgain) {
  auto system = MakeSystem();
  const auto& frames = Sequence().frames;
  for (size_t i = 0; i < 120; ++i) system->Track(frames[i]);
  ASSERT_GT(system->Stats().keyframes, 1);
  system->TakeMapDelta();
  system->Reset();
  EXPECT_EQ(system->Stats().keyframes, 0);
  EXPECT_EQ(system->Stats().map_points, 0);
  EXPECT_TRUE(system->Trajectory().empty());
  const MapDelta delta = system->TakeMapDelta();
  EXPECT_TRUE(delta.full);
  EXPECT_TRUE(delta.keyframes.empty());
  bool initialised = false;
  for (size_t i = 120; i < 240 && !initialised; ++i) {
    initialised = system->Track(frames[i]).state == TrackingState::kOk;
  }
  EXPECT_TRUE(initialised);
}

TEST(SystemApi, SavedMapIsLoadedForLocalisationOnly) {
  const auto& frames = Sequence().frames;
  const std::string path = ::testing::TempDir() + "/m2s_system_test.m2smap";
  Sim3 truth_from_map;
  {
    auto system = MakeSystem();
    for (size_t i = 0; i < frames.size(); ++i) system->Track(frames[i]);
    const auto ate = ComputeAte(system->Trajectory());
    std::printf("ATE %.3g m\n", ate.rmse);
    ASSERT_LT(ate.rmse, 1e-5);  // noise-free: measured 8e-8 m
    truth_from_map = ate.truth_from_estimate;
    ASSERT_TRUE(system->SaveMap(path).ok());
  }
  auto system = MakeSystem();
  const Status bad = system->LoadMap(path + ".missing");
  EXPECT_FALSE(bad.ok());
  ASSERT_TRUE(system->LoadMap(path).ok());
  const SystemStats loaded = system->Stats();
  EXPECT_GT(loaded.keyframes, 2);
  system->TakeMapDelta();
  int relocalised = 0, ok = 0;
  double max_error = 0.0;
  for (size_t i = 100; i < frames.size(); i += 3) {
    const TrackResult r = system->Track(frames[i]);
    EXPECT_FALSE(r.keyframe_created);
    relocalised += r.state == TrackingState::kRelocalized ? 1 : 0;
    ok += r.state == TrackingState::kOk ? 1 : 0;
    if (r.state == TrackingState::kOk || r.state == TrackingState::kRelocalized) {
      const Eigen::Vector3d p = truth_from_map * r.world_from_camera.translation();
      max_error =
          std::max(max_error, (p - frames[i].ground_truth_world_from_camera->translation()).norm());
    }
  }
  EXPECT_EQ(relocalised, 1);
  EXPECT_GT(ok, 50);
  std::printf("localisation max error %.3g m\n", max_error);
  // In the saved map's frame (the same world as the first run); measured 1.7e-7 m.
  EXPECT_LT(max_error, 1e-5);
  EXPECT_EQ(system->Stats().keyframes, loaded.keyframes);  // the map never changes
  EXPECT_TRUE(system->TakeMapDelta().empty());
  std::remove(path.c_str());
}

// In real time the frames between the first map's two views are solved after it, over the
// next tracked frames: in the end they have the poses the deterministic system gives them
// (solved at once), on the truth, and the counters count them as tracked.
TEST(SystemApi, RealTimeSolvesTheFramesBetweenTheTwoViewsAfterTheMap) {
  const auto& frames = Sequence().frames;
  const size_t n = std::min<size_t>(frames.size(), 150);
  auto has_pose = [](TrackingState s) {
    return s == TrackingState::kOk || s == TrackingState::kRelocalized;
  };
  // The frames before the initialising one (the first with a pose) that end with a pose.
  struct Run {
    int64_t initialised_at = -1;
    std::vector<TrajectoryEntry> before;
    SystemStats stats;
    int64_t with_pose = 0;
  };
  auto run = [&](bool deterministic) {
    auto system = MakeSystem(deterministic);
    Run out;
    for (size_t i = 0; i < n; ++i) {
      TrackResult r;
      if (deterministic) {
        r = system->Track(frames[i]);
      } else {
        system->Submit(frames[i]);  // one at a time: nothing dropped
        EXPECT_TRUE(system->WaitForResult(&r, 60.0));
      }
      if (out.initialised_at < 0 && has_pose(r.state)) out.initialised_at = r.seq;
    }
    for (const TrajectoryEntry& e : system->Trajectory()) {
      out.with_pose += has_pose(e.state) ? 1 : 0;
      if (has_pose(e.state) && e.seq < out.initialised_at) out.before.push_back(e);
    }
    out.stats = system->Stats();
    return out;
  };
  const Run now = run(/*deterministic=*/true);
  const Run later = run(/*deterministic=*/false);
  ASSERT_GT(now.initialised_at, 0);
  EXPECT_EQ(later.initialised_at, now.initialised_at);
  // The reference frame and the frames between, all of them posed (noise-free data).
  ASSERT_GE(now.before.size(), 3u);
  ASSERT_EQ(later.before.size(), now.before.size());
  for (size_t i = 0; i < now.before.size(); ++i) {
    EXPECT_EQ(later.before[i].seq, now.before[i].seq);
    EXPECT_LT((later.before[i].world_from_camera.translation() -
               now.before[i].world_from_camera.translation())
                  .norm(),
              1e-6);
  }
  EXPECT_LT(ComputeAte(later.before).rmse, 1e-3);
  EXPECT_EQ(later.stats.frames_tracked, later.with_pose);
  EXPECT_EQ(later.stats.frames_tracked + later.stats.frames_lost +
                (now.initialised_at - static_cast<int64_t>(now.before.size())),
            static_cast<int64_t>(n));
}

TEST(SystemApi, ShutdownWithFramesStillQueuedIsCleanAndIdempotent) {
  Options options = DefaultOptions(Sequence().camera);
  options.deterministic = false;
  options.input_queue_capacity = 4;
  auto created = System::Create(options);
  ASSERT_TRUE(created.ok());
  std::unique_ptr<System> system = std::move(created.value());
  const auto& frames = Sequence().frames;
  for (const Frame& f : frames) system->Submit(f);  // far faster than tracking: drops
  // One result is out (returns as soon as it is; the bound only guards a hung tracker), the
  // rest may still be queued.
  TrackResult first;
  ASSERT_TRUE(system->WaitForResult(&first, /*timeout_s=*/60.0));
  system->Shutdown();
  system->Shutdown();
  const SystemStats stats = system->Stats();
  EXPECT_EQ(stats.frames_submitted, static_cast<int64_t>(frames.size()));
  EXPECT_GT(stats.frames_dropped_queue, 0);
  // Every frame is taken or dropped at most once; the ones still queued at Shutdown are neither.
  EXPECT_GT(stats.frames_processed, 0);
  EXPECT_LE(stats.frames_processed + stats.frames_dropped_queue, stats.frames_submitted);
  EXPECT_LE(stats.frames_tracked + stats.frames_lost, stats.frames_processed);
  system->Submit(frames[0]);  // ignored after shutdown
  EXPECT_EQ(system->Stats().frames_submitted, static_cast<int64_t>(frames.size()));
  EXPECT_EQ(system->Track(frames[1]).state, TrackingState::kRejected);
}

}  // namespace
}  // namespace m2s::slam
