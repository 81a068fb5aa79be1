// OptimizePose: exact recovery on noise-free data, rejection of wrong correspondences, the
// Ceres reference solver agreeing with the hand-written one, and bad input handled by value.
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "optimization/problems.h"
#include "synthetic_scene.h"

namespace m2s::slam {
namespace {

struct Observations {
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uv;
};

// Points in a 4 m cube seen by a camera 6 m away, keeping the ones inside the image.
Observations Observe(const Camera& camera, const Pose3& camera_from_world, int count,
                     std::mt19937* rng) {
  Observations out;
  while (static_cast<int>(out.points.size()) < count) {
    for (const Eigen::Vector3d& p : testing::RandomPoints(count, 2.0, rng)) {
      const Eigen::Vector3d pc = camera_from_world * p;
      if (pc.z() <= camera.near) continue;
      const Eigen::Vector2d uv = camera.Project(pc);
      if (!camera.InImage(uv.x(), uv.y())) continue;
      out.points.push_back(p);
      out.uv.push_back(uv);
      if (static_cast<int>(out.points.size()) == count) break;
    }
  }
  return out;
}

class OptimizePoseTest : public ::testing::Test {
 protected:
  void SetUp() override {
    truth_ = testing::LookAt({6.0, 1.0, 0.5}, {0.0, 0.0, 0.0}).Inverse();
    observations_ = Observe(camera_, truth_, 1000, &rng_);
  }
  std::mt19937 rng_{42};
  Camera camera_ = testing::TestCamera();
  Pose3 truth_;
  Observations observations_;
};

TEST_F(OptimizePoseTest, RecoversAPerturbedPoseExactlyOnNoiseFreeData) {
  for (bool use_ceres : {false, true}) {
    Pose3 pose = testing::Perturb(truth_, 3.0 * M_PI / 180.0, 0.2, &rng_);
    PoseOnlyOptions options;
    options.use_ceres = use_ceres;
    const PoseOnlyResult result =
        OptimizePose(camera_, options, observations_.points, observations_.uv, &pose);
    EXPECT_TRUE(result.converged) << "ceres " << use_ceres;
    EXPECT_EQ(result.num_inliers, 1000);
    EXPECT_LT(testing::PoseError(pose, truth_), 1e-9) << "ceres " << use_ceres;
    EXPECT_LT(result.final_rmse_px, 1e-6);
    for (bool inlier : result.inlier) EXPECT_TRUE(inlier);
  }
}

TEST_F(OptimizePoseTest, RejectsWrongCorrespondences) {
  // 10% of the observations get the pixel of another, distant point (a wrong id).
  std::vector<bool> wrong(observations_.points.size(), false);
  std::uniform_int_distribution<size_t> pick(0, observations_.points.size() - 1);
  int injected = 0;
  std::vector<Eigen::Vector2d> uv = observations_.uv;
  while (injected < 100) {
    const size_t i = pick(rng_);
    const size_t j = pick(rng_);
    if (wrong[i] || (observations_.uv[i] - observations_.uv[j]).norm() < 20.0) continue;
    uv[i] = observations_.uv[j];
    wrong[i] = true;
    ++injected;
  }
  for (bool use_ceres : {false, true}) {
    Pose3 pose = testing::Perturb(truth_, 2.0 * M_PI / 180.0, 0.1, &rng_);
    PoseOnlyOptions options;
    options.use_ceres = use_ceres;
    const PoseOnlyResult result = OptimizePose(camera_, options, observations_.points, uv, &pose);
    EXPECT_TRUE(result.converged);
    EXPECT_EQ(result.num_inliers, 900);
    EXPECT_LT(testing::PoseError(pose, truth_), 1e-9) << "ceres " << use_ceres;
    ASSERT_EQ(result.inlier.size(), wrong.size());
    for (size_t i = 0; i < wrong.size(); ++i) EXPECT_EQ(result.inlier[i], !wrong[i]) << i;
  }
}

TEST_F(OptimizePoseTest, NoisyFeaturesGiveASmallErrorAndTheNoiseLevelAsRmse) {
  std::normal_distribution<double> noise(0.0, 0.5);
  std::vector<Eigen::Vector2d> uv = observations_.uv;
  for (Eigen::Vector2d& x : uv) x += Eigen::Vector2d(noise(rng_), noise(rng_));
  Pose3 pose = testing::Perturb(truth_, 2.0 * M_PI / 180.0, 0.1, &rng_);
  const PoseOnlyResult result =
      OptimizePose(camera_, PoseOnlyOptions(), observations_.points, uv, &pose);
  EXPECT_TRUE(result.converged);
  EXPECT_GT(result.num_inliers, 990);
  EXPECT_LT(testing::PoseError(pose, truth_), 2e-3);
  EXPECT_NEAR(result.final_rmse_px, 0.5 * std::sqrt(2.0), 0.1);
}

TEST_F(OptimizePoseTest, NonFiniteAndBehindCameraObservationsAreOutliers) {
  std::vector<Eigen::Vector3d> points = observations_.points;
  std::vector<Eigen::Vector2d> uv = observations_.uv;
  points[3] = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  uv[5].x() = std::numeric_limits<double>::infinity();
  // A point behind the camera: mirror through the camera centre.
  const Eigen::Vector3d center = truth_.Inverse().translation();
  points[7] = 2.0 * center - points[7];
  Pose3 pose = testing::Perturb(truth_, 1.0 * M_PI / 180.0, 0.05, &rng_);
  const PoseOnlyResult result = OptimizePose(camera_, PoseOnlyOptions(), points, uv, &pose);
  EXPECT_TRUE(result.converged);
  EXPECT_FALSE(result.inlier[3]);
  EXPECT_FALSE(result.inlier[5]);
  EXPECT_FALSE(result.inlier[7]);
  EXPECT_EQ(result.num_inliers, 997);
  EXPECT_LT(testing::PoseError(pose, truth_), 1e-9);
}

TEST_F(OptimizePoseTest, BadInputIsReportedAndLeavesThePoseUnchanged) {
  const Pose3 start = testing::Perturb(truth_, 1.0 * M_PI / 180.0, 0.05, &rng_);
  Pose3 pose = start;
  std::vector<Eigen::Vector2d> short_uv(observations_.uv.begin(), observations_.uv.end() - 1);
  PoseOnlyResult result =
      OptimizePose(camera_, PoseOnlyOptions(), observations_.points, short_uv, &pose);
  EXPECT_FALSE(result.converged);
  EXPECT_EQ(testing::PoseError(pose, start), 0.0);

  result = OptimizePose(camera_, PoseOnlyOptions(), {}, {}, &pose);
  EXPECT_FALSE(result.converged);
  EXPECT_EQ(result.num_inliers, 0);

  PoseOnlyOptions bad;
  bad.rounds = 0;
  result = OptimizePose(camera_, bad, observations_.points, observations_.uv, &pose);
  EXPECT_FALSE(result.converged);
  EXPECT_EQ(testing::PoseError(pose, start), 0.0);

  result =
      OptimizePose(camera_, PoseOnlyOptions(), observations_.points, observations_.uv, nullptr);
  EXPECT_FALSE(result.converged);
}

TEST(PoseOnlyOptionsTest, CheckRejectsBadValues) {
  Status why;
  EXPECT_TRUE((why = PoseOnlyOptions().Check()));
  auto expect_rejected = [](PoseOnlyOptions o) {
    Status reason;
    EXPECT_FALSE((reason = o.Check()));
    EXPECT_FALSE(reason.message().empty());
  };
  PoseOnlyOptions o;
  o.huber_delta_px = 0.0;
  expect_rejected(o);
  o = {};
  o.chi2_threshold = -1.0;
  expect_rejected(o);
  o = {};
  o.pixel_sigma = std::numeric_limits<double>::quiet_NaN();
  expect_rejected(o);
  o = {};
  o.rounds = 0;
  expect_rejected(o);
  o = {};
  o.max_iterations_per_round = 0;
  expect_rejected(o);
}

}  // namespace
}  // namespace m2s::slam
