// Tracker: which map points a pose is solved on when points mapped long ago ("dormant") are
// re-observed, and which keyframe a frame is recorded against while its reference keyframe
// still waits for mapping. References: the true pose of a synthetic frame, and poses solved
// directly with OptimizePose on chosen point subsets.
#include "tracking/tracker.h"

#include <fstream>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/numeric.h"
#include "optimization/problems.h"

namespace m2s::slam {
namespace {

constexpr KeyframeId kOldKeyframe = 0;
constexpr KeyframeId kReferenceKeyframe = 40;  // > drift.min_keyframe_gap after kOldKeyframe
constexpr VertexId kFirstOldId = 100000;

struct Scene {
  std::vector<VertexId> ids;
  std::vector<Eigen::Vector3d> true_points;  // world
  std::vector<bool> old;                     // observed only by kOldKeyframe (dormant)
};

// A point in front of the identity camera, projecting inside [u0, u1] x [v0, v1].
Eigen::Vector3d PointInPatch(const Camera& camera, std::mt19937* rng, double u0, double u1,
                             double v0, double v1) {
  std::uniform_real_distribution<double> u(u0, u1), v(v0, v1), depth(1.5, 3.0);
  return camera.Unproject({u(*rng), v(*rng)}, depth(*rng));
}

// Appends n points (ids from first_id) projecting inside the patch of the identity camera.
void AddPoints(const Camera& camera, int n, VertexId first_id, bool old, double u0, double u1,
               double v0, double v1, std::mt19937* rng, Scene* scene) {
  for (int i = 0; i < n; ++i) {
    scene->ids.push_back(first_id + static_cast<VertexId>(i));
    scene->true_points.push_back(PointInPatch(camera, rng, u0, u1, v0, v1));
    scene->old.push_back(old);
  }
}

// Recent and old points over the whole image, and the map positions with the old part of the
// map shifted by `drift` (a map that drifted before the recent keyframes).
struct DriftedScene {
  Scene scene;
  std::vector<Eigen::Vector3d> mapped;
};
DriftedScene RecentAndDriftedOldPoints(const Camera& camera, int recent, int old,
                                       const Eigen::Vector3d& drift, std::mt19937* rng) {
  DriftedScene d;
  AddPoints(camera, recent, 0, false, 10, 630, 10, 470, rng, &d.scene);
  AddPoints(camera, old, kFirstOldId, true, 10, 630, 10, 470, rng, &d.scene);
  d.mapped = d.scene.true_points;
  for (size_t i = 0; i < d.mapped.size(); ++i) {
    if (d.scene.old[i]) d.mapped[i] += drift;
  }
  return d;
}

Options TestOptions() {
  Options options;
  options.camera = Camera::FromHorizontalFov(640, 480, 90.0);
  options.pixel_sigma = 0.5;
  return options;
}

// Inserts the scene into the map: old points observed by kOldKeyframe, recent ones by the
// reference keyframe (both at the identity pose), each at `mapped(i)`.
template <typename Mapped>
void InsertScene(const Scene& scene, const Camera& camera, Mapped mapped, Map* map) {
  while (map->NextKeyframeId() < kReferenceKeyframe) {
  }  // reserved: the tracker's own keyframes get later ids
  map->Write([&](MapData& m) {
    for (const KeyframeId kf_id : {kOldKeyframe, kReferenceKeyframe}) {
      Keyframe kf;
      kf.id = kf_id;
      for (size_t i = 0; i < scene.ids.size(); ++i) {
        if (scene.old[i] != (kf_id == kOldKeyframe)) continue;
        kf.ids.push_back(scene.ids[i]);
        kf.uvs.push_back(camera.Project(scene.true_points[i]));
      }
      m.AddKeyframe(std::move(kf));
    }
    for (size_t i = 0; i < scene.ids.size(); ++i) {
      const KeyframeId observer = scene.old[i] ? kOldKeyframe : kReferenceKeyframe;
      m.AddPoint(scene.ids[i], mapped(i), observer);
      m.AddObservation(scene.ids[i], observer);
    }
  });
}

// InsertScene with every point at its true position.
void InsertTrueScene(const Scene& scene, const Camera& camera, Map* map) {
  InsertScene(
      scene, camera, [&](size_t i) { return scene.true_points[i]; }, map);
}

// n points in the central part of the identity camera's image (still in view after a small
// motion), mapped at their true positions.
void MapCentralPoints(const Camera& camera, int n, std::mt19937* rng, Scene* scene, Map* map) {
  AddPoints(camera, n, 0, false, 80, 560, 80, 400, rng, scene);
  InsertTrueScene(*scene, camera, map);
}

// The frame seen from `world_from_camera` with Gaussian pixel noise (sorted by id).
SortedFeatures Observe(const Scene& scene, const Camera& camera, const Pose3& world_from_camera,
                       double noise_px, std::mt19937* rng) {
  std::normal_distribution<double> noise(0.0, noise_px);
  const Pose3 camera_from_world = world_from_camera.Inverse();
  SortedFeatures f;
  for (size_t i = 0; i < scene.ids.size(); ++i) {
    f.ids.push_back(scene.ids[i]);
    f.uvs.push_back(camera.Project(camera_from_world * scene.true_points[i]) +
                    Eigen::Vector2d(noise(*rng), noise(*rng)));
  }
  return f;
}

double PositionError(const Pose3& a, const Pose3& b) {
  return (a.translation() - b.translation()).norm();
}

// OptimizePose from the identity on the chosen points of the frame.
Pose3 SolveOn(const Options& options, const Scene& scene,
              const std::vector<Eigen::Vector3d>& mapped, const SortedFeatures& frame, bool use_old,
              bool use_recent) {
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  for (size_t i = 0; i < scene.ids.size(); ++i) {
    if (scene.old[i] ? !use_old : !use_recent) continue;
    points.push_back(mapped[i]);
    uvs.push_back(frame.uvs[i]);
  }
  PoseOnlyOptions po;
  po.pixel_sigma = options.pixel_sigma;
  po.huber_delta_px = std::sqrt(kChi2TwoDof95) * options.pixel_sigma;
  Pose3 camera_from_world;
  OptimizePose(options.camera, po, points, uvs, &camera_from_world);
  return camera_from_world.Inverse();
}

// A pose-only problem recorded in a real-time noisy benchmark run (room-s2, 75 fps): the
// tracker's motion prior (camera_from_world, first line: qw qx qy qz tx ty tz), then one
// "x y z u v" line per map point and its observation. Camera 640x480, 90 deg, pixel_sigma 1.
struct RecordedProblem {
  Pose3 prior;
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
};

RecordedProblem LoadRecorded(const std::string& name) {
  RecordedProblem p;
  std::ifstream in(std::string(M2S_SOURCE_DIR) + "/tests/data/tracking/" + name);
  EXPECT_TRUE(in.good()) << name;
  double qw, qx, qy, qz, tx, ty, tz;
  in >> qw >> qx >> qy >> qz >> tx >> ty >> tz;
  p.prior = Pose3(Eigen::Quaterniond(qw, qx, qy, qz).normalized(), Eigen::Vector3d(tx, ty, tz));
  double x, y, z, u, v;
  while (in >> x >> y >> z >> u >> v) {
    p.points.emplace_back(x, y, z);
    p.uvs.emplace_back(u, v);
  }
  return p;
}

int InliersAt(const Camera& camera, const RecordedProblem& p, const Pose3& camera_from_world) {
  int n = 0;
  for (size_t i = 0; i < p.points.size(); ++i) {
    const Eigen::Vector3d pc = camera_from_world * p.points[i];
    if (pc.z() > 0.0 && (camera.Project(pc) - p.uvs[i]).squaredNorm() <= kChi2TwoDof95) ++n;
  }
  return n;
}

TEST(Tracker, PoseSolveNeverEndsFarBelowItsPriorsInliers) {
  const Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  PoseOnlyOptions options;  // as the tracker sets them for pixel_sigma 1
  options.pixel_sigma = 1.0;
  options.huber_delta_px = std::sqrt(kChi2TwoDof95);
  for (const char* name : {"pose_prior_case_all.txt", "pose_prior_case_subset.txt"}) {
    SCOPED_TRACE(name);
    const RecordedProblem p = LoadRecorded(name);
    ASSERT_GT(p.points.size(), 300u);
    const int prior = InliersAt(camera, p, p.prior);
    // The defect: the plain four-round solve leaves the prior for a pose with far fewer inliers.
    Pose3 plain = p.prior;
    OptimizePose(camera, options, p.points, p.uvs, &plain);
    ASSERT_LT(InliersAt(camera, p, plain), 0.9 * prior) << "the recorded case no longer fails";
    Pose3 guarded;
    const int n = SolvePoseFromPrior(camera, options, p.points, p.uvs, p.prior, &guarded);
    EXPECT_EQ(n, InliersAt(camera, p, guarded));
    EXPECT_GE(n, 0.97 * prior);
  }
}

TEST(Tracker, ConsistentDormantPointsJoinThePose) {
  // The recent points crowd one corner of the image (the camera turns into a new area), where
  // rotation and translation are hard to tell apart; the old points cover the whole image and
  // agree with them. Solving on the recent points alone (what tracking did before) is far off.
  const Options options = TestOptions();
  std::mt19937 rng(7);
  Scene scene;
  AddPoints(options.camera, 80, 0, false, 560, 630, 400, 470, &rng, &scene);
  AddPoints(options.camera, 800, kFirstOldId, true, 10, 630, 10, 470, &rng, &scene);
  Map map;
  InsertTrueScene(scene, options.camera, &map);
  Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
  tracker.Start(kReferenceKeyframe, Pose3::Identity(), 80, 0.0, 2.0);
  const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d(0.01, -0.005, 0.004));
  const SortedFeatures frame = Observe(scene, options.camera, truth, 0.5, &rng);

