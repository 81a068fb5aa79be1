// Bundle adjustment on Ceres: ReprojectionError on (pose on PoseManifold, point), Huber loss,
// Schur elimination of the points (DENSE_SCHUR for small windows, SPARSE_SCHUR above), fixed
// keyframes and points held constant, gauge fixed by the first keyframe when none is fixed.
// ORB-SLAM2's two passes: solve robustly, drop chi-square outliers, solve again without the loss.
#include <array>
#include <chrono>
#include <cmath>
#include <memory>

#include <ceres/loss_function.h>
#include <ceres/ordered_groups.h>
#include <ceres/problem.h>
#include <ceres/solver.h>

#include "optimization/cost_functions.h"
#include "optimization/problems.h"

namespace m2s::slam {
namespace {

// Above this many variable keyframes the reduced camera system is solved sparsely.
constexpr int kDenseSchurMaxKeyframes = 40;

using PoseParameters = std::array<double, kPoseParameterSize>;

// Whitened squared residual of one observation, or a negative value when the point is not in
// front of the camera or not finite.
double Chi2(const Camera& camera, double inv_sigma, const PoseParameters& pose,
            const Eigen::Vector3d& point, const Eigen::Vector2d& uv) {
  double residuals[2];
  const ReprojectionError error(camera, uv, inv_sigma);
  if (!error(pose.data(), point.data(), residuals)) return -1.0;
  const double chi2 = residuals[0] * residuals[0] + residuals[1] * residuals[1];
  return std::isfinite(chi2) ? chi2 : -1.0;
}

ceres::LinearSolverType ChooseLinearSolver(int variable_keyframes) {
  if (variable_keyframes <= kDenseSchurMaxKeyframes) return ceres::DENSE_SCHUR;
  if (ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ||
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::EIGEN_SPARSE) ||
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::CX_SPARSE)) {
    return ceres::SPARSE_SCHUR;
  }
  return ceres::DENSE_SCHUR;
}

// One Ceres solve over the observations with use[i]; returns iterations, or -1 on failure.
int SolvePass(const Camera& camera, const BundleAdjustmentOptions& options,
              const std::vector<bool>& use, bool robust, std::vector<PoseParameters>* poses,
              BaProblem* problem) {
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem ceres_problem(problem_options);
  PoseManifold pose_manifold;
  ceres::HuberLoss huber(options.huber_delta_px / options.pixel_sigma);
  const double inv_sigma = 1.0 / options.pixel_sigma;

  const int num_keyframes = static_cast<int>(problem->keyframes.size());
  std::vector<bool> keyframe_used(num_keyframes, false);
  std::vector<bool> point_used(problem->points.size(), false);
  bool any_fixed = false;
  for (const BaKeyframe& keyframe : problem->keyframes) any_fixed = any_fixed || keyframe.fixed;
  // Gauge: without a fixed keyframe, the first keyframe with observations is held.
  int gauge_keyframe = -1;
  if (!any_fixed) {
    for (size_t i = 0; i < use.size() && gauge_keyframe < 0; ++i) {
      if (use[i]) gauge_keyframe = problem->observations[i].keyframe_index;
    }
    for (size_t i = 0; i < use.size(); ++i) {
      if (use[i] && problem->observations[i].keyframe_index < gauge_keyframe) {
        gauge_keyframe = problem->observations[i].keyframe_index;
      }
    }
  }
  auto keyframe_fixed = [&](int index) {
    return problem->keyframes[index].fixed || index == gauge_keyframe;
  };

  int residuals = 0;
  for (size_t i = 0; i < use.size(); ++i) {
    if (!use[i]) continue;
    const BaObservation& observation = problem->observations[i];
    BaPoint& point = problem->points[observation.point_index];
    if (point.fixed && keyframe_fixed(observation.keyframe_index)) continue;  // nothing to move
    double* pose = (*poses)[observation.keyframe_index].data();
    ceres_problem.AddResidualBlock(new AnalyticReprojectionError(camera, observation.uv, inv_sigma),
                                   robust ? &huber : nullptr, pose, point.position_world.data());
    if (!keyframe_used[observation.keyframe_index]) {
      keyframe_used[observation.keyframe_index] = true;
      ceres_problem.SetManifold(pose, &pose_manifold);
    }
    point_used[observation.point_index] = true;
    ++residuals;
  }
  if (residuals == 0) return 0;

  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  int variable_keyframes = 0;
  for (int k = 0; k < num_keyframes; ++k) {
    if (!keyframe_used[k]) continue;
    double* pose = (*poses)[k].data();
    if (keyframe_fixed(k)) {
      ceres_problem.SetParameterBlockConstant(pose);
    } else {
      ++variable_keyframes;
    }
    ordering->AddElementToGroup(pose, 1);
  }
  for (size_t p = 0; p < problem->points.size(); ++p) {
    if (!point_used[p]) continue;
    double* position = problem->points[p].position_world.data();
    if (problem->points[p].fixed) ceres_problem.SetParameterBlockConstant(position);
    ordering->AddElementToGroup(position, 0);
  }

  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ChooseLinearSolver(variable_keyframes);
  solver_options.linear_solver_ordering = ordering;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.num_threads = options.num_threads;
  solver_options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &ceres_problem, &summary);
  if (!summary.IsSolutionUsable()) return -1;
  return summary.num_successful_steps + summary.num_unsuccessful_steps;
}

}  // namespace

