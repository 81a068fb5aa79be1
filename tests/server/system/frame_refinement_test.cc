// RefineFramePose, SolveUnposedFrames, SmoothLooseFrames' frames without a pose,
// ApplyMotionPrior (server/system/trajectory_refinement.h) and KeepObservations (system_common.h):
// a tracked frame re-solved on the map its observations refer to, and frames returned without a
// pose solved on it or given the centre interpolated between tracked ones, against the known poses
// they were seen from.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "map/map.h"
#include "system/system_common.h"
#include "system/trajectory_refinement.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {
namespace {

constexpr KeyframeId kReference = 3;

MeasurementModel Model() {
  MeasurementModel m;
  m.camera = Camera::FromHorizontalFov(640, 480, 90.0);
  m.pixel_sigma = 0.5;
  return m;
}

// 300 points on a 4 m x 3 m wall 3-5 m in front of the origin (a staircase in depth), the
// points of `object` (ids kObject + i), and one keyframe at the origin.
constexpr VertexId kObject = 1000;
void MakeMap(Map* map, const std::vector<Eigen::Vector3d>& object = {}) {
  map->Write([&](MapData& m) {
    Keyframe kf;
    kf.id = kReference;
    std::vector<std::pair<VertexId, Eigen::Vector3d>> points;
    for (VertexId v = 0; v < 300; ++v) {
      points.emplace_back(v, Eigen::Vector3d(-2.0 + 4.0 * (v % 20) / 19.0,
                                             -1.5 + 3.0 * (v / 20) / 14.0, 3.0 + 0.5 * (v % 5)));
    }
    for (size_t i = 0; i < object.size(); ++i) points.emplace_back(kObject + i, object[i]);
    for (const auto& [id, p] : points) {
      kf.ids.push_back(id);
      kf.uvs.push_back(Model().camera.Project(p));
    }
    m.AddKeyframe(std::move(kf));
    for (const auto& [id, p] : points) {
      m.AddPoint(id, p, kReference);
      m.AddObservation(id, kReference);
    }
  });
}

// A 0.3 m x 0.3 m x 0.1 m object of 40 points 4 m away, right of the wall's centre.
std::vector<Eigen::Vector3d> Object() {
  std::vector<Eigen::Vector3d> object;
  for (int k = 0; k < 40; ++k) {
    object.emplace_back(1.0 + 0.1 * (k % 4), -0.2 + 0.075 * (k / 4 % 5), 4.0 + 0.1 * (k / 20));
  }
  return object;
}

// The record of a frame seen from `truth` (world_from_camera), its observations exact, its pose
// relative to the keyframe at the origin `tracked` (as tracking left it).
TrajectoryRecord SeenFrom(const Map& map, const MeasurementModel& model, const Pose3& truth,
                          const Pose3& tracked) {
  TrajectoryRecord r;
  r.state = TrackingState::kOk;
  r.reference = kReference;
  r.reference_from_camera = tracked;
  map.Read([&](const MapData& m) {
    for (const auto& [id, point] : m.points()) {
      const Eigen::Vector3d pc = truth.Inverse() * point.position;
      r.observed_ids.push_back(id);
      r.observed_uvs.push_back(model.camera.Project(pc).cast<float>());
    }
  });
  return r;
}

// The record's pose relative to the keyframe at the origin (its world pose) is `truth`. The
// pixels are floats (1e-4 px at 640 px): micrometres at 3-5 m.
void ExpectPose(const Pose3& truth, const TrajectoryRecord& r) {
  const Pose3 error = truth.Inverse() * r.reference_from_camera;
  EXPECT_LT(error.translation().norm(), 1e-5);
  EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle(), 1e-5);
}

// RefineFramePose on `map` as it is now.
bool Refine(const Map& map, const MeasurementModel& model, TrajectoryRecord* r,
            const Pose3* fallback_start = nullptr) {
  return map.Read([&](const MapData& m) { return RefineFramePose(model, m, r, fallback_start); });
}

TEST(RefineFramePose, RecoversThePoseTheFrameWasSeenFrom) {
  Map map;
  MakeMap(&map);
  const MeasurementModel model = Model();
  const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d(0.3, -0.1, 0.2));
  // Tracked 4 cm and 0.6 degrees off (as against a map that was off there).
  const Pose3 tracked =
      truth * Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitX())),
                    Eigen::Vector3d(0.03, 0.0, -0.027));
  TrajectoryRecord r = SeenFrom(map, model, truth, tracked);
  EXPECT_TRUE(Refine(map, model, &r));
  ExpectPose(truth, r);
}