  const TrackerOutput out = tracker.Track(1, 0.02, frame, /*mapping_busy=*/true);
  ASSERT_EQ(out.state, TrackingState::kOk);
  const double recent_only =
      PositionError(SolveOn(options, scene, scene.true_points, frame, false, true), truth);
  const double all =
      PositionError(SolveOn(options, scene, scene.true_points, frame, true, true), truth);
  ASSERT_GT(recent_only, 4.0 * all) << "the scene does not tell the two solutions apart";
  EXPECT_LT(PositionError(out.world_from_camera, truth), 1.5 * all);
  EXPECT_GT(out.num_inliers, 700);  // the old points count as inliers
}

TEST(Tracker, DriftedDormantPointsAreLeftOut) {
  // The old part of the map has drifted 4 cm: its points disagree with the recent ones, and
  // the pose follows the recent points (the drift check in mapping deals with the old ones).
  const Options options = TestOptions();
  std::mt19937 rng(11);
  const auto [scene, mapped] =
      RecentAndDriftedOldPoints(options.camera, 300, 900, Eigen::Vector3d(0.04, 0.0, 0.0), &rng);
  Map map;
  InsertScene(
      scene, options.camera, [&](size_t i) { return mapped[i]; }, &map);
  Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
  tracker.Start(kReferenceKeyframe, Pose3::Identity(), 300, 0.0, 2.0);
  const Pose3 truth(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.005, 0.0, 0.002));
  const SortedFeatures frame = Observe(scene, options.camera, truth, 0.5, &rng);

