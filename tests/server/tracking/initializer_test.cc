// Two-view initialisation on exact synthetic views: a general 3-D scene (essential matrix), a
// planar one (homography), refusal under pure rotation, and the poses of the frames between the
// two views.
#include "tracking/initializer.h"

#include <algorithm>
#include <random>

#include <gtest/gtest.h>

namespace m2s::slam {
namespace {

struct Views {
  std::vector<Eigen::Vector3d> points;  // world = camera 0
  SortedFeatures view0, view1;
};

SortedFeatures Project(const Camera& camera, const Pose3& world_from_camera,
                       const std::vector<Eigen::Vector3d>& points) {
  SortedFeatures f;
  const Pose3 camera_from_world = world_from_camera.Inverse();
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d pc = camera_from_world * points[i];
    if (pc.z() <= camera.near) continue;
    const Eigen::Vector2d uv = camera.Project(pc);
    if (!camera.InImage(uv.x(), uv.y())) continue;
    f.ids.push_back(static_cast<VertexId>(i));
    f.uvs.push_back(uv);
  }
  return f;
}

Views MakeViews(const Camera& camera, const Pose3& world_from_camera1, bool planar, int n = 600) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> xy(-2.0, 2.0), depth(3.0, 7.0);
  Views v;
  for (int i = 0; i < n; ++i) {
    const double x = xy(rng), y = xy(rng);
    // The plane is tilted (z = 4 + 0.3 x) so the homography is not a pure scaling.
    v.points.emplace_back(x, y, planar ? 4.0 + 0.3 * x : depth(rng));
  }
  v.view0 = Project(camera, Pose3::Identity(), v.points);
  v.view1 = Project(camera, world_from_camera1, v.points);
  return v;
}

Options TestOptions() {
  Options o;
  o.camera = Camera();
  return o;
}

Pose3 Motion(double tx, double yaw_deg) {
  return Pose3(
      Eigen::Quaterniond(Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY())),
      Eigen::Vector3d(tx, 0.05, 0.1));
}

// Checks the initial map against the truth up to the monocular scale.
void ExpectMatchesTruth(const InitialMap& map, const Views& views,
                        const Pose3& world_from_camera1) {
  EXPECT_TRUE(map.first.world_from_camera.translation().isZero(1e-12));
  const Pose3& est = map.second.world_from_camera;
  const double scale = world_from_camera1.translation().norm() / est.translation().norm();
  EXPECT_LT(RotationAngle(est.rotation().conjugate() * world_from_camera1.rotation()), 1e-5);
  EXPECT_LT((est.translation() * scale - world_from_camera1.translation()).norm(), 1e-5);
  ASSERT_GE(map.points.size(), 100u);
  std::vector<double> depths;
  for (size_t i = 0; i < map.points.size(); ++i) {
    const Eigen::Vector3d& truth = views.points[map.point_ids[i]];
    EXPECT_LT((map.points[i] * scale - truth).norm(), 1e-4) << "point " << map.point_ids[i];
    depths.push_back(map.points[i].z());
  }
  std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
  EXPECT_NEAR(depths[depths.size() / 2], 1.0, 1e-9);  // scale: median depth 1
}

// Compares the solved frames between the two views with the truth (truth[seq]: world from
// camera), up to the monocular scale; returns their seqs in order.
std::vector<int64_t> ExpectInbetweenMatchesTruth(const InitialMap& map,
                                                 const std::vector<Pose3>& truth) {
  const Pose3 origin = truth[map.first.seq];
  const double scale = (origin.Inverse() * truth[map.second.seq]).translation().norm() /
                       map.second.world_from_camera.translation().norm();
  std::vector<int64_t> solved;
  for (const InitialInbetween& f : map.inbetween) {
    solved.push_back(f.seq);
    const Pose3 expected = origin.Inverse() * truth[f.seq];
    const Pose3& est = f.world_from_camera;
    EXPECT_LT(RotationAngle(est.rotation().conjugate() * expected.rotation()), 1e-5) << f.seq;
    EXPECT_LT((est.translation() * scale - expected.translation()).norm(), 1e-5) << f.seq;
    EXPECT_GE(f.observed_ids.size(), static_cast<size_t>(60)) << f.seq;
    EXPECT_EQ(f.observed_ids.size(), f.observed_uvs.size());
  }
  return solved;
}

TEST(Initializer, GeneralSceneUsesTheEssentialMatrix) {
  const Options options = TestOptions();
  const Pose3 motion = Motion(0.4, 4.0);
  const Views views = MakeViews(options.camera, motion, /*planar=*/false);
  Initializer init(options.measurement(), options.initializer, 1);
  EXPECT_FALSE(init.Process(0, 0.0, views.view0).has_value());
  const auto map = init.Process(1, 0.1, views.view1);
  ASSERT_TRUE(map.has_value()) << init.last_failure();
  EXPECT_FALSE(map->used_homography);
  EXPECT_EQ(map->first.seq, 0);
  EXPECT_EQ(map->second.seq, 1);
  ExpectMatchesTruth(*map, views, motion);
}

