// Tracker recovery: relocalisation by PnP in sparse views and its guards (most associated
// points must agree; an OpenCV exception is a lost frame), and a view that empties to a few
// mapped points. References: the least-squares pose on the frame's points (OptimizePose).
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "tracker_test_scene.h"
#include "tracking/tracker.h"

namespace m2s::slam {
namespace {

using namespace tracker_test;  // NOLINT(build/namespaces): the shared test scene

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