  const TrackerOutput out = tracker.Track(1, 0.02, frame, /*mapping_busy=*/true);
  ASSERT_EQ(out.state, TrackingState::kOk);
  const double joint = PositionError(SolveOn(options, scene, mapped, frame, true, true), truth);
  ASSERT_GT(joint, 0.01) << "the drift does not pull a joint solution";
  // Exactly the solution on the recent points (same solver, same points, same start).
  const Pose3 recent = SolveOn(options, scene, mapped, frame, false, true);
  EXPECT_LT(PositionError(out.world_from_camera, recent), 1e-9);
  EXPECT_LT(PositionError(out.world_from_camera, truth), 2e-3);
}

TEST(Tracker, SparseViewFollowsItsRecentPointsWhenDormantOnesDisagree) {
  // A sparse view (a low-poly room): 26 recent points and 20 old ones whose part of the map is
  // 4 cm off. Together they fit no pose with the 35 inliers a view of 46 points needs; the 26
  // recent points alone track it (a view of 26 needs 20), as many recent points would in a
  // dense view. The frame is not lost.
  const Options options = TestOptions();
  std::mt19937 rng(13);
  const auto [scene, mapped] =
      RecentAndDriftedOldPoints(options.camera, 26, 20, Eigen::Vector3d(0.04, 0.0, 0.0), &rng);
  Map map;
  InsertScene(
      scene, options.camera, [&](size_t i) { return mapped[i]; }, &map);
  Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
  tracker.Start(kReferenceKeyframe, Pose3::Identity(), 26, 0.0, 2.0);
  const Pose3 truth(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.005, 0.0, 0.002));
  const SortedFeatures frame = Observe(scene, options.camera, truth, 0.5, &rng);

  const TrackerOutput out = tracker.Track(1, 0.02, frame, /*mapping_busy=*/true);
  ASSERT_EQ(out.state, TrackingState::kOk);
  EXPECT_GE(out.num_inliers, 20);
  EXPECT_LT(out.num_inliers, 35);
  // The solution on the recent points (same solver, from the same start).
  const Pose3 recent = SolveOn(options, scene, mapped, frame, false, true);
  ASSERT_LT(PositionError(recent, truth), 5e-3);
  EXPECT_LT(PositionError(out.world_from_camera, recent), 1e-6);
}