TEST(Initializer, PlanarSceneUsesTheHomography) {
  const Options options = TestOptions();
  const Pose3 motion = Motion(0.5, -3.0);
  const Views views = MakeViews(options.camera, motion, /*planar=*/true);
  TwoViewRefusal refusal;
  const auto two_view = ReconstructTwoView(options.measurement(), options.initializer, views.view0,
                                           views.view1, &refusal);
  ASSERT_TRUE(two_view.has_value()) << refusal.message;
  EXPECT_TRUE(two_view->used_homography);
  Initializer init(options.measurement(), options.initializer, 1);
  init.Process(0, 0.0, views.view0);
  const auto map = init.Process(1, 0.1, views.view1);
  ASSERT_TRUE(map.has_value()) << init.last_failure();
  ExpectMatchesTruth(*map, views, motion);
}

TEST(Initializer, RefusesPureRotationAndTinyParallax) {
  const Options options = TestOptions();
  Initializer init(options.measurement(), options.initializer, 1);
  const Views first = MakeViews(options.camera, Pose3::Identity(), false);
  EXPECT_FALSE(init.Process(0, 0.0, first.view0).has_value());
  for (int k = 1; k <= 20; ++k) {
    const Pose3 rotation(Eigen::Quaterniond(Eigen::AngleAxisd(
                             0.5 * k * M_PI / 180.0, Eigen::Vector3d(0.2, 1.0, 0.1).normalized())),
                         Eigen::Vector3d::Zero());
    const Views views = MakeViews(options.camera, rotation, false);
    EXPECT_FALSE(init.Process(k, 0.1 * k, views.view1).has_value()) << "rotation step " << k;
  }
  // A 2 mm translation at 3-7 m depth: far below one degree of parallax.
  const Views tiny = MakeViews(options.camera, Motion(0.002, 1.0), false);
  TwoViewRefusal refusal;
  EXPECT_FALSE(ReconstructTwoView(options.measurement(), options.initializer, tiny.view0,
                                  tiny.view1, &refusal)
                   .has_value());
  EXPECT_EQ(refusal.kind, TwoViewRefusal::Kind::kNoModel) << refusal.message;
}

TEST(Initializer, ToleratesWrongIds) {
  const Options options = TestOptions();
  const Pose3 motion = Motion(0.4, 4.0);
  Views views = MakeViews(options.camera, motion, false);
  // 3% of the second view's features get the uv of another feature (wrong ids).
  for (size_t i = 0; i + 7 < views.view1.size(); i += 33)
    std::swap(views.view1.uvs[i], views.view1.uvs[i + 7]);
  Initializer init(options.measurement(), options.initializer, 1);
  init.Process(0, 0.0, views.view0);
  const auto map = init.Process(1, 0.1, views.view1);
  ASSERT_TRUE(map.has_value()) << init.last_failure();
  const Pose3& est = map->second.world_from_camera;
  EXPECT_LT(RotationAngle(est.rotation().conjugate() * motion.rotation()), 1e-4);
  EXPECT_LT((est.translation().normalized() - motion.translation().normalized()).norm(), 1e-3);
}

// A slow sideways motion: the first frames have too little parallax; once a later one
// initialises, the frames between the two views get their poses on the initial map (the truth
// up to the monocular scale), and a frame that is not a view of the scene (its pixels shuffled
// among its ids) is left out. The same when the map leaves them to the caller
// (DeferInbetween) and InbetweenSolver solves them.
TEST(Initializer, SolvesTheFramesBetweenTheTwoViews) {
  const Options options = TestOptions();
  for (const bool defer : {false, true}) {
    SCOPED_TRACE(defer ? "deferred" : "at once");
    Initializer init(options.measurement(), options.initializer, 1);
    init.DeferInbetween(defer);
    const int kScrambled = 5;
    std::vector<Pose3> truth;
    std::optional<InitialMap> map;
    for (int k = 0; k < 60 && !map; ++k) {
      truth.push_back(Motion(0.01 * k, 0.1 * k));
      SortedFeatures view = MakeViews(options.camera, truth.back(), false).view1;
      if (k == kScrambled) {
        std::mt19937 rng(3);
        std::shuffle(view.uvs.begin(), view.uvs.end(), rng);
      }
      map = init.Process(k, 0.1 * k, view);
    }
    ASSERT_TRUE(map.has_value()) << init.last_failure();
    ASSERT_EQ(map->first.seq, 0);
    const int64_t second = map->second.seq;
    ASSERT_GE(second, 3) << "the motion is meant to need several frames";
    if (defer) {
      EXPECT_TRUE(map->inbetween.empty());
      ASSERT_EQ(map->unsolved.size(), static_cast<size_t>(second - 1));
      InbetweenSolver solver(options.measurement(), options.initializer.min_points, *map,
                             std::move(map->unsolved));
      while (!solver.done()) {
        if (auto f = solver.SolveNext()) map->inbetween.push_back(std::move(*f));
      }
    } else {
      EXPECT_TRUE(map->unsolved.empty());
    }
    for (const InitialInbetween& f : map->inbetween) {
      EXPECT_GE(f.observed_ids.size(), map->points.size() * 9 / 10) << f.seq;
    }
    const std::vector<int64_t> solved = ExpectInbetweenMatchesTruth(*map, truth);
    std::vector<int64_t> expected_seqs;
    for (int64_t k = 1; k < second; ++k) {
      if (k != kScrambled) expected_seqs.push_back(k);
    }
    EXPECT_EQ(solved, expected_seqs);
  }
}