// A keyframe's record follows its keyframe in the map while that pose explains the record's
// observations; a keyframe left where its observations no longer fit (the bundle adjustment
// dropped them as outliers) is re-solved like any tracked frame.
TEST(RefineFramePose, ResolvesAKeyframeOnlyWhereItsObservationsDoNotFitIt) {
  Map map;
  MakeMap(&map);
  const MeasurementModel model = Model();
  const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d(0.2, 0.1, -0.1));
  // 0.3 mm off: 0.03 px at 3-5 m, within tracking's bound.
  const Pose3 fitting = truth * Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(3e-4, 0, 0));
  TrajectoryRecord kept = SeenFrom(map, model, truth, fitting);
  kept.is_keyframe = true;
  EXPECT_FALSE(Refine(map, model, &kept));
  EXPECT_EQ(kept.reference_from_camera.translation(), fitting.translation());

  // 5 cm off: 3-5 px at 3-5 m.
  const Pose3 off = truth * Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.05, 0, 0));
  TrajectoryRecord drifted = SeenFrom(map, model, truth, off);
  drifted.is_keyframe = true;
  EXPECT_TRUE(Refine(map, model, &drifted));
  ExpectPose(truth, drifted);
}

// A frame whose own estimate the solve cannot start from (turned away from the wall: every
// point behind the camera) is solved from the start it is given (RefineMap: the frame before
// it), and left as it is without one.
TEST(RefineFramePose, StartsFromTheGivenPoseWhenItsOwnFails) {
  Map map;
  MakeMap(&map);
  const MeasurementModel model = Model();
  const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d(0.3, -0.1, 0.2));
  const Pose3 turned =
      truth * Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d::Zero());
  TrajectoryRecord alone = SeenFrom(map, model, truth, turned);
  EXPECT_FALSE(Refine(map, model, &alone));
  EXPECT_EQ(alone.reference_from_camera.translation(), turned.translation());

  // The frame before: 3 cm and 1 degree away (camera_from_world).
  const Pose3 previous =
      (truth * Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(0.017, Eigen::Vector3d::UnitX())),
                     Eigen::Vector3d(0.03, 0.0, 0.0)))
          .Inverse();
  TrajectoryRecord r = SeenFrom(map, model, truth, turned);
  EXPECT_TRUE(Refine(map, model, &r, &previous));
  ExpectPose(truth, r);
}

TEST(RefineFramePose, LeavesLostFramesAndFramesWithoutMappedObservations) {
  Map map;
  MakeMap(&map);
  const MeasurementModel model = Model();
  const Pose3 truth(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1, 0.0, 0.0));
  const Pose3 tracked(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.15, 0.0, 0.0));
  auto unchanged = [&](TrajectoryRecord r) {
    EXPECT_FALSE(Refine(map, model, &r));
    EXPECT_EQ(r.reference_from_camera.translation(), tracked.translation());
  };
  TrajectoryRecord lost = SeenFrom(map, model, truth, tracked);
  lost.state = TrackingState::kLost;
  unchanged(lost);
  TrajectoryRecord unmapped = SeenFrom(map, model, truth, tracked);
  for (VertexId& id : unmapped.observed_ids) id += 1000;  // points the map no longer has
  unchanged(unmapped);
  TrajectoryRecord none = SeenFrom(map, model, truth, tracked);
  none.observed_ids.clear();
  none.observed_uvs.clear();
  unchanged(none);
}

// A walk of 9 frames along x, 5 cm apart, looking at the wall: frames 0 and 8 tracked, the
// ones between returned lost (their features kept).
std::vector<TrajectoryRecord> LostWalk(const Map& map, const MeasurementModel& model,
                                       std::vector<Pose3>* truths) {
  std::vector<TrajectoryRecord> records;
  for (int i = 0; i < 9; ++i) {
    const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.01 * i, Eigen::Vector3d::UnitY())),
                      Eigen::Vector3d(0.05 * i, 0.0, 0.0));
    truths->push_back(truth);
    TrajectoryRecord r = SeenFrom(map, model, truth, truth);
    r.seq = i;
    if (i > 0 && i < 8) {
      r.state = TrackingState::kLost;
      r.reference.reset();
    }
    records.push_back(std::move(r));
  }
  return records;
}