TEST(Tracker, LostTrackerRelocalisesInASparseView) {
  // A view of 20 mapped points (fewer than min_inliers, 30): a lost tracker relocalises in it
  // by PnP, with the inliers a sparse view needs (75 %, at least 8).
  const Options options = TestOptions();
  ASSERT_GT(options.tracker.min_inliers, 20);
  std::mt19937 rng(17);
  Scene scene;
  Map map;
  MapCentralPoints(options.camera, 20, &rng, &scene, &map);
  Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
  tracker.StartLost();
  const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d(0.1, -0.05, 0.03));
  // The points are placed for the identity camera; this pose still sees all of them.
  const SortedFeatures frame = Observe(scene, options.camera, truth, 0.5, &rng);
  for (const Eigen::Vector2d& uv : frame.uvs) {
    ASSERT_TRUE(uv.x() > 0 && uv.x() < 640 && uv.y() > 0 && uv.y() < 480) << uv.transpose();
  }
  const TrackerOutput out = tracker.Track(1, 0.1, frame, /*mapping_busy=*/false);
  ASSERT_EQ(out.state, TrackingState::kRelocalized);
  EXPECT_GE(out.num_inliers, 15);
  // The least-squares pose on every point, solved from the identity (the truth is 10 cm and
  // 3 degrees away): what 20 points with 0.5 px noise tell about the pose.
  const Pose3 all = SolveOn(options, scene, scene.true_points, frame, true, true);
  ASSERT_LT(PositionError(all, truth), 1e-2);
  EXPECT_LT(PositionError(out.world_from_camera, all), 1e-4);
  EXPECT_LT(out.world_from_camera.rotation().angularDistance(all.rotation()), 1e-4);
}