// Seed() (the lost frames before a new map starts): the earliest frame with nearly the most
// features is the reference, not the sparse views before it; once a later frame initialises,
// the seeded frames before and after the reference get their poses too.
TEST(Initializer, SeedTakesTheEarliestFullViewAsReferenceAndSolvesTheSeededFrames) {
  const Options options = TestOptions();
  Initializer init(options.measurement(), options.initializer, 1);
  const int kSparse = 3, kSeeded = 10;
  std::vector<Pose3> truth;
  std::vector<InitialFrame> seeded;
  for (int k = 0; k < kSeeded; ++k) {
    truth.push_back(Motion(0.01 * k, 0.1 * k));
    SortedFeatures view = MakeViews(options.camera, truth.back(), false).view1;
    if (k < kSparse) {  // a view of 70 of the points: turning from a bare wall
      view.ids.resize(70);
      view.uvs.resize(70);
    }
    seeded.push_back(InitialFrame{k, 0.1 * k, view, Pose3::Identity()});
  }
  init.Seed(seeded, Initializer::SeedReference::kEarliestFull);
  std::optional<InitialMap> map;
  for (int k = kSeeded; k < 80 && !map; ++k) {
    truth.push_back(Motion(0.01 * k, 0.1 * k));
    map = init.Process(k, 0.1 * k, MakeViews(options.camera, truth.back(), false).view1);
  }
  ASSERT_TRUE(map.has_value()) << init.last_failure();
  EXPECT_EQ(map->first.seq, kSparse);
  const int64_t second = map->second.seq;
  const std::vector<int64_t> solved = ExpectInbetweenMatchesTruth(*map, truth);
  std::vector<int64_t> expected_seqs;
  for (int64_t k = 0; k < second; ++k) {
    if (k != kSparse) expected_seqs.push_back(k);
  }
  EXPECT_EQ(solved, expected_seqs);
}

// OpenCV's homography solver throws on fewer than four matches. Only options Check() refuses
// (min_points under 8) let the initialiser hand it so few; the exception must end as a refused
// attempt with its reason.
TEST(Initializer, AnOpenCvExceptionIsARefusedAttempt) {
  Options options = TestOptions();
  options.initializer.min_points = 3;
  ASSERT_FALSE(options.initializer.Check());
  TwoViewRefusal refusal;
  SortedFeatures view0, view1;
  for (VertexId id = 0; id < 3; ++id) {
    view0.ids.push_back(id);
    view0.uvs.emplace_back(100.0 + 150.0 * id, 120.0 + 90.0 * id);
    view1.ids.push_back(id);
    view1.uvs.push_back(view0.uvs.back() + Eigen::Vector2d(60.0, 10.0 * id));  // much motion
  }
  std::optional<TwoViewReconstruction> two_view;
  EXPECT_NO_THROW(two_view = ReconstructTwoView(options.measurement(), options.initializer, view0,
                                                view1, &refusal));
  EXPECT_FALSE(two_view.has_value());
  EXPECT_EQ(refusal.kind, TwoViewRefusal::Kind::kSolverError) << refusal.message;
  EXPECT_EQ(refusal.message.rfind("OpenCV error: ", 0), 0u) << refusal.message;

  Initializer init(options.measurement(), options.initializer, 1);
  std::optional<InitialMap> map;
  EXPECT_NO_THROW(map = init.Process(0, 0.0, view0));
  EXPECT_NO_THROW(map = init.Process(1, 0.5, view1));
  EXPECT_FALSE(map.has_value());
  EXPECT_EQ(init.last_failure().rfind("OpenCV error: ", 0), 0u) << init.last_failure();
}

}  // namespace
}  // namespace m2s::slam