class UnposedFrames : public testing::Test {
 protected:
  void SetUp() override {
    MakeMap(&map);
    records = LostWalk(map, model, &truths);
  }
  Map map;
  const MeasurementModel model = Model();
  std::vector<Pose3> truths;
  std::vector<TrajectoryRecord> records;
};

TEST_F(UnposedFrames, GivesLostFramesBetweenTwoPosesTheirTruePoses) {
  int solved = 0;
  map.Read([&](const MapData& m) { solved = SolveUnposedFrames(model, m, 0, 60, &records); });
  EXPECT_EQ(solved, 7);
  for (int i = 1; i < 8; ++i) {
    EXPECT_EQ(records[i].state, TrackingState::kOk) << i;
    ASSERT_TRUE(records[i].reference.has_value()) << i;
    EXPECT_EQ(*records[i].reference, kReference);
    // The keyframe is at the origin: the relative pose is the world pose (float pixels).
    const Pose3 error = truths[i].Inverse() * records[i].reference_from_camera;
    EXPECT_LT(error.translation().norm(), 1e-5) << i;
    EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle(), 1e-5) << i;
  }
}

TEST_F(UnposedFrames, LeavesFramesWithOneSideFewPointsOrAnUndeterminedView) {
  // Frame 8 lost too: frames 1-8 have a pose on one side only, and the map (one keyframe) is
  // young.
  records[8].state = TrackingState::kLost;
  records[8].reference.reset();
  int solved = -1;
  map.Read([&](const MapData& m) { solved = SolveUnposedFrames(model, m, 0, 60, &records); });
  EXPECT_EQ(solved, 0);
  records = LostWalk(map, model, &truths);
  // Frame 3 sees 59 map points, fewer than the 60 asked.
  auto keep = [](TrajectoryRecord* r, auto&& pred) {
    TrajectoryRecord kept = *r;
    kept.observed_ids.clear();
    kept.observed_uvs.clear();
    for (size_t k = 0; k < r->observed_ids.size(); ++k) {
      if (!pred(r->observed_ids[k])) continue;
      kept.observed_ids.push_back(r->observed_ids[k]);
      kept.observed_uvs.push_back(r->observed_uvs[k]);
    }
    *r = kept;
  };
  keep(&records[3], [](VertexId v) { return v < 59; });
  map.Read([&](const MapData& m) { solved = SolveUnposedFrames(model, m, 0, 60, &records); });
  EXPECT_EQ(solved, 6);
  EXPECT_EQ(records[3].state, TrackingState::kLost);
  // Frame 5 sees the nine points of a 0.4 m square in a corner of the wall (3-4 m deep),
  // 0.5 px off: its centre is determined to decimetres, not to 1 % of the depth.
  truths.clear();
  records = LostWalk(map, model, &truths);
  keep(&records[5], [](VertexId v) { return v % 20 < 3 && v / 20 < 3; });
  for (size_t k = 0; k < records[5].observed_uvs.size(); ++k) {
    const float off = k % 2 == 0 ? 0.35f : -0.35f;
    records[5].observed_uvs[k] += Eigen::Vector2f(off, k % 3 == 0 ? off : -off);
  }
  map.Read([&](const MapData& m) { solved = SolveUnposedFrames(model, m, 0, 4, &records); });
  EXPECT_EQ(solved, 6);
  EXPECT_EQ(records[5].state, TrackingState::kLost);
}

TEST_F(UnposedFrames, FramesBeforeTheFirstPoseOfAMatureMapAreSolvedWithAPnpSecondOpinion) {
  // Frames 0-7 lost, frame 8 tracked: a pose on one side only. The map gets four more
  // keyframes (no longer young): each frame's sweep solve is checked against PnP + RANSAC.
  for (int i = 0; i < 8; ++i) {
    records[i].state = TrackingState::kLost;
    records[i].reference.reset();
  }
  map.Write([](MapData& m) {
    for (KeyframeId id = kReference + 1; id <= kReference + 4; ++id) {
      Keyframe kf;
      kf.id = id;
      m.AddKeyframe(std::move(kf));
    }
  });
  int solved = 0;
  map.Read([&](const MapData& m) { solved = SolveUnposedFrames(model, m, 0, 60, &records); });
  EXPECT_EQ(solved, 8);
  for (int i = 0; i < 8; ++i) {
    ASSERT_EQ(records[i].state, TrackingState::kOk) << i;
    const Pose3 error = truths[i].Inverse() * records[i].reference_from_camera;
    EXPECT_LT(error.translation().norm(), 1e-5) << i;
    EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle(), 1e-5) << i;
  }
}