TEST(Tracker, AViewOfTenMappedPointsKeepsItsTrackAndRelocalises) {
  // A view that empties to 10 mapped points (a hand-held camera turned to a bare wall): from
  // the motion prior the frame is tracked, and a lost tracker relocalises in it, each on all
  // 10 points (8 inliers suffice; relocalisation must still explain half of what it matched).
  const Options options = TestOptions();
  std::mt19937 rng(23);
  Scene scene;
  Map map;
  MapCentralPoints(options.camera, 10, &rng, &scene, &map);
  const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d(0.01, -0.005, 0.004));
  const SortedFeatures frame = Observe(scene, options.camera, truth, 0.5, &rng);
  // What 10 points with 0.5 px noise tell about the pose: least squares on all of them.
  const Pose3 all = SolveOn(options, scene, scene.true_points, frame, true, true);
  ASSERT_LT(PositionError(all, truth), 1e-2);

  Tracker tracking(options.measurement(), options.tracker, options.drift, &map);
  tracking.Start(kReferenceKeyframe, Pose3::Identity(), 10, 0.0, 2.0);
  const TrackerOutput tracked = tracking.Track(1, 0.03, frame, /*mapping_busy=*/true);
  ASSERT_EQ(tracked.state, TrackingState::kOk);
  EXPECT_EQ(tracked.num_inliers, 10);
  EXPECT_LT(PositionError(tracked.world_from_camera, all), 1e-4);

  Tracker lost(options.measurement(), options.tracker, options.drift, &map);
  lost.StartLost();
  const TrackerOutput relocalised = lost.Track(1, 0.03, frame, /*mapping_busy=*/false);
  ASSERT_EQ(relocalised.state, TrackingState::kRelocalized);
  EXPECT_EQ(relocalised.num_inliers, 10);
  EXPECT_LT(PositionError(relocalised.world_from_camera, all), 1e-4);
  EXPECT_LT(relocalised.world_from_camera.rotation().angularDistance(all.rotation()), 1e-4);
}

TEST(Tracker, FramesRecordAgainstAKeyframeStillQueuedForMapping) {
  // A keyframe candidate that mapping has not inserted yet is the reference of the next
  // frames; the recorded relative pose is taken from the pose the candidate was made with.
  const Options options = TestOptions();
  std::mt19937 rng(3);
  Scene scene;
  AddPoints(options.camera, 400, 0, false, 10, 630, 10, 470, &rng, &scene);
  Map map;
  InsertTrueScene(scene, options.camera, &map);
  Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
  tracker.Start(kReferenceKeyframe, Pose3::Identity(), 400, 0.0, 2.0);
  // Past tracker.keyframe_max_interval_s: the first frame makes a keyframe.
  const Pose3 first(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.01, 0.0, 0.0));
  TrackerOutput made =
      tracker.Track(1, 2.0, Observe(scene, options.camera, first, 0.0, &rng), false);
  ASSERT_TRUE(made.keyframe.has_value());
  const KeyframeCandidate candidate = *made.keyframe;  // never handed to mapping here
  const Pose3 second(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.012, 0.001, 0.0));
  const TrackerOutput out =
      tracker.Track(2, 2.01, Observe(scene, options.camera, second, 0.0, &rng), true);
  ASSERT_EQ(out.state, TrackingState::kOk);
  ASSERT_TRUE(out.reference_keyframe.has_value());
  EXPECT_EQ(*out.reference_keyframe, candidate.id);
  const Pose3 expected = candidate.world_from_camera.Inverse() * out.world_from_camera;
  EXPECT_LT((out.reference_from_camera.translation() - expected.translation()).norm(), 1e-12);
  EXPECT_LT(out.reference_from_camera.rotation().angularDistance(expected.rotation()), 1e-12);
  EXPECT_LT(PositionError(candidate.world_from_camera * out.reference_from_camera, second), 1e-6);
}

