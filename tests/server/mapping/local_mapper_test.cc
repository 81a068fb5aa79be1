// LocalMapper on exact synthetic data: a sequence of keyframes along a circle in a point room
// is inserted, triangulated and bundle adjusted into a consistent map close to the truth; on a
// line of keyframes with known observers, Process culls exactly the keyframes whose points
// enough others see (as many as the option asks for), one at a time, and holds the keyframes
// outside its window fixed.
#include "mapping/local_mapper.h"

#include <algorithm>
#include <map>
#include <random>

#include <gtest/gtest.h>

#include "slam_sim.h"
#include "synthetic_views.h"

namespace m2s::slam {
namespace {

// Every invariant of a map the mapper leaves: observers exist, are sorted and measure the
// point; every point has two observers; keyframe point counts are right.
void ExpectConsistent(const MapData& m) {
  std::map<KeyframeId, int> counted;
  for (const auto& [id, p] : m.points()) {
    EXPECT_GE(p.observers.size(), 2u) << "point " << id;
    EXPECT_TRUE(std::is_sorted(p.observers.begin(), p.observers.end()));
    EXPECT_TRUE(p.position.allFinite());
    for (const KeyframeId o : p.observers) {
      const Keyframe* kf = m.keyframe(o);
      ASSERT_NE(kf, nullptr) << "point " << id << " observer " << o;
      EXPECT_NE(kf->Find(id), nullptr);
      ++counted[o];
    }
  }
  for (const auto& [id, kf] : m.keyframes()) EXPECT_EQ(kf.num_points, counted[id]) << id;
}

TEST(LocalMapper, ProcessBuildsAConsistentMapOfASequence) {
  const Scene room = testing::MakePointRoom(4000);
  const Camera camera;
  constexpr int kFrames = 16;
  std::vector<Pose3> truth;
  std::vector<SortedFeatures> views;
  for (int i = 0; i < kFrames; ++i) {
    truth.push_back(testing::CirclePose(0.12 * i));
    views.push_back(testing::ObservePoints(room, camera, truth.back()));
  }
  auto position = [&](VertexId v) { return room.positions[v].cast<double>().eval(); };
  // The initial map: the first two views, their shared points at the true positions.
  InitialMap initial;
  initial.first = {0, 0.0, views[0], truth[0]};
  initial.second = {1, 0.1, views[1], truth[1]};
  for (const VertexId v : views[0].ids) {
    if (std::binary_search(views[1].ids.begin(), views[1].ids.end(), v)) {
      initial.point_ids.push_back(v);
      initial.points.push_back(position(v));
    }
  }
  Map map;
  const Options options;
  LocalMapper mapper(options.measurement(), options.mapper, options.drift, &map);
  const KeyframeId first = map.NextKeyframeId();
  mapper.InsertInitialMap(initial, first, map.NextKeyframeId());
  const size_t initial_points = initial.points.size();
  for (int i = 2; i < kFrames; ++i) {
    KeyframeCandidate c;
    c.id = map.NextKeyframeId();
    c.seq = i;
    c.timestamp = 0.1 * i;
    c.world_from_camera = truth[i];
    c.features = views[i];
    map.Read([&](const MapData& m) {
      for (const VertexId v : c.features.ids) {
        if (m.point(v) != nullptr) c.tracked_points.push_back(v);
      }
    });
    mapper.Process(c);
    ASSERT_TRUE(map.Read([&](const MapData& m) { return m.keyframe(c.id) != nullptr; }));
  }
  const MappingStats stats = mapper.stats();
  EXPECT_EQ(stats.keyframes_processed, kFrames - 2);
  // Points created count the initial ones; the keyframes triangulated a few hundred more.
  EXPECT_GT(stats.points_created, static_cast<int64_t>(initial_points) + 300);
  EXPECT_GT(stats.global_bundle_adjustments, 0);  // while the map was young
  EXPECT_GT(stats.total_local_ba_ms, 0.0);        // after
  map.Read([&](const MapData& m) {
    EXPECT_EQ(static_cast<int64_t>(m.keyframes().size()) + stats.keyframes_culled, kFrames);
    EXPECT_GT(m.points().size(), initial_points + 300);
    ExpectConsistent(m);
    // Exact views: the poses and points stay at the truth (the first keyframe holds the gauge).
    for (const auto& [id, kf] : m.keyframes()) {
      EXPECT_LT((kf.world_from_camera.translation() - truth[id].translation()).norm(), 1e-6);
    }
    for (const auto& [id, p] : m.points()) EXPECT_LT((p.position - position(id)).norm(), 1e-5);
  });
}

// Keyframes 0..11 on a line (x = 0.1 k) see 60 points; 5 and 6 see 30 more that no one else
// sees. Keyframe 12 then maps the 60 points again.
struct Line {
  static constexpr int kShared = 60;
  static constexpr int kPair = 30;
  Camera camera;
  std::vector<Eigen::Vector3d> points;  // ids 0..89
  Map map;
  KeyframeCandidate newest;

  Pose3 PoseOf(KeyframeId k) const {
    return Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * k, 0.0, 0.0));
  }
  SortedFeatures View(KeyframeId k) const {
    SortedFeatures f;
    const Pose3 camera_from_world = PoseOf(k).Inverse();
    const int count = (k == 5 || k == 6) ? kShared + kPair : kShared;
    for (int v = 0; v < count; ++v) {
      f.ids.push_back(static_cast<VertexId>(v));
      f.uvs.push_back(camera.Project(camera_from_world * points[v]));
    }
    return f;
  }

