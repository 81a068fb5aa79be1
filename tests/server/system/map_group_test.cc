// Map groups: several agents on one shared map. References: the generated ground truth (one
// Sim3 for all agents' poses together, computed by slam_sim.h independently of the library) and
// the known layout of each run (who saw what first).
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "slam_sim.h"

namespace m2s::slam::testing {
namespace {

constexpr double kFps = 30.0;

bool Posed(const TrajectoryEntry& e) {
  return e.state == TrackingState::kOk || e.state == TrackingState::kRelocalized;
}

// A head-motion walk through the default room; `reverse` walks it backwards in time (the same
// places in the opposite direction).
std::vector<Frame> Walk(uint64_t seed, double duration_s, bool reverse = false) {
  SimOptions sim;
  sim.fps = kFps;
  sim.duration_s = duration_s;
  sim.seed = seed;
  sim.budget = 600;
  HeadMotionOptions motion = DefaultHeadMotionOptions();
  motion.duration_s = duration_s;
  motion.rate_hz = kFps;
  motion.seed = seed;
  auto walk = GenerateHeadMotion(motion);
  EXPECT_TRUE(walk.ok()) << walk.error();
  std::vector<TimedPose> poses = walk->poses();
  if (reverse) {
    std::vector<TimedPose> backwards;
    for (size_t i = poses.size(); i-- > 0;) {
      backwards.push_back({poses[poses.size() - 1 - i].timestamp, poses[i].world_from_camera});
    }
    poses = backwards;
  }
  auto trajectory = Trajectory::FromPoses(std::move(poses));
  EXPECT_TRUE(trajectory.ok()) << trajectory.error();
  return ProjectFrames(DefaultScene(), *trajectory, Camera(), sim);
}

std::shared_ptr<MapGroup> MakeGroup(bool deterministic = true) {
  Options options = DefaultOptions(Camera());
  options.deterministic = deterministic;
  auto group = MapGroup::Create(options);
  EXPECT_TRUE(group.ok()) << group.error();
  return *group;
}

std::unique_ptr<System> JoinGroup(MapGroup& group) {
  auto agent = group.Join();
  EXPECT_TRUE(agent.ok()) << agent.error();
  return std::move(*agent);
}

// Every agent's posed frames in the group's map, for one common alignment.
std::vector<TrajectoryEntry> GroupMapPoses(const std::vector<System*>& agents) {
  std::vector<TrajectoryEntry> all;
  for (System* agent : agents) {
    for (const TrajectoryEntry& e : agent->Trajectory()) {
      if (Posed(e) && e.map_id == 0) all.push_back(e);
    }
  }
  return all;
}

int CountLost(const System& agent) {
  int lost = 0;
  for (const TrajectoryEntry& e : agent.Trajectory()) lost += e.state == TrackingState::kLost;
  return lost;
}

TEST(MapGroup, TwoAgentsWalkingInOppositeDirectionsBuildOneMapInOneFrame) {
  const std::vector<Frame> a_frames = Walk(/*seed=*/4, /*duration_s=*/8.0);
  const std::vector<Frame> b_frames = Walk(/*seed=*/4, /*duration_s=*/8.0, /*reverse=*/true);
  std::shared_ptr<MapGroup> group = MakeGroup();
  std::unique_ptr<System> a = JoinGroup(*group);
  std::unique_ptr<System> b = JoinGroup(*group);
  for (size_t i = 0; i < a_frames.size(); ++i) {
    a->Track(a_frames[i]);
    b->Track(b_frames[i]);
  }
  // B starts where A ends. B initialises the group's map first (A's start needs more
  // parallax); A builds a map of its own, which merges into the group's when the walks meet.
  EXPECT_EQ(b->Stats().frames_in_unmerged_maps, 0);
  EXPECT_EQ(a->Stats().frames_in_unmerged_maps, 0);
  EXPECT_EQ(CountLost(*a), 0);
  EXPECT_EQ(CountLost(*b), 0);
  const GroupStats stats = group->Stats();
  EXPECT_EQ(stats.agents_active, 2);
  EXPECT_EQ(stats.merges, 1);
  ASSERT_EQ(stats.merge_ms.size(), 1u);

  const std::vector<TrajectoryEntry> joint = GroupMapPoses({a.get(), b.get()});
  const AteResult ate = ComputeAte(joint);
  EXPECT_LT(ate.rmse, 1e-3);
  // Alone, A initialises at frame 49 and B at frame 10: the group costs neither any frame.
  EXPECT_GE(ate.num_poses, 2 * a_frames.size() - 60);
  std::printf("two agents: joint ATE %.3g m over %zu of %zu poses, merge %.1f ms\n", ate.rmse,
              ate.num_poses, 2 * a_frames.size(), stats.merge_ms[0]);
}

TEST(MapGroup, ALateJoinerLocalisesInTheGroupsMapWithoutInitialising) {
  const std::vector<Frame> a_frames = Walk(/*seed=*/2, /*duration_s=*/5.0);
  std::shared_ptr<MapGroup> group = MakeGroup();
  std::unique_ptr<System> a = JoinGroup(*group);
  for (const Frame& f : a_frames) a->Track(f);
  const int keyframes_before = group->Stats().keyframes;

  // The late joiner walks where A walked.
  std::unique_ptr<System> b = JoinGroup(*group);
  const TrackResult first = b->Track(a_frames[60]);
  EXPECT_EQ(first.state, TrackingState::kRelocalized);
  EXPECT_EQ(first.map_id, 0);
  ASSERT_TRUE(a_frames[60].ground_truth_world_from_camera.has_value());
  for (size_t i = 61; i < 120; ++i) {
    Frame f = a_frames[i];
    f.seq = static_cast<int64_t>(i);
    const TrackResult r = b->Track(f);
    EXPECT_TRUE(r.state == TrackingState::kOk || r.state == TrackingState::kRelocalized) << i;
  }
  EXPECT_EQ(b->Stats().maps_created, 1);  // never a map of its own
  EXPECT_EQ(group->Stats().merges, 0);
  const AteResult ate = ComputeAte(GroupMapPoses({a.get(), b.get()}));
  EXPECT_LT(ate.rmse, 1e-3);
  EXPECT_GE(group->Stats().keyframes, keyframes_before);
}

TEST(MapGroup, AnAgentThatLeavesKeepsItsKeyframesInTheMapAndRejoins) {
  const std::vector<Frame> frames = Walk(/*seed=*/5, /*duration_s=*/6.0);
  std::shared_ptr<MapGroup> group = MakeGroup();
  std::unique_ptr<System> a = JoinGroup(*group);
  for (const Frame& f : frames) a->Track(f);
  const GroupStats before = group->Stats();
  ASSERT_GT(before.keyframes, 2);
  a->Shutdown();
  a.reset();
  const GroupStats after = group->Stats();
  EXPECT_EQ(after.agents_active, 0);
  EXPECT_EQ(after.agents_joined, 1);
  EXPECT_EQ(after.keyframes, before.keyframes);
  EXPECT_EQ(after.map_points, before.map_points);

  std::unique_ptr<System> again = JoinGroup(*group);
  const TrackResult r = again->Track(frames[100]);
  EXPECT_EQ(r.state, TrackingState::kRelocalized);
  EXPECT_EQ(again->Stats().maps_created, 1);
}

// Frames [first, first + count) of `walk`, numbered from 0 (an agent that starts there).
std::vector<Frame> Window(const std::vector<Frame>& walk, size_t first, size_t count) {
  std::vector<Frame> out(walk.begin() + static_cast<std::ptrdiff_t>(first),
                         walk.begin() + static_cast<std::ptrdiff_t>(first + count));
  for (size_t i = 0; i < out.size(); ++i) out[i].seq = static_cast<int64_t>(i);
  return out;
}

TEST(MapGroup, FourAgentsStartingAlongOnePathEndInOneMap) {
  // Each agent starts 1 s further along the same path: where it starts, no one has mapped
  // yet; the agents behind it arrive there later.
  const std::vector<Frame> walk = Walk(/*seed=*/11, /*duration_s=*/8.0);
  std::shared_ptr<MapGroup> group = MakeGroup();
  std::vector<std::vector<Frame>> windows;
  std::vector<std::unique_ptr<System>> agents;
  for (size_t k = 0; k < 4; ++k) {
    windows.push_back(Window(walk, k * 30, 120));
    agents.push_back(JoinGroup(*group));
  }
  for (size_t i = 0; i < 120; ++i) {
    for (size_t k = 0; k < agents.size(); ++k) agents[k]->Track(windows[k][i]);
  }
  std::vector<System*> raw;
  for (auto& agent : agents) {
    raw.push_back(agent.get());
    EXPECT_EQ(agent->Stats().frames_in_unmerged_maps, 0);
    EXPECT_EQ(agent->Stats().current_map, 0);
    EXPECT_EQ(CountLost(*agent), 0);
  }
  const AteResult ate = ComputeAte(GroupMapPoses(raw));
  EXPECT_LT(ate.rmse, 1e-3);
  std::printf("four agents: joint ATE %.3g m over %zu of %d poses, %lld merges\n", ate.rmse,
              ate.num_poses, 4 * 120, static_cast<long long>(group->Stats().merges));
}

TEST(MapGroup, EachAgentGetsTheSharedMapsDeltasWithItsOwnKeyframesMarked) {
  const std::vector<Frame> frames = Walk(/*seed=*/6, /*duration_s=*/5.0);
  std::shared_ptr<MapGroup> group = MakeGroup();
  std::unique_ptr<System> a = JoinGroup(*group);
  for (size_t i = 0; i < 90; ++i) a->Track(frames[i]);
  std::unique_ptr<System> b = JoinGroup(*group);
  for (size_t i = 90; i < frames.size(); ++i) {
    a->Track(frames[i]);
    Frame f = frames[i];
    b->Track(f);
  }
  const MapDelta a_delta = a->TakeMapDelta();
  const MapDelta b_delta = b->TakeMapDelta();
  // Both are the whole shared map (first deltas), with the same points and keyframes.
  EXPECT_TRUE(a_delta.full);
  EXPECT_TRUE(b_delta.full);
  EXPECT_EQ(a_delta.point_ids, b_delta.point_ids);
  ASSERT_EQ(a_delta.keyframes.size(), b_delta.keyframes.size());
  int a_own = 0, b_own = 0;
  for (size_t i = 0; i < a_delta.keyframes.size(); ++i) {
    EXPECT_EQ(a_delta.keyframes[i].id, b_delta.keyframes[i].id);
    EXPECT_NE(a_delta.keyframes[i].own, b_delta.keyframes[i].own) << "one owner per keyframe";
    a_own += a_delta.keyframes[i].own;
    b_own += b_delta.keyframes[i].own;
  }
  EXPECT_GT(a_own, 0);
  EXPECT_GT(b_own, 0);
  // Later deltas are incremental and agree with the map.
  for (size_t i = 0; i < 30; ++i) {
    Frame f = frames[frames.size() - 1 - i];
    f.seq = static_cast<int64_t>(frames.size() + i);
    f.timestamp = frames.back().timestamp + (i + 1) / kFps;
    a->Track(f);
  }
  const MapDelta b_next = b->TakeMapDelta();
  EXPECT_FALSE(b_next.full);
  EXPECT_EQ(b_next.base_revision, b_delta.revision);
  EXPECT_EQ(b_next.revision, a->Stats().map_revision);
}

TEST(MapGroup, FramesOfOneGroupNeverChangeAnothersMap) {
  const std::vector<Frame> frames = Walk(/*seed=*/7, /*duration_s=*/4.0);
  std::shared_ptr<MapGroup> one = MakeGroup();
  std::shared_ptr<MapGroup> two = MakeGroup();
  std::unique_ptr<System> a = JoinGroup(*one);
  std::unique_ptr<System> b = JoinGroup(*two);
  for (const Frame& f : frames) a->Track(f);
  EXPECT_GT(one->Stats().keyframes, 2);
  EXPECT_EQ(two->Stats().keyframes, 0);
  EXPECT_EQ(b->Stats().map_revision, 0u);
  EXPECT_TRUE(b->Trajectory().empty());
}

TEST(MapGroup, ASavedGroupMapServesAnotherGroupInLocalisationOnlyMode) {
  const std::vector<Frame> frames = Walk(/*seed=*/8, /*duration_s=*/5.0);
  std::shared_ptr<MapGroup> group = MakeGroup();
  std::unique_ptr<System> a = JoinGroup(*group);
  for (const Frame& f : frames) a->Track(f);
  const std::string path = ::testing::TempDir() + "/map_group_test.m2smap";
  ASSERT_TRUE(group->SaveMap(path).ok());
  // Loading into a group with an active agent is refused.
  EXPECT_FALSE(group->LoadMap(path).ok());

  std::shared_ptr<MapGroup> anchor = MakeGroup();
  ASSERT_TRUE(anchor->LoadMap(path).ok()) << anchor->LoadMap(path).message();
  const GroupStats loaded = anchor->Stats();
  EXPECT_TRUE(loaded.localization_only);
  EXPECT_EQ(loaded.keyframes, group->Stats().keyframes);
  std::unique_ptr<System> b = JoinGroup(*anchor);
  for (size_t i = 30; i < frames.size(); ++i) {
    Frame f = frames[i];
    const TrackResult r = b->Track(f);
    EXPECT_TRUE(r.state == TrackingState::kOk || r.state == TrackingState::kRelocalized) << i;
  }
  EXPECT_EQ(anchor->Stats().keyframes, loaded.keyframes);  // never changed
  EXPECT_EQ(anchor->Stats().map_points, loaded.map_points);
  std::remove(path.c_str());
}

TEST(MapGroup, AResumedMapIsExtendedInTheSameWorld) {
  // A server maps the first half of a walk and saves; a restarted one resumes the map and an
  // agent walks the second half: it relocalises in the saved map and extends it, and its poses
  // continue the first agent's in one world.
  const std::vector<Frame> walk = Walk(/*seed=*/10, /*duration_s=*/8.0);
  const std::vector<Frame> first_half = Window(walk, 0, 130);
  const std::vector<Frame> second_half = Window(walk, 110, 130);
  const std::string path = ::testing::TempDir() + "/map_group_resume_test.m2smap";
  std::vector<TrajectoryEntry> before;
  int saved_keyframes = 0;
  {
    std::shared_ptr<MapGroup> group = MakeGroup();
    std::unique_ptr<System> a = JoinGroup(*group);
    for (const Frame& f : first_half) a->Track(f);
    before = a->Trajectory();
    ASSERT_TRUE(group->SaveMap(path).ok());
    saved_keyframes = group->Stats().keyframes;
  }
  std::shared_ptr<MapGroup> restarted = MakeGroup();
  ASSERT_TRUE(restarted->ResumeMap(path).ok());
  EXPECT_FALSE(restarted->Stats().localization_only);
  std::unique_ptr<System> b = JoinGroup(*restarted);
  const TrackResult first = b->Track(second_half[0]);
  EXPECT_EQ(first.state, TrackingState::kRelocalized);
  for (size_t i = 1; i < second_half.size(); ++i) b->Track(second_half[i]);
  EXPECT_EQ(CountLost(*b), 0);
  EXPECT_EQ(b->Stats().maps_created, 1);
  EXPECT_GT(restarted->Stats().keyframes, saved_keyframes);  // extended
  std::vector<TrajectoryEntry> joint = b->Trajectory();
  for (const TrajectoryEntry& e : before) {
    if (Posed(e)) joint.push_back(e);
  }
  const AteResult ate = ComputeAte(joint);
  EXPECT_LT(ate.rmse, 1e-3);
  std::remove(path.c_str());
}

TEST(MapGroup, MapsInItsOwnMappingThreadWithTwoAgentsSubmittingConcurrently) {
  // B walks A's path one second behind it.
  const std::vector<Frame> walk = Walk(/*seed=*/9, /*duration_s=*/6.0);
  const std::vector<Frame> a_frames = Window(walk, 0, 150);
  const std::vector<Frame> b_frames = Window(walk, 30, 150);
  std::shared_ptr<MapGroup> group = MakeGroup(/*deterministic=*/false);
  std::unique_ptr<System> a = JoinGroup(*group);
  std::unique_ptr<System> b = JoinGroup(*group);
  auto run = [](System* agent, const std::vector<Frame>* frames) {
    for (const Frame& f : *frames) {
      agent->Submit(f);
      TrackResult r;
      ASSERT_TRUE(agent->WaitForResult(&r, 60.0));
      if (r.keyframe_created) {
        // Unpaced, tracking would outrun mapping by far (no camera is that fast): let the
        // mapping thread take the keyframe before the next frame; its mapping still runs
        // while the next frames are tracked.
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
        while (agent->Stats().mapping_queue > 0 && std::chrono::steady_clock::now() < deadline) {
          std::this_thread::yield();
        }
      }
    }
  };
  std::thread ta(run, a.get(), &a_frames);
  std::thread tb(run, b.get(), &b_frames);
  ta.join();
  tb.join();
  // Whatever the interleaving (B relocalising in A's map, or B's own map merged), both end in
  // the group's map, in one world.
  EXPECT_EQ(a->Stats().current_map, 0);
  EXPECT_EQ(b->Stats().current_map, 0);
  EXPECT_EQ(a->Stats().frames_in_unmerged_maps + b->Stats().frames_in_unmerged_maps, 0);
  const AteResult ate = ComputeAte(GroupMapPoses({a.get(), b.get()}));
  EXPECT_LT(ate.rmse, 1e-3);
  a->Shutdown();
  b->Shutdown();
  EXPECT_EQ(group->Stats().agents_active, 0);
}

}  // namespace
}  // namespace m2s::slam::testing
