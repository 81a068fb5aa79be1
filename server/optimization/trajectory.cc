// A trajectory smoothed by a motion prior on Ceres (problems.h, OptimizeTrajectory): each
// frame's pose on PoseManifold fits its fixed points (PoseOnlyReprojectionError), and
// CentreAccelerationError ties consecutive frames; both under a Huber loss at their
// chi-square bounds.
#include <array>
#include <cmath>
#include <vector>

#include <ceres/loss_function.h>
#include <ceres/problem.h>
#include <ceres/solver.h>

#include "optimization/cost_functions.h"
#include "optimization/problems.h"
#include "optimization/sparse_solver.h"

namespace m2s::slam {

Status TrajectoryOptions::Check() const {
  const auto positive = [](double v) { return v > 0.0 && std::isfinite(v); };
  if (!positive(pixel_sigma)) {
    return Status::Error("TrajectoryOptions: pixel_sigma must be positive and finite");
  }
  if (!positive(acceleration_sigma)) {
    return Status::Error("TrajectoryOptions: acceleration_sigma must be positive and finite");
  }
  if (!positive(max_gap_s)) {
    return Status::Error("TrajectoryOptions: max_gap_s must be positive and finite");
  }
  if (max_iterations < 1) {
    return Status::Error("TrajectoryOptions: max_iterations must be at least 1");
  }
  return Status::Ok();
}

TrajectoryResult OptimizeTrajectory(const Camera& camera, const TrajectoryOptions& options,
                                    std::vector<TrajectoryFrame>* frames) {
  TrajectoryResult result;
  if (frames == nullptr || !options.Check()) return result;
  const size_t n = frames->size();
  for (size_t i = 0; i < n; ++i) {
    const TrajectoryFrame& f = (*frames)[i];
    if ((f.points_world.empty() && !f.fixed) || f.points_world.size() != f.observations_uv.size() ||
        !std::isfinite(f.t) || (i > 0 && !(f.t > (*frames)[i - 1].t))) {
      return result;
    }
  }
  std::vector<std::array<double, kPoseParameterSize>> parameters(n);
  for (size_t i = 0; i < n; ++i) parameters[i] = PoseToParameters((*frames)[i].camera_from_world);

  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  PoseManifold manifold;
  ceres::HuberLoss reprojection_loss(std::sqrt(kChi2TwoDof95));
  ceres::HuberLoss prior_loss(std::sqrt(kChi2ThreeDof95));
  const double inv_pixel_sigma = 1.0 / options.pixel_sigma;
  for (size_t i = 0; i < n; ++i) {
    const TrajectoryFrame& f = (*frames)[i];
    if (f.fixed) continue;  // its observations cannot move it
    for (size_t k = 0; k < f.points_world.size(); ++k) {
      problem.AddResidualBlock(
          PoseOnlyReprojectionError::Create(camera, f.points_world[k], f.observations_uv[k],
                                            inv_pixel_sigma),
          &reprojection_loss, parameters[i].data());
    }
    problem.SetManifold(parameters[i].data(), &manifold);
  }
  for (size_t i = 1; i + 1 < n; ++i) {
    const double dt01 = (*frames)[i].t - (*frames)[i - 1].t;
    const double dt12 = (*frames)[i + 1].t - (*frames)[i].t;
    if (dt01 > options.max_gap_s || dt12 > options.max_gap_s) continue;
    problem.AddResidualBlock(
        CentreAccelerationError::Create(dt01, dt12, 1.0 / options.acceleration_sigma), &prior_loss,
        parameters[i - 1].data(), parameters[i].data(), parameters[i + 1].data());
    ++result.priors;
  }
  for (size_t i = 0; i < n; ++i) {
    if ((*frames)[i].fixed && problem.HasParameterBlock(parameters[i].data())) {
      problem.SetManifold(parameters[i].data(), &manifold);
      problem.SetParameterBlockConstant(parameters[i].data());
    }
  }

  const ceres::Solver::Summary summary = internal::SolveSparse(&problem, options.max_iterations);
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.success = summary.IsSolutionUsable();
  if (!result.success) return result;
  for (size_t i = 0; i < n; ++i) {
    if (!(*frames)[i].fixed)
      (*frames)[i].camera_from_world = PoseFromParameters(parameters[i].data());
  }
  return result;
}

}  // namespace m2s::slam
