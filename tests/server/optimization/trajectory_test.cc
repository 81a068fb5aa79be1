// OptimizeTrajectory and CentreAccelerationError: the residual against the divided difference
// computed by hand; a trajectory at constant velocity recovered from perturbed poses, a held
// frame left where it is;
// 0.5 px noise on a few bunched points averaged out by the prior; gaps and bad input.
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "optimization/cost_functions.h"
#include "optimization/problems.h"
#include "synthetic_scene.h"

namespace m2s::slam {
namespace {

constexpr double kFps = 30.0;

// camera_from_world of a camera at `centre` looking along +x (world z up).
Pose3 CameraAt(const Eigen::Vector3d& centre) {
  return LookAt(centre, centre + Eigen::Vector3d(1.0, 0.0, 0.0)).Inverse();
}

// Frames at `centres` (1 / kFps apart) seeing `points` exactly.
std::vector<TrajectoryFrame> Frames(const Camera& camera,
                                    const std::vector<Eigen::Vector3d>& centres,
                                    const std::vector<Eigen::Vector3d>& points) {
  std::vector<TrajectoryFrame> frames;
  for (size_t i = 0; i < centres.size(); ++i) {
    TrajectoryFrame f;
    f.t = static_cast<double>(i) / kFps;
    f.camera_from_world = CameraAt(centres[i]);
    for (const Eigen::Vector3d& p : points) {
      const Eigen::Vector3d pc = f.camera_from_world * p;
      if (pc.z() <= 0.0) continue;
      f.points_world.push_back(p);
      f.observations_uv.push_back(camera.Project(pc));
    }
    frames.push_back(std::move(f));
  }
  return frames;
}

// `count` points in a `size` cube around (depth, 0, 0) ahead of the cameras.
std::vector<Eigen::Vector3d> PointsAhead(int count, double size, double depth, std::mt19937* rng) {
  std::vector<Eigen::Vector3d> points = testing::RandomPoints(count, 0.5 * size, rng);
  for (Eigen::Vector3d& p : points) p.x() += depth;
  return points;
}

Eigen::Vector3d Centre(const Pose3& camera_from_world) {
  return camera_from_world.Inverse().translation();
}

TEST(CentreAccelerationError, IsTheSecondDividedDifferenceOfTheCentres) {
  // Centres 0, 1, 4 m along x at t = 0, 0.5, 1.5 s: velocities 2 and 3 m/s over intervals
  // whose midpoints are 1 s apart, so 1 m/s^2; halved sigma doubles it. Rotations differ
  // (the centre is -R^T t, not t).
  const Pose3 p0 = CameraAt({0.0, 0.0, 0.0});
  const Pose3 p1 = LookAt({1.0, 0.0, 0.0}, {1.0, 5.0, 0.0}).Inverse();
  const Pose3 p2 = LookAt({4.0, 0.0, 0.0}, {4.0, 0.0, -5.0}).Inverse();
  const auto a0 = PoseToParameters(p0), a1 = PoseToParameters(p1), a2 = PoseToParameters(p2);
  const double* parameters[] = {a0.data(), a1.data(), a2.data()};
  std::unique_ptr<ceres::CostFunction> cost(CentreAccelerationError::Create(0.5, 1.0, 2.0));
  double residuals[3];
  ASSERT_TRUE(cost->Evaluate(parameters, residuals, nullptr));
  EXPECT_NEAR(residuals[0], 2.0 * (2.0 * (3.0 - 2.0) / 1.5), 1e-12);
  EXPECT_NEAR(residuals[1], 0.0, 1e-12);
  EXPECT_NEAR(residuals[2], 0.0, 1e-12);
}

TEST(OptimizeTrajectory, RecoversAConstantVelocityWalkFromPerturbedPoses) {
  std::mt19937 rng(3);
  const Camera camera = testing::TestCamera();
  const std::vector<Eigen::Vector3d> points = PointsAhead(60, 2.0, 4.0, &rng);
  std::vector<Eigen::Vector3d> centres;
  for (int i = 0; i < 30; ++i) centres.emplace_back(0.0, 0.02 * i, 0.005 * i);
  std::vector<TrajectoryFrame> frames = Frames(camera, centres, points);
  for (size_t i = 0; i + 1 < frames.size(); ++i) {
    frames[i].camera_from_world = testing::Perturb(frames[i].camera_from_world, 0.01, 0.02, &rng);
  }
  // The last frame held at its true pose, its observations not needed.
  frames.back().fixed = true;
  frames.back().points_world.clear();
  frames.back().observations_uv.clear();
  const Pose3 held = frames.back().camera_from_world;
  TrajectoryOptions options;
  options.pixel_sigma = 0.5;
  const TrajectoryResult result = OptimizeTrajectory(camera, options, &frames);
  ASSERT_TRUE(result.success);
  EXPECT_EQ(result.priors, 28);
  // Zero acceleration and exact pixels: the truth is the minimum, at zero cost.
  EXPECT_LT(result.final_cost, 1e-12);
  for (size_t i = 0; i + 1 < frames.size(); ++i) {
    EXPECT_LT((Centre(frames[i].camera_from_world) - centres[i]).norm(), 1e-7) << i;
  }
  EXPECT_EQ(frames.back().camera_from_world.Matrix(), held.Matrix());
}

// 40 points in a 0.4 m cube 4 m ahead at 0.5 px: each view fixes its centre to centimetres
// (mostly along the view axis), independently from frame to frame. The walk curves at
// 0.5 m/s^2; a prior of 5 m/s^2 averages the noise over neighbouring frames.
TEST(OptimizeTrajectory, AMotionPriorAveragesTheNoiseOfLooseViews) {
  std::mt19937 rng(11);
  const Camera camera = testing::TestCamera();
  const std::vector<Eigen::Vector3d> points = PointsAhead(40, 0.4, 4.0, &rng);
  std::vector<Eigen::Vector3d> centres;
  for (int i = 0; i < 90; ++i) {
    const double t = i / kFps;
    centres.emplace_back(0.1 * std::sin(M_PI * t), 0.3 * t, 0.05 * std::cos(M_PI * t));
  }
  std::vector<TrajectoryFrame> frames = Frames(camera, centres, points);
  std::normal_distribution<double> pixel(0.0, 0.5);
  for (TrajectoryFrame& f : frames) {
    for (Eigen::Vector2d& uv : f.observations_uv) uv += Eigen::Vector2d(pixel(rng), pixel(rng));
  }
  auto rms_error = [&](const std::vector<TrajectoryFrame>& solved) {
    double sum = 0.0;
    for (size_t i = 0; i < solved.size(); ++i)
      sum += (Centre(solved[i].camera_from_world) - centres[i]).squaredNorm();
    return std::sqrt(sum / static_cast<double>(solved.size()));
  };
  // Each frame alone: a prior so weak (1e6 m/s^2) that it constrains nothing.
  TrajectoryOptions options;
  options.pixel_sigma = 0.5;
  options.max_iterations = 50;
  std::vector<TrajectoryFrame> alone = frames, smoothed = frames;
  options.acceleration_sigma = 1e6;
  ASSERT_TRUE(OptimizeTrajectory(camera, options, &alone).success);
  options.acceleration_sigma = 5.0;
  ASSERT_TRUE(OptimizeTrajectory(camera, options, &smoothed).success);
  const double alone_error = rms_error(alone), smoothed_error = rms_error(smoothed);
  // Measured: 38.2 mm alone, 14.4 mm with the prior.
  EXPECT_GT(alone_error, 0.02);
  EXPECT_LT(smoothed_error, 0.5 * alone_error);
}

TEST(OptimizeTrajectory, NoPriorAcrossAGap) {
  std::mt19937 rng(5);
  const Camera camera = testing::TestCamera();
  std::vector<Eigen::Vector3d> centres;
  for (int i = 0; i < 10; ++i) centres.emplace_back(0.0, 0.01 * i, 0.0);
  std::vector<TrajectoryFrame> frames = Frames(camera, centres, PointsAhead(30, 2.0, 4.0, &rng));
  for (size_t i = 5; i < frames.size(); ++i) frames[i].t += 0.2;  // 0.233 s between 4 and 5
  const TrajectoryResult result = OptimizeTrajectory(camera, TrajectoryOptions(), &frames);
  ASSERT_TRUE(result.success);
  EXPECT_EQ(result.priors, 3 + 3);  // (0,1,2)..(2,3,4) and (5,6,7)..(7,8,9)
}

TEST(OptimizeTrajectory, RejectsBadInputAndChangesNothing) {
  std::mt19937 rng(9);
  const Camera camera = testing::TestCamera();
  std::vector<Eigen::Vector3d> centres;
  for (int i = 0; i < 5; ++i) centres.emplace_back(0.0, 0.01 * i, 0.0);
  const std::vector<TrajectoryFrame> good =
      Frames(camera, centres, PointsAhead(30, 2.0, 4.0, &rng));
  auto rejected = [&](std::vector<TrajectoryFrame> frames, const TrajectoryOptions& options) {
    const std::vector<TrajectoryFrame> before = frames;
    const bool success = OptimizeTrajectory(camera, options, &frames).success;
    for (size_t i = 0; i < frames.size(); ++i) {
      EXPECT_EQ(frames[i].camera_from_world.Matrix(), before[i].camera_from_world.Matrix());
    }
    return !success;
  };
  std::vector<TrajectoryFrame> no_points = good;
  no_points[2].points_world.clear();
  no_points[2].observations_uv.clear();
  EXPECT_TRUE(rejected(no_points, TrajectoryOptions()));
  std::vector<TrajectoryFrame> mismatched = good;
  mismatched[1].observations_uv.pop_back();
  EXPECT_TRUE(rejected(mismatched, TrajectoryOptions()));
  std::vector<TrajectoryFrame> backwards = good;
  backwards[3].t = backwards[1].t;
  EXPECT_TRUE(rejected(backwards, TrajectoryOptions()));
  std::vector<TrajectoryFrame> nan_time = good;
  nan_time[0].t = std::nan("");
  EXPECT_TRUE(rejected(nan_time, TrajectoryOptions()));
  for (const double bad : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    TrajectoryOptions options;
    options.pixel_sigma = bad;
    EXPECT_TRUE(rejected(good, options)) << bad;
    options = TrajectoryOptions();
    options.acceleration_sigma = bad;
    EXPECT_TRUE(rejected(good, options)) << bad;
    options = TrajectoryOptions();
    options.max_gap_s = bad;
    EXPECT_TRUE(rejected(good, options)) << bad;
  }
  TrajectoryOptions no_iterations;
  no_iterations.max_iterations = 0;
  EXPECT_TRUE(rejected(good, no_iterations));
  EXPECT_FALSE(OptimizeTrajectory(camera, TrajectoryOptions(), nullptr).success);
}

}  // namespace
}  // namespace m2s::slam