TEST_F(UnposedFrames, ExactObservationsOfAFewPointsFixThePose) {
  // The four corners of that square, exact (noise-free features): their pose stands, however
  // loosely 0.5 px of noise would leave it.
  records[5].observed_ids.clear();
  records[5].observed_uvs.clear();
  for (const VertexId v : {0, 2, 40, 42}) {
    records[5].observed_ids.push_back(v);
    map.Read([&](const MapData& m) {
      const Eigen::Vector3d pc = truths[5].Inverse() * m.point(v)->position;
      records[5].observed_uvs.push_back(model.camera.Project(pc).cast<float>());
    });
  }
  int solved = 0;
  map.Read([&](const MapData& m) { solved = SolveUnposedFrames(model, m, 0, 4, &records); });
  EXPECT_EQ(solved, 7);
  ASSERT_EQ(records[5].state, TrackingState::kOk);
  const Pose3 error = truths[5].Inverse() * records[5].reference_from_camera;
  EXPECT_LT(error.translation().norm(), 1e-3);
  EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle(), 1e-4);
}

TEST_F(UnposedFrames, PointsWhosePositionsAreLooseDoNotFixAPose) {
  // Frame 5 sees the 100 points of the wall's lower third, 0.35 px off (alternating): the
  // points well constrained (0.2 % of their depth), its centre is fixed; each known to 5 % of
  // its depth only (triangulated over a small baseline), the same view leaves it loose.
  auto noisy_lower_third = [&]() {
    truths.clear();
    records = LostWalk(map, model, &truths);
    TrajectoryRecord& r = records[5];
    TrajectoryRecord kept = r;
    kept.observed_ids.clear();
    kept.observed_uvs.clear();
    for (size_t k = 0; k < r.observed_ids.size(); ++k) {
      if (r.observed_ids[k] >= 100) continue;
      const float off = k % 2 == 0 ? 0.35f : -0.35f;
      kept.observed_ids.push_back(r.observed_ids[k]);
      kept.observed_uvs.push_back(r.observed_uvs[k] +
                                  Eigen::Vector2f(off, k % 3 == 0 ? off : -off));
    }
    r = kept;
  };
  auto set_uncertainty = [&](double relative) {
    map.Write([&](MapData& m) {
      for (VertexId v = 0; v < 100; ++v) m.SetPointUncertainty(v, relative, relative <= 0.01);
    });
  };
  set_uncertainty(0.002);
  noisy_lower_third();
  int solved = 0;
  map.Read([&](const MapData& m) { solved = SolveUnposedFrames(model, m, 0, 20, &records); });
  EXPECT_EQ(solved, 7);
  ASSERT_EQ(records[5].state, TrackingState::kOk);
  const Pose3 error = truths[5].Inverse() * records[5].reference_from_camera;
  EXPECT_LT(error.translation().norm(), 0.01);
  set_uncertainty(0.05);
  noisy_lower_third();
  map.Read([&](const MapData& m) { solved = SolveUnposedFrames(model, m, 0, 20, &records); });
  EXPECT_EQ(solved, 6);
  EXPECT_EQ(records[5].state, TrackingState::kLost);
}

