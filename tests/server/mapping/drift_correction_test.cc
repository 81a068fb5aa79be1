// Drift correction on a loop: a map built along a circle of keyframes with a growing Sim3 drift
// (locally consistent, like a drifting SLAM estimate). The last keyframe re-observes points of
// the first ones. Each of DriftCorrector::Check's outcomes is made by the loop's data: no drift
// (kAgree), drift (kCorrected, and the trajectory error shrinks), re-observed points no recent
// keyframe measured (kDeferred), and recent measurements that triangulate nothing
// (kInconclusive); the mapper merges the re-observations unless the check was deferred.
#include <cmath>
#include <random>
#include <tuple>

#include <gtest/gtest.h>

#include "m2s/common/alignment.h"
#include "mapping/drift_corrector.h"
#include "mapping/local_mapper.h"
#include "slam_sim.h"
#include "synthetic_views.h"

namespace m2s::slam {
namespace {

constexpr int kKeyframes = 40;
constexpr double kTurn = 2.0 * M_PI + 0.6;  // a bit more than one turn

// The drift accumulated at keyframe i, scaled by `amount` (0: none).
Sim3 Drift(int i, double amount) {
  const double f = amount * static_cast<double>(i) / kKeyframes;
  return Sim3(
      1.0 + 0.03 * f,
      Eigen::Quaterniond(Eigen::AngleAxisd(4.0 * M_PI / 180.0 * f, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(0.06 * f, 0.03 * f, 0.0));
}

// What the keyframes between the first quarter and the loop's end measure of the points first
// seen in the first quarter (the points the loop's end re-observes).
enum class RecentViews {
  kExact,      // their projections
  kNone,       // nothing: only the loop's end sees them again
  kScrambled,  // projections moved by tens of pixels: nothing triangulates from them
};

struct Loop {
  std::vector<Pose3> truth;     // keyframes 0..kKeyframes
  KeyframeCandidate candidate;  // keyframe kKeyframes
};

// Writes keyframes 0..kKeyframes-1 (drifted by `drift`) and their points into `map`, and
// returns the loop's end as tracking would hand it over: points unseen for more than
// drift.min_keyframe_gap keyframes are dormant.
Loop BuildLoop(const Options& options, double drift, RecentViews recent, Map* map) {
  static const Scene room = testing::MakePointRoom(8000);
  Loop loop;
  std::vector<SortedFeatures> features;
  for (int i = 0; i <= kKeyframes; ++i) {
    loop.truth.push_back(testing::CirclePose(kTurn * i / kKeyframes));
    features.push_back(testing::ObservePoints(room, options.camera, loop.truth.back()));
  }
  std::vector<int> first_seen(room.positions.size(), -1);
  for (int i = 0; i < kKeyframes; ++i) {
    for (const VertexId v : features[i].ids) {
      if (first_seen[v] < 0) first_seen[v] = i;
    }
  }
  // The second half of the loop does not observe points first seen in the first quarter (they
  // become dormant); what it measures of them is `recent`.
  auto old_point = [&](VertexId v) { return first_seen[v] >= 0 && first_seen[v] < kKeyframes / 4; };
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> shift(-40.0, 40.0);
  for (int i = kKeyframes / 2; i < kKeyframes; ++i) {
    SortedFeatures kept;
    for (size_t k = 0; k < features[i].size(); ++k) {
      const VertexId v = features[i].ids[k];
      Eigen::Vector2d uv = features[i].uvs[k];
      if (old_point(v) && recent == RecentViews::kNone) continue;
      if (old_point(v) && recent == RecentViews::kScrambled)
        uv += Eigen::Vector2d(shift(rng), shift(rng));
      kept.ids.push_back(v);
      kept.uvs.push_back(uv);
    }
    features[i] = std::move(kept);
  }
  map->Write([&](MapData& m) {
    for (int i = 0; i < kKeyframes; ++i) {
      Keyframe kf;
      kf.id = static_cast<KeyframeId>(i);
      kf.seq = i;
      kf.timestamp = i;
      kf.world_from_camera = Drift(i, drift).TransformPose(loop.truth[i]);
      kf.ids = features[i].ids;
      kf.uvs = features[i].uvs;
      m.AddKeyframe(std::move(kf));
    }
    for (size_t v = 0; v < room.positions.size(); ++v) {
      const int first = first_seen[v];
      if (first < 0) continue;
      std::vector<KeyframeId> observers;
      for (int i = first; i < kKeyframes; ++i) {
        if (i >= kKeyframes / 2 && old_point(static_cast<VertexId>(v))) continue;
        if (std::binary_search(features[i].ids.begin(), features[i].ids.end(),
                               static_cast<VertexId>(v))) {
          observers.push_back(static_cast<KeyframeId>(i));
        }
      }
      if (observers.size() < 2) continue;
      m.AddPoint(static_cast<VertexId>(v), Drift(first, drift) * room.positions[v].cast<double>(),
                 first);
      for (const KeyframeId o : observers) m.AddObservation(static_cast<VertexId>(v), o);
    }
  });
  for (int i = 0; i < kKeyframes; ++i) map->NextKeyframeId();

  KeyframeCandidate& c = loop.candidate;
  c.id = map->NextKeyframeId();
  c.seq = kKeyframes;
  c.timestamp = kKeyframes;
  c.world_from_camera = Drift(kKeyframes, drift).TransformPose(loop.truth[kKeyframes]);
  c.features = features[kKeyframes];
  map->Read([&](const MapData& m) {
    for (const VertexId v : c.features.ids) {
      const MapPoint* p = m.point(v);
      if (p == nullptr) continue;
      if (static_cast<int>(p->last_observer()) < kKeyframes - options.drift.min_keyframe_gap) {
        c.dormant_points.push_back(v);
      } else {
        c.tracked_points.push_back(v);
      }
    }
  });
  EXPECT_GE(static_cast<int>(c.dormant_points.size()), options.drift.min_points);
  return loop;
}

// The candidate as LocalMapper inserts it before the drift check.
void InsertCandidate(const KeyframeCandidate& c, Map* map) {
  map->Write([&](MapData& m) {
    Keyframe kf;
    kf.id = c.id;
    kf.seq = c.seq;
    kf.timestamp = c.timestamp;
    kf.world_from_camera = c.world_from_camera;
    kf.ids = c.features.ids;
    kf.uvs = c.features.uvs;
    m.AddKeyframe(std::move(kf));
    for (const VertexId id : c.tracked_points) m.AddObservation(id, c.id);
  });
}

// The outcome of the candidate's drift check, and whether it corrected the map.
DriftOutcome CheckLoop(double drift, RecentViews recent, uint64_t* epochs_published = nullptr) {
  Options options;
  Map map;
  const Loop loop = BuildLoop(options, drift, recent, &map);
  InsertCandidate(loop.candidate, &map);
  DriftCorrector corrector(options.measurement(), options.drift, &map);
  const uint64_t epoch = map.correction().epoch;
  const DriftOutcome outcome = corrector.Check(loop.candidate.id, loop.candidate.dormant_points);
  if (epochs_published != nullptr) *epochs_published = map.correction().epoch - epoch;
  return outcome;
}

// How many of the candidate's dormant points it observes after LocalMapper::Process.
int MergedDormantPoints(const Map& map, const KeyframeCandidate& c) {
  int merged = 0;
  map.Read([&](const MapData& m) {
    for (const VertexId v : c.dormant_points) {
      const MapPoint* p = m.point(v);
      if (p != nullptr && std::binary_search(p->observers.begin(), p->observers.end(), c.id)) {
        ++merged;
      }
    }
  });
  return merged;
}

double KeyframeAte(const Map& map, const std::vector<Pose3>& truth) {
  std::vector<Eigen::Vector3d> est, gt;
  map.Read([&](const MapData& m) {
    for (const auto& [id, kf] : m.keyframes()) {
      est.push_back(kf.world_from_camera.translation());
      gt.push_back(truth[id].translation());
    }
  });
  const auto s = AlignPoints(est, gt, true);
  double sse = 0;
  for (size_t i = 0; i < est.size(); ++i) sse += ((*s) * est[i] - gt[i]).squaredNorm();
  return std::sqrt(sse / static_cast<double>(est.size()));
}

TEST(DriftCorrection, LoopClosureShrinksTheTrajectoryError) {
  Options options;
  Map map;
  const Loop loop = BuildLoop(options, /*drift=*/1.0, RecentViews::kExact, &map);
  const double before = KeyframeAte(map, loop.truth);
  LocalMapper mapper(options.measurement(), options.mapper, options.drift, &map);
  const uint64_t epoch = map.correction().epoch;
  mapper.Process(loop.candidate);
  const double after = KeyframeAte(map, loop.truth);
  std::printf("keyframe ATE before %.4f m, after %.4f m (%zu dormant points)\n", before, after,
              loop.candidate.dormant_points.size());
  EXPECT_EQ(mapper.stats().loop_corrections, 1);
  EXPECT_GT(map.correction().epoch, epoch);  // the tracker is told
  EXPECT_LT(after, 0.5 * before);
  // The dormant points are ordinary observations now.
  map.Read([&](const MapData& m) {
    for (const VertexId v : loop.candidate.dormant_points) {
      const MapPoint* p = m.point(v);
      if (p != nullptr) {
        EXPECT_EQ(p->last_observer(), loop.candidate.id);
      }
    }
  });
}

TEST(DriftCorrection, DriftIsCorrected) {
  uint64_t epochs = 0;
  EXPECT_EQ(CheckLoop(/*drift=*/1.0, RecentViews::kExact, &epochs), DriftOutcome::kCorrected);
  EXPECT_EQ(epochs, 1u);
}

TEST(DriftCorrection, AnUndriftedLoopAgreesInTheImage) {
  uint64_t epochs = 0;
  EXPECT_EQ(CheckLoop(/*drift=*/0.0, RecentViews::kExact, &epochs), DriftOutcome::kAgree);
  EXPECT_EQ(epochs, 0u);  // nothing moved
}

TEST(DriftCorrection, PointsNoRecentKeyframeMeasuredAreDeferred) {
  uint64_t epochs = 0;
  EXPECT_EQ(CheckLoop(/*drift=*/1.0, RecentViews::kNone, &epochs), DriftOutcome::kDeferred);
  EXPECT_EQ(epochs, 0u);
}

TEST(DriftCorrection, RecentViewsThatTriangulateNothingAreInconclusive) {
  uint64_t epochs = 0;
  EXPECT_EQ(CheckLoop(/*drift=*/1.0, RecentViews::kScrambled, &epochs),
            DriftOutcome::kInconclusive);
  EXPECT_EQ(epochs, 0u);
}

// The mapper merges the re-observed points unless the check was deferred (no recent keyframe
// measured them): agreeing and inconclusive checks merge.
TEST(DriftCorrection, MapperMergesReobservationsUnlessTheCheckIsDeferred) {
  for (const auto& [drift, recent, merges] :
       {std::tuple{0.0, RecentViews::kExact, true}, std::tuple{1.0, RecentViews::kNone, false},
        std::tuple{1.0, RecentViews::kScrambled, true}}) {
    SCOPED_TRACE(::testing::Message()
                 << "drift " << drift << ", recent views " << static_cast<int>(recent));
    Options options;
    Map map;
    const Loop loop = BuildLoop(options, drift, recent, &map);
    LocalMapper mapper(options.measurement(), options.mapper, options.drift, &map);
    mapper.Process(loop.candidate);
    const int merged = MergedDormantPoints(map, loop.candidate);
    EXPECT_EQ(mapper.stats().loop_corrections, 0);
    if (merges) {
      EXPECT_GE(merged, static_cast<int>(loop.candidate.dormant_points.size()) * 9 / 10);
    } else {
      EXPECT_EQ(merged, 0);
    }
  }
}

// Points that moved while unseen (an object carried away), not drift: the loop has no drift;
// of the old points its end sees again, those on the left of the image (40 %) are stored
// 0.3 m off, rigidly, and stay dormant; the others are tracked on (seen through the loop, as
// the walls around a moved object are) and agree. No correction; the mapper forgets the moved
// points (they reproject far off) and maps them anew.
TEST(DriftCorrection, PointsThatMovedWhileUnseenAreNotTakenForDrift) {
  Options options;
  Map map;
  Loop loop = BuildLoop(options, /*drift=*/0.0, RecentViews::kExact, &map);
  KeyframeCandidate& c = loop.candidate;
  std::vector<std::pair<double, VertexId>> by_u;
  for (const VertexId v : c.dormant_points) {
    const auto it = std::lower_bound(c.features.ids.begin(), c.features.ids.end(), v);
    by_u.emplace_back(c.features.uvs[static_cast<size_t>(it - c.features.ids.begin())].x(), v);
  }
  std::sort(by_u.begin(), by_u.end());
  c.dormant_points.clear();
  for (size_t k = 0; k < by_u.size(); ++k) {
    (k < by_u.size() * 2 / 5 ? c.dormant_points : c.tracked_points).push_back(by_u[k].second);
  }
  std::sort(c.dormant_points.begin(), c.dormant_points.end());
  std::sort(c.tracked_points.begin(), c.tracked_points.end());
  ASSERT_GE(static_cast<int>(c.dormant_points.size()), options.drift.min_points);
  map.Write([&](MapData& m) {
    for (const VertexId v : c.dormant_points) {
      m.SetPointPosition(v, m.point(v)->position + Eigen::Vector3d(0.3, 0.0, 0.0));
    }
  });
  {
    Map copy;
    copy.Write([&](MapData& m) { m = map.Read([](const MapData& d) { return d; }); });
    InsertCandidate(c, &copy);
    DriftCorrector corrector(options.measurement(), options.drift, &copy);
    EXPECT_EQ(corrector.Check(c.id, c.dormant_points), DriftOutcome::kAgree);
    EXPECT_EQ(copy.correction().epoch, 0u);
  }
  LocalMapper mapper(options.measurement(), options.mapper, options.drift, &map);
  mapper.Process(c);
  EXPECT_EQ(mapper.stats().loop_corrections, 0);
  EXPECT_EQ(MergedDormantPoints(map, c), 0);  // forgotten, not merged
  EXPECT_LT(KeyframeAte(map, loop.truth), 1e-9);
}

}  // namespace
}  // namespace m2s::slam