  Line() {
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> x(-0.4, 1.6), y(-0.8, 0.8), shared_z(3.0, 5.0);
    for (int v = 0; v < kShared + kPair; ++v) {
      // The pair's points are nearer, so that 5 and 6 (10 cm apart) see them with parallax.
      const double z = v < kShared ? shared_z(rng) : 2.0;
      points.emplace_back(v < kShared ? x(rng) : 0.55 + 0.3 * y(rng), y(rng), z);
    }
    map.Write([&](MapData& m) {
      for (KeyframeId k = 0; k < 12; ++k) {
        Keyframe kf;
        kf.id = k;
        kf.world_from_camera = PoseOf(k);
        const SortedFeatures f = View(k);
        kf.ids = f.ids;
        kf.uvs = f.uvs;
        m.AddKeyframe(std::move(kf));
      }
      for (int v = 0; v < kShared + kPair; ++v) {
        const auto id = static_cast<VertexId>(v);
        m.AddPoint(id, points[v], v < kShared ? 0 : 5);
        for (KeyframeId k = 0; k < 12; ++k) {
          if (v < kShared || k == 5 || k == 6) m.AddObservation(id, k);
        }
      }
    });
    for (int k = 0; k < 12; ++k) map.NextKeyframeId();
    newest.id = map.NextKeyframeId();
    newest.world_from_camera = PoseOf(newest.id);
    newest.features = View(newest.id);
    for (int v = 0; v < kShared; ++v) newest.tracked_points.push_back(static_cast<VertexId>(v));
  }
};

TEST(LocalMapper, ProcessCullsTheKeyframesOthersSeeWellEnoughOneAtATime) {
  Line line;
  Options options;  // keyframe_redundancy 1.0: every point seen by 3 others
  options.mapper.keyframe_redundancy_observers = 3;
  LocalMapper mapper(options.measurement(), options.mapper, options.drift, &line.map);
  const Pose3 first_before =
      line.map.Read([](const MapData& m) { return m.keyframe(0)->world_from_camera; });
  mapper.Process(line.newest);
  std::vector<KeyframeId> kept;
  line.map.Read([&](const MapData& m) {
    for (const auto& [id, kf] : m.keyframes()) kept.push_back(id);
    ExpectConsistent(m);
    // Keyframe 0 was outside the local window (12 keyframes: 12 and 11..1): held fixed.
    EXPECT_EQ(m.keyframe(0)->world_from_camera.translation(), first_before.translation());
    EXPECT_EQ(m.keyframe(0)->world_from_camera.rotation().coeffs(),
              first_before.rotation().coeffs());
  });
  // Examined newest neighbour first (11, 10, ...): each goes while every one of its points
  // keeps three other observers. 5 and 6 see points only they see: kept. The first keyframe
  // and the newest are never culled. 4..1 go while 0, 5, 6 and 12 remain.
  EXPECT_EQ(kept, (std::vector<KeyframeId>{0, 5, 6, 12}));
  EXPECT_EQ(mapper.stats().keyframes_culled, 9);
  // The culled keyframes stay resolvable.
  line.map.Read([&](const MapData& m) {
    for (KeyframeId k = 1; k < 12; ++k) {
      const std::optional<Pose3> pose = m.ResolveKeyframePose(k);
      ASSERT_TRUE(pose.has_value()) << k;
      EXPECT_LT((pose->translation() - line.PoseOf(k).translation()).norm(), 1e-6) << k;
    }
  });
}

TEST(LocalMapper, KeyframesStayUntilTheirPointsHaveEnoughOtherObservers) {
  // The 60 shared points have 13 observers after the newest keyframe. Asking for 8 others,
  // culling (newest neighbour first) removes 11, 10, 9, 8 and 7, after which each of them
  // has 7 others; 5 and 6 keep their own points.
  Line eight;
  Options options;
  options.mapper.keyframe_redundancy_observers = 8;
  LocalMapper mapper(options.measurement(), options.mapper, options.drift, &eight.map);
  mapper.Process(eight.newest);
  std::vector<KeyframeId> kept;
  eight.map.Read([&](const MapData& m) {
    for (const auto& [id, kf] : m.keyframes()) kept.push_back(id);
    ExpectConsistent(m);
  });
  EXPECT_EQ(kept, (std::vector<KeyframeId>{0, 1, 2, 3, 4, 5, 6, 12}));
  EXPECT_EQ(mapper.stats().keyframes_culled, 5);
  // The default asks for 20 others: all 13 keyframes stay.
  Line all;
  const Options defaults;
  LocalMapper keeper(defaults.measurement(), defaults.mapper, defaults.drift, &all.map);
  keeper.Process(all.newest);
  EXPECT_EQ(keeper.stats().keyframes_culled, 0);
  EXPECT_EQ(all.map.Read([](const MapData& m) { return m.keyframes().size(); }), 13u);
}

TEST(LocalMapper, NothingIsCulledWhileTheMapIsYoung) {
  Line line;
  line.map.Write([](MapData& m) {
    for (KeyframeId k = 7; k < 12; ++k) m.RemoveKeyframe(k, std::nullopt);
  });
  const Options options;
  LocalMapper mapper(options.measurement(), options.mapper, options.drift, &line.map);
  mapper.Process(line.newest);  // 8 keyframes
  EXPECT_EQ(mapper.stats().keyframes_culled, 0);
  EXPECT_EQ(line.map.Read([](const MapData& m) { return m.keyframes().size(); }), 8u);
}

}  // namespace
}  // namespace m2s::slam