// A walk of 31 frames at 30 fps along x (0.3 m/s, turning 3 degrees/s) past the wall and a
// 0.3 m object 4 m away (40 points), tracked with 0.5 px of noise (poses a few millimetres
// off); frames 12-18 lost, each seeing only the object. SolveUnposedFrames leaves them (its
// points do not fix their centre); SmoothLooseFrames gives them the centre interpolated
// between the tracked frames and the rotation their points fit there.
class GapFrames : public testing::Test {
 protected:
  void SetUp() override {
    MakeMap(&map, Object());
    std::mt19937 rng(7);
    std::normal_distribution<double> pixel(0.0, model.pixel_sigma), centre(0.0, 0.002);
    for (int i = 0; i < 31; ++i) {
      const Pose3 truth(
          Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * i / 30.0, Eigen::Vector3d::UnitY())),
          Eigen::Vector3d(0.01 * i, 0.0, 0.0));
      truths.push_back(truth);
      const Pose3 tracked(
          truth.rotation(),
          truth.translation() + Eigen::Vector3d(centre(rng), centre(rng), centre(rng)));
      TrajectoryRecord r = SeenFrom(map, model, truth, tracked);
      r.seq = i;
      r.timestamp = i / 30.0;
      for (Eigen::Vector2f& uv : r.observed_uvs) {
        uv += Eigen::Vector2f(static_cast<float>(pixel(rng)), static_cast<float>(pixel(rng)));
      }
      if (i >= 12 && i <= 18) {
        r.state = TrackingState::kLost;
        r.reference.reset();
        TrajectoryRecord object = r;
        object.observed_ids.clear();
        object.observed_uvs.clear();
        for (size_t k = 0; k < r.observed_ids.size(); ++k) {
          if (r.observed_ids[k] < kObject) continue;
          object.observed_ids.push_back(r.observed_ids[k]);
          object.observed_uvs.push_back(r.observed_uvs[k]);
        }
        r = object;
      }
      records.push_back(std::move(r));
    }
  }
  Map map;
  const MeasurementModel model = Model();
  std::vector<Pose3> truths;
  std::vector<TrajectoryRecord> records;
};

TEST_F(GapFrames, LostFramesBetweenTrackedOnesTakeTheInterpolatedCentre) {
  SmoothedFrames smoothed;
  map.Read([&](const MapData& m) {
    ASSERT_EQ(SolveUnposedFrames(model, m, 0, kUnposedMinPoints, &records), 0);
    smoothed = SmoothLooseFrames(model, m, 0, 600, &records);
  });
  EXPECT_EQ(smoothed.posed, 7);
  for (int i = 12; i <= 18; ++i) {
    ASSERT_EQ(records[i].state, TrackingState::kOk) << i;
    const Pose3 error = truths[i].Inverse() * records[i].reference_from_camera;
    // The tracked poses' 2 mm: their interpolation is off by about that much. The object's
    // 40 points at 0.5 px fix the rotation about the view axis to about 0.25 degrees.
    EXPECT_LT(error.translation().norm(), 0.006) << i;
    EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle() * 180.0 / M_PI, 1.0) << i;
  }
}

// The rotation given the centre needs no more points than tracking's rotation-only pose
// (kMinRotationOnlyInliers): the lost frames cut to that many of the object's points are
// posed, one fewer are not.
TEST_F(GapFrames, AsFewPointsAsARotationOnlyPoseNeeds) {
  auto cut = [&](size_t n) {
    std::vector<TrajectoryRecord> cut_records = records;
    for (int i = 12; i <= 18; ++i) {
      cut_records[i].observed_ids.resize(n);
      cut_records[i].observed_uvs.resize(n);
    }
    return cut_records;
  };
  const size_t enough = tracker_internal::kMinRotationOnlyInliers;
  std::vector<TrajectoryRecord> few = cut(enough), too_few = cut(enough - 1);
  SmoothedFrames posed, not_posed;
  map.Read([&](const MapData& m) {
    posed = SmoothLooseFrames(model, m, 0, 600, &few);
    not_posed = SmoothLooseFrames(model, m, 0, 600, &too_few);
  });
  EXPECT_EQ(posed.posed, 7);
  EXPECT_EQ(not_posed.posed, 0);
  for (int i = 12; i <= 18; ++i) {
    ASSERT_EQ(few[i].state, TrackingState::kOk) << i;
    const Pose3 error = truths[i].Inverse() * few[i].reference_from_camera;
    // The interpolation's 2 mm, as above. The 12 points span 0.3 x 0.15 m at 4 m: at 0.5 px
    // they fix the roll about the view axis to about 0.7 degrees (1 sigma; the bound: 3).
    EXPECT_LT(error.translation().norm(), 0.006) << i;
    EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle() * 180.0 / M_PI, 2.1) << i;
    EXPECT_EQ(too_few[i].state, TrackingState::kLost) << i;
  }
}