TEST(Tracker, PosesAreSolvedOnWellConstrainedPointsWhenThereAreEnough) {
  // 250 well-constrained points at their true positions and 300 poorly constrained ones 4 cm
  // off (MapPoint::constrained false). With at least min_constrained_points constrained ones the
  // pose is the solution on those alone; with fewer (a young map) or 0, on every point.
  Options options = TestOptions();
  constexpr VertexId kFirstUncertainId = 1000;
  std::mt19937 rng(5);
  Scene scene;
  AddPoints(options.camera, 250, 0, false, 10, 630, 10, 470, &rng, &scene);
  AddPoints(options.camera, 300, kFirstUncertainId, false, 10, 630, 10, 470, &rng, &scene);
  std::vector<Eigen::Vector3d> mapped = scene.true_points;
  for (size_t i = 0; i < mapped.size(); ++i) {
    if (scene.ids[i] >= kFirstUncertainId) mapped[i] += Eigen::Vector3d(0.04, 0.0, 0.0);
  }
  const Pose3 truth(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.005, 0.0, 0.002));
  const SortedFeatures frame = Observe(scene, options.camera, truth, 0.5, &rng);
  // OptimizePose from the identity (the tracker's prior) on the constrained points.
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  for (size_t i = 0; i < scene.ids.size(); ++i) {
    if (scene.ids[i] >= kFirstUncertainId) continue;
    points.push_back(mapped[i]);
    uvs.push_back(frame.uvs[i]);
  }
  PoseOnlyOptions po;
  po.pixel_sigma = options.pixel_sigma;
  po.huber_delta_px = std::sqrt(kChi2TwoDof95) * options.pixel_sigma;
  Pose3 constrained_from_world;
  OptimizePose(options.camera, po, points, uvs, &constrained_from_world);
  const Pose3 constrained = constrained_from_world.Inverse();
  const Pose3 all = SolveOn(options, scene, mapped, frame, true, true);
  ASSERT_GT(PositionError(all, truth), 0.01) << "the uncertain points do not pull the pose";
  ASSERT_LT(PositionError(constrained, truth), 2e-3);

  for (const int min_constrained : {250, 251, 0}) {
    options.tracker.min_constrained_points = min_constrained;
    Map map;
    InsertScene(
        scene, options.camera, [&](size_t i) { return mapped[i]; }, &map);
    map.Write([&](MapData& m) {
      for (const VertexId id : scene.ids) {
        if (id >= kFirstUncertainId) m.SetPointUncertainty(id, 0.5, false);
      }
    });
    Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
    tracker.Start(kReferenceKeyframe, Pose3::Identity(), 550, 0.0, 2.0);
    const TrackerOutput out = tracker.Track(1, 0.02, frame, /*mapping_busy=*/true);
    ASSERT_EQ(out.state, TrackingState::kOk);
    const Pose3& expected = min_constrained == 250 ? constrained : all;
    EXPECT_LT(PositionError(out.world_from_camera, expected), 1e-9)
        << "min_constrained_points " << min_constrained;
  }
}

TEST(Tracker, OnlyPointsOffBeyondTheirOwnUncertaintyAreMovedVertices) {
  // 200 well-placed points, 12 whose vertex moved 0.2 m after mapping (well constrained), and
  // 12 poorly triangulated ones mapped 6 cm off (relative uncertainty 0.05: up to ~16 px at
  // this focal length). Both kinds are pose outliers in every frame; after three frames the
  // keyframe names the moved vertices and none of the poorly triangulated points.
  const Options options = TestOptions();
  constexpr VertexId kFirstMovedId = 1000, kFirstPoorId = 2000;
  std::mt19937 rng(11);
  Scene scene;
  AddPoints(options.camera, 200, 0, false, 10, 630, 10, 470, &rng, &scene);
  AddPoints(options.camera, 12, kFirstMovedId, false, 10, 630, 10, 470, &rng, &scene);
  AddPoints(options.camera, 12, kFirstPoorId, false, 10, 630, 10, 470, &rng, &scene);
  std::vector<Eigen::Vector3d> mapped = scene.true_points;
  for (size_t i = 0; i < scene.ids.size(); ++i) {
    if (scene.ids[i] >= kFirstPoorId) {
      mapped[i] += Eigen::Vector3d(0.06, 0.0, 0.0);
    } else if (scene.ids[i] >= kFirstMovedId) {
      scene.true_points[i] += Eigen::Vector3d(0.0, 0.2, 0.0);  // moved after mapping
    }
  }
  Map map;
  InsertScene(
      scene, options.camera, [&](size_t i) { return mapped[i]; }, &map);
  map.Write([&](MapData& m) {
    for (const VertexId id : scene.ids) {
      if (id >= kFirstPoorId) {
        m.SetPointUncertainty(id, 0.05, false);
      } else {
        m.SetPointUncertainty(id, 0.001, true);
      }
    }
  });
  Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
  tracker.Start(kReferenceKeyframe, Pose3::Identity(), 0, 0.0, 2.0);
  std::optional<KeyframeCandidate> keyframe;
  for (int k = 1; k <= 3; ++k) {
    const Pose3 truth(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.002 * k, 0.0, 0.001 * k));
    const SortedFeatures frame = Observe(scene, options.camera, truth, 0.5, &rng);
    // The last frame comes after the keyframe interval, so it makes a keyframe.
    const double t = k < 3 ? 0.02 * k : 1.0 + options.tracker.keyframe_max_interval_s;
    const TrackerOutput out = tracker.Track(k, t, frame, /*mapping_busy=*/k < 3);
    ASSERT_EQ(out.state, TrackingState::kOk) << "frame " << k;
    // The poorly triangulated points may pull the pose by a few mm; the moved ones do not.
    EXPECT_LT(PositionError(out.world_from_camera, truth), 5e-3) << "frame " << k;
    keyframe = out.keyframe;
  }
  ASSERT_TRUE(keyframe.has_value());
  std::vector<VertexId> expected;
  for (VertexId id = kFirstMovedId; id < kFirstMovedId + 12; ++id) expected.push_back(id);
  EXPECT_EQ(keyframe->moved_points, expected);
}

