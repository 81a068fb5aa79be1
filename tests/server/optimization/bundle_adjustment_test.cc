// BundleAdjust on synthetic scenes (cameras on an arc around a cube of points): convergence to
// the ground truth (up to the gauge), outlier flags, fixed parameters, bad input.
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/alignment.h"
#include "optimization/problems.h"
#include "synthetic_scene.h"

namespace m2s::slam {
namespace {

struct Scene {
  std::vector<Pose3> camera_from_world;  // truth
  std::vector<Eigen::Vector3d> points;   // truth
  BaProblem problem;                     // truth, with every visible observation
};

Scene MakeScene(int num_keyframes, int num_points, std::mt19937* rng) {
  const Camera camera = testing::TestCamera();
  Scene scene;
  scene.points = testing::RandomPoints(num_points, 1.5, rng);
  for (const Pose3& world_from_camera : testing::CirclePoses(num_keyframes, 6.0, M_PI / 2)) {
    scene.camera_from_world.push_back(world_from_camera.Inverse());
  }
  for (size_t k = 0; k < scene.camera_from_world.size(); ++k) {
    scene.problem.keyframes.push_back(
        {static_cast<KeyframeId>(k), scene.camera_from_world[k], false});
  }
  for (size_t p = 0; p < scene.points.size(); ++p) {
    scene.problem.points.push_back({static_cast<VertexId>(p), scene.points[p], false});
  }
  for (size_t k = 0; k < scene.camera_from_world.size(); ++k) {
    for (size_t p = 0; p < scene.points.size(); ++p) {
      const Eigen::Vector3d pc = scene.camera_from_world[k] * scene.points[p];
      const Eigen::Vector2d uv = camera.Project(pc);
      if (pc.z() > camera.near && camera.InImage(uv.x(), uv.y())) {
        scene.problem.observations.push_back({static_cast<int>(k), static_cast<int>(p), uv});
      }
    }
  }
  return scene;
}

void PerturbProblem(BaProblem* problem, double angle, double shift, double point_shift,
                    std::mt19937* rng) {
  std::normal_distribution<double> normal(0.0, point_shift);
  for (BaKeyframe& keyframe : problem->keyframes) {
    if (!keyframe.fixed)
      keyframe.camera_from_world = testing::Perturb(keyframe.camera_from_world, angle, shift, rng);
  }
  for (BaPoint& point : problem->points) {
    if (!point.fixed)
      point.position_world += Eigen::Vector3d(normal(*rng), normal(*rng), normal(*rng));
  }
}

double MaxPointError(const BaProblem& problem, const std::vector<Eigen::Vector3d>& truth) {
  double worst = 0.0;
  for (size_t p = 0; p < truth.size(); ++p) {
    worst = std::max(worst, (problem.points[p].position_world - truth[p]).norm());
  }
  return worst;
}

TEST(BundleAdjustTest, ConvergesToTruthWithTwoKeyframesFixed) {
  std::mt19937 rng(7);
  Scene scene = MakeScene(8, 300, &rng);
  // Two fixed keyframes at the truth fix the gauge, scale included.
  scene.problem.keyframes[0].fixed = true;
  scene.problem.keyframes[7].fixed = true;
  PerturbProblem(&scene.problem, 2.0 * M_PI / 180.0, 0.1, 0.05, &rng);
  const BundleAdjustmentResult result =
      BundleAdjust(testing::TestCamera(), BundleAdjustmentOptions(), &scene.problem);
  ASSERT_TRUE(result.success);
  EXPECT_GT(result.initial_rmse_px, 1.0);
  EXPECT_LT(result.final_rmse_px, 1e-6);
  for (size_t k = 0; k < scene.camera_from_world.size(); ++k) {
    EXPECT_LT(testing::PoseError(scene.problem.keyframes[k].camera_from_world,
                                 scene.camera_from_world[k]),
              1e-7)
        << k;
  }
  EXPECT_EQ(scene.problem.keyframes[0].camera_from_world.Matrix(),
            scene.camera_from_world[0].Matrix());
  EXPECT_EQ(scene.problem.keyframes[7].camera_from_world.Matrix(),
            scene.camera_from_world[7].Matrix());
  EXPECT_LT(MaxPointError(scene.problem, scene.points), 1e-7);
  for (bool outlier : result.outlier) EXPECT_FALSE(outlier);
}

TEST(BundleAdjustTest, WithoutFixedKeyframesTheFirstHoldsTheGaugeAndTheRestIsTrueUpToSim3) {
  std::mt19937 rng(8);
  Scene scene = MakeScene(6, 200, &rng);
  PerturbProblem(&scene.problem, 1.0 * M_PI / 180.0, 0.05, 0.03, &rng);
  const Pose3 first = scene.problem.keyframes[0].camera_from_world;
  BundleAdjustmentOptions options;
  options.max_iterations = 100;
  const BundleAdjustmentResult result =
      BundleAdjust(testing::TestCamera(), options, &scene.problem);
  ASSERT_TRUE(result.success);
  EXPECT_EQ(scene.problem.keyframes[0].camera_from_world.Matrix(), first.Matrix());
  EXPECT_LT(result.final_rmse_px, 1e-5);
  // Align the estimated camera centres and points to the truth with one similarity.
  std::vector<Eigen::Vector3d> estimate, truth;
  for (size_t k = 0; k < scene.camera_from_world.size(); ++k) {
    estimate.push_back(scene.problem.keyframes[k].camera_from_world.Inverse().translation());
    truth.push_back(scene.camera_from_world[k].Inverse().translation());
  }
  for (size_t p = 0; p < scene.points.size(); ++p) {
    estimate.push_back(scene.problem.points[p].position_world);
    truth.push_back(scene.points[p]);
  }
  const std::optional<Sim3> truth_from_estimate = AlignPoints(estimate, truth, true);
  ASSERT_TRUE(truth_from_estimate.has_value());
  for (size_t i = 0; i < estimate.size(); ++i) {
    EXPECT_LT(((*truth_from_estimate) * estimate[i] - truth[i]).norm(), 1e-5) << i;
  }
}

TEST(BundleAdjustTest, FlagsOutliersAndIsNotDisturbedByThem) {
  std::mt19937 rng(9);
  Scene scene = MakeScene(8, 300, &rng);
  scene.problem.keyframes[0].fixed = true;
  scene.problem.keyframes[7].fixed = true;
  std::vector<bool> corrupted(scene.problem.observations.size(), false);
  std::uniform_int_distribution<size_t> pick(0, corrupted.size() - 1);
  for (int n = 0; n < static_cast<int>(corrupted.size()) / 50;) {  // 2% wrong by 15-30 px
    const size_t i = pick(rng);
    if (corrupted[i]) continue;
    const double angle = std::uniform_real_distribution<double>(0, 2 * M_PI)(rng);
    const double radius = std::uniform_real_distribution<double>(15, 30)(rng);
    scene.problem.observations[i].uv += radius * Eigen::Vector2d(std::cos(angle), std::sin(angle));
    corrupted[i] = true;
    ++n;
  }
  PerturbProblem(&scene.problem, 1.0 * M_PI / 180.0, 0.05, 0.02, &rng);
  const BundleAdjustmentResult result =
      BundleAdjust(testing::TestCamera(), BundleAdjustmentOptions(), &scene.problem);
  ASSERT_TRUE(result.success);
  ASSERT_EQ(result.outlier.size(), corrupted.size());
  for (size_t i = 0; i < corrupted.size(); ++i) EXPECT_EQ(result.outlier[i], corrupted[i]) << i;
  EXPECT_LT(result.final_rmse_px, 1e-6);
  EXPECT_LT(MaxPointError(scene.problem, scene.points), 1e-6);
  for (size_t k = 0; k < scene.camera_from_world.size(); ++k) {
    EXPECT_LT(testing::PoseError(scene.problem.keyframes[k].camera_from_world,
                                 scene.camera_from_world[k]),
              1e-7);
  }
}

TEST(BundleAdjustTest, FixedPointsStayFixedAndFreeKeyframesFollowThem) {
  std::mt19937 rng(10);
  Scene scene = MakeScene(5, 150, &rng);
  for (BaPoint& point : scene.problem.points) point.fixed = true;  // structure-only known
  PerturbProblem(&scene.problem, 2.0 * M_PI / 180.0, 0.1, 0.0, &rng);
  scene.problem.keyframes[2].fixed = true;  // a fixed, wrong keyframe stays where it is
  const Pose3 wrong_fixed = scene.problem.keyframes[2].camera_from_world;
  const BundleAdjustmentResult result =
      BundleAdjust(testing::TestCamera(), BundleAdjustmentOptions(), &scene.problem);
  ASSERT_TRUE(result.success);
  EXPECT_EQ(MaxPointError(scene.problem, scene.points), 0.0);
  EXPECT_EQ(scene.problem.keyframes[2].camera_from_world.Matrix(), wrong_fixed.Matrix());
  for (size_t k : {0, 1, 3, 4}) {
    EXPECT_LT(testing::PoseError(scene.problem.keyframes[k].camera_from_world,
                                 scene.camera_from_world[k]),
              1e-8);
  }
}

TEST(BundleAdjustTest, ManyKeyframesUseTheSparseSolverAndConverge) {
  std::mt19937 rng(11);
  Scene scene = MakeScene(60, 400, &rng);
  scene.problem.keyframes[0].fixed = true;
  scene.problem.keyframes[59].fixed = true;
  PerturbProblem(&scene.problem, 0.5 * M_PI / 180.0, 0.02, 0.01, &rng);
  const BundleAdjustmentResult result =
      BundleAdjust(testing::TestCamera(), BundleAdjustmentOptions(), &scene.problem);
  ASSERT_TRUE(result.success);
  EXPECT_LT(result.final_rmse_px, 1e-6);
  EXPECT_LT(MaxPointError(scene.problem, scene.points), 1e-7);
}

TEST(BundleAdjustTest, MalformedProblemsAreRejectedUnchanged) {
  std::mt19937 rng(12);
  Scene scene = MakeScene(3, 50, &rng);
  PerturbProblem(&scene.problem, 1.0 * M_PI / 180.0, 0.05, 0.02, &rng);
  BaProblem bad = scene.problem;
  bad.observations.push_back({5, 0, Eigen::Vector2d(1, 1)});  // keyframe index out of range
  const BaProblem before = bad;
  BundleAdjustmentResult result =
      BundleAdjust(testing::TestCamera(), BundleAdjustmentOptions(), &bad);
  EXPECT_FALSE(result.success);
  EXPECT_EQ(MaxPointError(bad,
                          [&] {
                            std::vector<Eigen::Vector3d> p;
                            for (const BaPoint& x : before.points) p.push_back(x.position_world);
                            return p;
                          }()),
            0.0);

  bad = scene.problem;
  bad.points[0].position_world.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(BundleAdjust(testing::TestCamera(), BundleAdjustmentOptions(), &bad).success);

  BundleAdjustmentOptions options;
  options.num_threads = 0;
  EXPECT_FALSE(BundleAdjust(testing::TestCamera(), options, &scene.problem).success);
  EXPECT_FALSE(BundleAdjust(testing::TestCamera(), BundleAdjustmentOptions(), nullptr).success);

  BaProblem empty;
  EXPECT_TRUE(BundleAdjust(testing::TestCamera(), BundleAdjustmentOptions(), &empty).success);
}

TEST(BundleAdjustmentOptionsTest, CheckRejectsBadValues) {
  EXPECT_TRUE(BundleAdjustmentOptions().Check());
  Status why;
  BundleAdjustmentOptions o;
  o.pixel_sigma = 0.0;
  EXPECT_FALSE((why = o.Check()));
  EXPECT_FALSE(why.message().empty());
  o = {};
  o.huber_delta_px = -2.0;
  EXPECT_FALSE((why = o.Check()));
  o = {};
  o.chi2_threshold = std::numeric_limits<double>::infinity();
  EXPECT_FALSE((why = o.Check()));
  o = {};
  o.max_iterations = 0;
  EXPECT_FALSE((why = o.Check()));
}

}  // namespace
}  // namespace m2s::slam