TEST_F(GapFrames, NotWhenTheInterpolationIsLoose) {
  // The tracked poses 20 cm off, alternately: the interpolation's measured deviation is above
  // 2.5 % of the object's depth.
  for (int i = 0; i < 31; ++i) {
    if (i >= 12 && i <= 18) continue;
    records[i].reference_from_camera =
        Pose3(truths[i].rotation(),
              truths[i].translation() + Eigen::Vector3d(0.0, i % 2 == 0 ? 0.2 : -0.2, 0.0));
    records[i].observed_uvs.clear();
    map.Read([&](const MapData& m) {
      for (const VertexId v : records[i].observed_ids) {
        const Eigen::Vector3d pc =
            records[i].reference_from_camera.Inverse() * m.point(v)->position;
        records[i].observed_uvs.push_back(model.camera.Project(pc).cast<float>());
      }
    });
  }
  SmoothedFrames smoothed;
  map.Read([&](const MapData& m) { smoothed = SmoothLooseFrames(model, m, 0, 600, &records); });
  EXPECT_EQ(smoothed.posed, 0);
  for (int i = 12; i <= 18; ++i) EXPECT_EQ(records[i].state, TrackingState::kLost) << i;
}

// ApplyMotionPrior: a walk of 61 frames at 30 fps curving along the wall, each frame seeing 30
// of its points (every tenth) or only a 0.3 m object 4 m away (40 points), solved alone on its
// pixels (RefineFramePose from the truth), as tracking leaves such views: with 0.5 px of noise,
// millimetres off (the wall) or centimetres (the object, a loosely determined centre),
// independently from frame to frame.
class MotionPrior : public testing::Test {
 protected:
  void SetUp() override { MakeMap(&map, Object()); }
  // The walk's records, each frame's pixels with `noise_px` of Gaussian noise.
  std::vector<TrajectoryRecord> Walk(double noise_px, bool object_only = false) {
    std::mt19937 rng(17);
    std::normal_distribution<double> pixel(0.0, 1.0);
    std::vector<TrajectoryRecord> records;
    truths.clear();
    for (int i = 0; i < 61; ++i) {
      const double t = i / 30.0;
      const Pose3 truth(
          Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * t, Eigen::Vector3d::UnitY())),
          Eigen::Vector3d(0.3 * t, 0.03 * std::sin(2.0 * M_PI * t), 0.05 * std::cos(M_PI * t)));
      truths.push_back(truth);
      const TrajectoryRecord all = SeenFrom(map, model, truth, truth);
      TrajectoryRecord r = all;
      r.seq = i;
      r.timestamp = t;
      r.observed_ids.clear();
      r.observed_uvs.clear();
      for (size_t k = 0; k < all.observed_ids.size(); ++k) {
        const VertexId id = all.observed_ids[k];
        if (object_only ? id < kObject : (id >= kObject || id % 10 != 0)) continue;
        r.observed_ids.push_back(id);
        r.observed_uvs.push_back(
            all.observed_uvs[k] +
            static_cast<float>(noise_px) *
                Eigen::Vector2f(static_cast<float>(pixel(rng)), static_cast<float>(pixel(rng))));
      }
      EXPECT_TRUE(Refine(map, model, &r)) << i;
      records.push_back(std::move(r));
    }
    return records;
  }
  double CentreRms(const std::vector<TrajectoryRecord>& records) const {
    double sum = 0.0;
    for (size_t i = 0; i < records.size(); ++i) {
      sum +=
          (records[i].reference_from_camera.translation() - truths[i].translation()).squaredNorm();
    }
    return std::sqrt(sum / static_cast<double>(records.size()));
  }
  MotionPriorResult Apply(double acceleration_sigma, std::vector<TrajectoryRecord>* records) {
    return map.Read([&](const MapData& m) {
      return ApplyMotionPrior(model, m, 0, 600, acceleration_sigma, records);
    });
  }
  Map map;
  const MeasurementModel model = Model();
  std::vector<Pose3> truths;
};

TEST_F(MotionPrior, AveragesEachFramesNoiseOverItsNeighbours) {
  std::vector<TrajectoryRecord> records = Walk(0.5);
  const double alone = CentreRms(records);
  const MotionPriorResult result = Apply(5.0, &records);
  EXPECT_EQ(result.smoothed, 61);
  EXPECT_EQ(result.kept, 0);
  // The noise the residuals show: 0.5 px, less the six degrees of freedom each pose took out
  // of its 60 coordinates (sqrt(54 / 60): 0.47 expected; measured 0.472).
  EXPECT_NEAR(result.pixel_sigma, 0.47, 0.03);
  // The walk accelerates by at most 1.2 m/s^2 (well within the prior). Measured: 9.7 mm
  // alone, 5.5 mm smoothed.
  EXPECT_GT(alone, 0.005);
  EXPECT_LT(CentreRms(records), 0.7 * alone);
}