// OpenCV's PnP asserts on fewer than four points. Only options Check() refuses (min_inliers
// under 6) let relocalisation hand it so few; the exception must end as a lost frame.
TEST(Tracker, AnOpenCvExceptionInRelocalisationIsALostFrame) {
  Options options = TestOptions();
  options.tracker.min_inliers = 3;
  Status why;
  ASSERT_FALSE((why = options.tracker.Check()));
  std::mt19937 rng(3);
  Scene scene;
  AddPoints(options.camera, 3, 0, /*old=*/false, 100, 500, 100, 400, &rng, &scene);
  Map map;
  InsertTrueScene(scene, options.camera, &map);
  Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
  tracker.StartLost();
  TrackerOutput out;
  EXPECT_NO_THROW(out = tracker.Track(1, 0.1, Observe(scene, options.camera, Pose3(), 0.0, &rng),
                                      /*mapping_busy=*/false));
  EXPECT_EQ(out.state, TrackingState::kLost);
  EXPECT_FALSE(out.keyframe.has_value());
  EXPECT_TRUE(tracker.lost());
}

// Relocalisation with exact association: every associated point is the vertex the frame sees,
// so a PnP pose that explains only a minority of them is an ambiguity of a weak point set (a
// bunched or distant object fits a wrong pose within the RANSAC bound), never the pose.
// Here `consistent` of 100 points are mapped where they are and the rest metres off.
TrackerOutput RelocaliseWithConsistentPoints(int consistent, const Pose3& world_from_camera) {
  const Options options = TestOptions();
  std::mt19937 rng(11);
  Scene scene;
  AddPoints(options.camera, 100, 0, /*old=*/false, 40, 600, 40, 440, &rng, &scene);
  std::uniform_real_distribution<double> offset(-0.6, 0.6);
  std::vector<Eigen::Vector3d> mapped = scene.true_points;
  for (size_t i = static_cast<size_t>(consistent); i < mapped.size(); ++i) {
    mapped[i] += Eigen::Vector3d(offset(rng), offset(rng), offset(rng));
  }
  Map map;
  InsertScene(
      scene, options.camera, [&](size_t i) { return mapped[i]; }, &map);
  Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
  tracker.StartLost();
  return tracker.Track(1, 0.1, Observe(scene, options.camera, world_from_camera, 0.3, &rng),
                       /*mapping_busy=*/false);
}

TEST(Tracker, RelocalisationNeedsMostAssociatedPointsToAgree) {
  const Pose3 truth(Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                    Eigen::Vector3d(0.1, -0.05, 0.02));
  // 40 of 100 agree: more than TrackerOptions::min_inliers (30), still a minority.
  EXPECT_EQ(RelocaliseWithConsistentPoints(40, truth).state, TrackingState::kLost);
  const TrackerOutput majority = RelocaliseWithConsistentPoints(70, truth);
  ASSERT_EQ(majority.state, TrackingState::kRelocalized);
  EXPECT_LT(PositionError(majority.world_from_camera, truth), 0.01);
  EXPECT_GE(majority.num_inliers, 65);
}

}  // namespace
}  // namespace m2s::slam