Status BundleAdjustmentOptions::Check() const {
  if (!(huber_delta_px > 0.0) || !std::isfinite(huber_delta_px)) {
    return Status::Error("BundleAdjustmentOptions: huber_delta_px must be positive and finite");
  }
  if (!(chi2_threshold > 0.0) || !std::isfinite(chi2_threshold)) {
    return Status::Error("BundleAdjustmentOptions: chi2_threshold must be positive and finite");
  }
  if (!(pixel_sigma > 0.0) || !std::isfinite(pixel_sigma)) {
    return Status::Error("BundleAdjustmentOptions: pixel_sigma must be positive and finite");
  }
  if (max_iterations < 1)
    return Status::Error("BundleAdjustmentOptions: max_iterations must be >= 1");
  if (num_threads < 1) return Status::Error("BundleAdjustmentOptions: num_threads must be >= 1");
  return Status::Ok();
}

BundleAdjustmentResult BundleAdjust(const Camera& camera, const BundleAdjustmentOptions& options,
                                    BaProblem* problem) {
  const auto start = std::chrono::steady_clock::now();
  BundleAdjustmentResult result;
  if (problem == nullptr) return result;
  const size_t num_observations = problem->observations.size();
  result.outlier.assign(num_observations, true);
  if (!options.Check() || !camera.Check()) return result;
  const int num_keyframes = static_cast<int>(problem->keyframes.size());
  const int num_points = static_cast<int>(problem->points.size());
  for (const BaObservation& observation : problem->observations) {
    if (observation.keyframe_index < 0 || observation.keyframe_index >= num_keyframes ||
        observation.point_index < 0 || observation.point_index >= num_points) {
      return result;  // malformed problem: nothing is changed
    }
  }
  std::vector<PoseParameters> poses(num_keyframes);
  for (int k = 0; k < num_keyframes; ++k) {
    if (!problem->keyframes[k].camera_from_world.AllFinite()) return result;
    poses[k] = PoseToParameters(problem->keyframes[k].camera_from_world);
  }
  for (const BaPoint& point : problem->points) {
    if (!point.position_world.allFinite()) return result;
  }

  // Observations not in front of their camera (or not finite) are outliers from the start.
  const double inv_sigma = 1.0 / options.pixel_sigma;
  std::vector<bool> use(num_observations);
  double sum = 0.0;
  int used = 0;
  for (size_t i = 0; i < num_observations; ++i) {
    const BaObservation& o = problem->observations[i];
    const double chi2 = o.uv.allFinite() ? Chi2(camera, inv_sigma, poses[o.keyframe_index],
                                                problem->points[o.point_index].position_world, o.uv)
                                         : -1.0;
    use[i] = chi2 >= 0.0;
    if (use[i]) {
      sum += chi2;
      ++used;
    }
  }
  result.initial_rmse_px = used > 0 ? options.pixel_sigma * std::sqrt(sum / used) : 0.0;

  // Classifies every observation by chi-square at the current estimate.
  auto classify = [&]() {
    int outliers = 0;
    for (size_t i = 0; i < num_observations; ++i) {
      const BaObservation& o = problem->observations[i];
      const double chi2 = o.uv.allFinite()
                              ? Chi2(camera, inv_sigma, poses[o.keyframe_index],
                                     problem->points[o.point_index].position_world, o.uv)
                              : -1.0;
      result.outlier[i] = chi2 < 0.0 || chi2 > options.chi2_threshold;
      outliers += result.outlier[i] ? 1 : 0;
    }
    return outliers;
  };

  int iterations = SolvePass(camera, options, use, /*robust=*/true, &poses, problem);
  bool success = iterations >= 0;
  int outliers = classify();
  if (success && options.second_pass_without_outliers && outliers > 0) {
    for (size_t i = 0; i < num_observations; ++i) use[i] = !result.outlier[i];
    const int more = SolvePass(camera, options, use, /*robust=*/false, &poses, problem);
    success = more >= 0;
    iterations += std::max(more, 0);
    outliers = classify();
  }

  for (int k = 0; k < num_keyframes; ++k) {
    problem->keyframes[k].camera_from_world = PoseFromParameters(poses[k].data());
  }
  sum = 0.0;
  used = 0;
  for (size_t i = 0; i < num_observations; ++i) {
    if (result.outlier[i]) continue;
    const BaObservation& o = problem->observations[i];
    sum += Chi2(camera, inv_sigma, poses[o.keyframe_index],
                problem->points[o.point_index].position_world, o.uv);
    ++used;
  }
  result.final_rmse_px = used > 0 ? options.pixel_sigma * std::sqrt(sum / used) : 0.0;
  result.success = success;
  result.iterations = iterations;
  result.solve_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace m2s::slam