// A keyframe's record at its keyframe (as tracking leaves it, RefineFramePose too when the
// keyframe explains it) keeps the bundle adjustment's pose: held, the others smoothed around it.
TEST_F(MotionPrior, HoldsAKeyframeRecordAtItsKeyframe) {
  std::vector<TrajectoryRecord> records = Walk(0.5);
  records[30].reference_from_camera = truths[30];  // the keyframe at the truth
  const double alone = CentreRms(records);
  constexpr KeyframeId kMiddle = kReference + 1;
  map.Write([&](MapData& m) {
    Keyframe kf;
    kf.id = kMiddle;
    kf.world_from_camera = truths[30];
    m.AddKeyframe(std::move(kf));
  });
  records[30].is_keyframe = true;
  records[30].reference = kMiddle;
  records[30].reference_from_camera = Pose3::Identity();
  const MotionPriorResult result = Apply(5.0, &records);
  EXPECT_EQ(result.smoothed, 60);
  EXPECT_EQ(records[30].reference_from_camera.Matrix(), Pose3::Identity().Matrix());
  records[30].reference_from_camera = truths[30];  // for CentreRms, relative to the origin
  EXPECT_LT(CentreRms(records), 0.7 * alone);
}

// Views of the object alone leave the centre loosely determined (SmoothLooseFrames' to
// handle): the prior leaves them.
TEST_F(MotionPrior, LeavesLooselyDeterminedFrames) {
  std::vector<TrajectoryRecord> records = Walk(0.5, /*object_only=*/true);
  const std::vector<TrajectoryRecord> before = records;
  EXPECT_EQ(Apply(5.0, &records).smoothed, 0);
  for (size_t i = 0; i < records.size(); ++i) {
    EXPECT_EQ(records[i].reference_from_camera.Matrix(), before[i].reference_from_camera.Matrix());
  }
}

TEST_F(MotionPrior, LeavesExactDataAndADisabledPriorAlone) {
  std::vector<TrajectoryRecord> exact = Walk(0.0);
  const std::vector<TrajectoryRecord> before = exact;
  const MotionPriorResult result = Apply(5.0, &exact);
  EXPECT_EQ(result.smoothed, 0);
  EXPECT_LT(result.pixel_sigma, 0.01);
  std::vector<TrajectoryRecord> noisy = Walk(0.5);
  const std::vector<TrajectoryRecord> noisy_before = noisy;
  EXPECT_EQ(Apply(0.0, &noisy).smoothed, 0);
  for (size_t i = 0; i < exact.size(); ++i) {
    EXPECT_EQ(exact[i].reference_from_camera.Matrix(), before[i].reference_from_camera.Matrix());
    EXPECT_EQ(noisy[i].reference_from_camera.Matrix(),
              noisy_before[i].reference_from_camera.Matrix());
  }
}

TEST(KeepObservations, KeepsAnEvenSubsetOrNone) {
  TrackerOutput out;
  for (VertexId v = 0; v < 600; ++v) {
    out.observed_ids.push_back(v);
    out.observed_uvs.emplace_back(v, 2.0 * v);
  }
  TrajectoryRecord kept;
  KeepObservations(out.observed_ids, out.observed_uvs, 100, &kept);
  ASSERT_EQ(kept.observed_ids.size(), 100u);
  ASSERT_EQ(kept.observed_uvs.size(), 100u);
  for (size_t i = 0; i < 100; ++i) {
    EXPECT_EQ(kept.observed_ids[i], 6 * i);
    EXPECT_EQ(kept.observed_uvs[i], Eigen::Vector2f(6.0f * i, 12.0f * i));
  }
  TrajectoryRecord all;
  KeepObservations(out.observed_ids, out.observed_uvs, 1000, &all);
  EXPECT_EQ(all.observed_ids.size(), 600u);
  TrajectoryRecord none;
  KeepObservations(out.observed_ids, out.observed_uvs, 0, &none);
  EXPECT_TRUE(none.observed_ids.empty());
  EXPECT_TRUE(none.observed_uvs.empty());
}

}  // namespace
}  // namespace m2s::slam
