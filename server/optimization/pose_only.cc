// Pose-only optimisation for tracking: ORB-SLAM2's rounds of "optimise on the current inliers,
// then classify every observation by chi-square", with a Huber loss in the first half of the
// rounds. The default solver is a hand-written Levenberg-Marquardt on the 6-dof pose with
// analytic Jacobians (one pass over the observations per iteration, no allocation); the same
// problem on Ceres (PoseOnlyReprojectionError on PoseManifold) is kept as the reference.
#include <algorithm>
#include <array>
#include <cmath>
#include <memory>

#include <ceres/loss_function.h>
#include <ceres/problem.h>
#include <ceres/solver.h>
#include <Eigen/Cholesky>

#include "optimization/cost_functions.h"
#include "optimization/problems.h"

namespace m2s::slam {
namespace {

// Points closer than this (in the camera frame, map units) are not used.
constexpr double kMinDepth = 1e-6;
// Fewer inliers than this cannot constrain 6 dof robustly: the result is not converged.
constexpr int kMinInliers = 3;
// Levenberg-Marquardt damping schedule and stopping tolerances.
constexpr double kInitialLambda = 1e-5;
constexpr double kMaxLambda = 1e8;
constexpr double kStepTolerance = 1e-12;  // squared norm of the 6-vector update
constexpr double kRelativeCostTolerance = 1e-12;

using Matrix6 = Eigen::Matrix<double, 6, 6>;
using Vector6 = Eigen::Matrix<double, 6, 1>;

struct Intrinsics {
  double fx, fy, cx, cy, inv_sigma;
};

// The whitened residual of one observation, or false when the point is behind the camera.
inline bool Residual(const Intrinsics& k, const Eigen::Matrix3d& rotation,
                     const Eigen::Vector3d& translation, const Eigen::Vector3d& point,
                     const Eigen::Vector2d& uv, Eigen::Vector3d* p_camera, Eigen::Vector2d* e) {
  *p_camera = rotation * point + translation;
  if (!((*p_camera).z() > kMinDepth)) return false;
  const double inv_z = 1.0 / p_camera->z();
  (*e)[0] = (k.fx * p_camera->x() * inv_z + k.cx - uv.x()) * k.inv_sigma;
  (*e)[1] = (k.fy * p_camera->y() * inv_z + k.cy - uv.y()) * k.inv_sigma;
  return true;
}

// Huber on the squared whitened residual s (Ceres's convention): cost and IRLS weight.
inline void Huber(double s, double delta, bool robust, double* rho, double* weight) {
  if (!robust || s <= delta * delta) {
    *rho = s;
    *weight = 1.0;
    return;
  }
  const double r = std::sqrt(s);
  *rho = 2.0 * delta * r - delta * delta;
  *weight = delta / r;
}

// Cost at (rotation, translation) over active observations; with h/g, also the Gauss-Newton
// system for the left perturbation [rho, phi] (p' = Exp(phi) p + rho). Only the upper triangle
// of h is accumulated (scalar code: the Jacobian rows have known zeros), then mirrored.
double Linearise(const Intrinsics& k, const Eigen::Matrix3d& rotation,
                 const Eigen::Vector3d& translation, const std::vector<Eigen::Vector3d>& points,
                 const std::vector<Eigen::Vector2d>& uvs, const std::vector<bool>& active,
                 double delta, bool robust, Matrix6* h, Vector6* g) {
  double cost = 0.0;
  // Upper triangle of H, row-major (21 entries), and g.
  double hu[21] = {};
  double gv[6] = {};
  const double fx = k.fx * k.inv_sigma;
  const double fy = k.fy * k.inv_sigma;
  Eigen::Vector3d p;
  Eigen::Vector2d e;
  const size_t n = points.size();
  for (size_t i = 0; i < n; ++i) {
    if (!active[i]) continue;
    if (!Residual(k, rotation, translation, points[i], uvs[i], &p, &e)) continue;
    double rho = 0.0;
    double weight = 1.0;
    Huber(e.squaredNorm(), delta, robust, &rho, &weight);
    cost += rho;
    if (h == nullptr) continue;
    const double inv_z = 1.0 / p.z();
    const double x = p.x() * inv_z;
    const double y = p.y() * inv_z;
    // Row a: d e_u / d [rho, phi] = [a0, 0, a2, a3, a4, a5]; row b: [0, b1, b2, b3, b4, b5].
    const double a0 = fx * inv_z, a2 = -fx * x * inv_z, a3 = -fx * x * y, a4 = fx * (1.0 + x * x),
                 a5 = -fx * y;
    const double b1 = fy * inv_z, b2 = -fy * y * inv_z, b3 = -fy * (1.0 + y * y), b4 = fy * x * y,
                 b5 = fy * x;
    const double a[6] = {a0, 0.0, a2, a3, a4, a5};
    const double b[6] = {0.0, b1, b2, b3, b4, b5};
    const double eu = weight * e.x();
    const double ev = weight * e.y();
    int index = 0;
    for (int r = 0; r < 6; ++r) {
      const double wa = weight * a[r];
      const double wb = weight * b[r];
      for (int c = r; c < 6; ++c) hu[index++] += wa * a[c] + wb * b[c];
      gv[r] += a[r] * eu + b[r] * ev;
    }
  }
  if (h != nullptr) {
    int index = 0;
    for (int r = 0; r < 6; ++r) {
      for (int c = r; c < 6; ++c) (*h)(r, c) = (*h)(c, r) = hu[index++];
      (*g)[r] = gv[r];
    }
  }
  return cost;
}

Eigen::Quaterniond ExpRotation(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  if (angle < 1e-10)
    return Eigen::Quaterniond(1.0, 0.5 * phi.x(), 0.5 * phi.y(), 0.5 * phi.z()).normalized();
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, phi / angle));
}

// Levenberg-Marquardt on the active observations; true when it stopped on a tolerance.
bool SolveRound(const Intrinsics& k, const std::vector<Eigen::Vector3d>& points,
                const std::vector<Eigen::Vector2d>& uvs, const std::vector<bool>& active,
                double delta, bool robust, int max_iterations, Eigen::Quaterniond* rotation,
                Eigen::Vector3d* translation) {
  Matrix6 h;
  Vector6 g;
  Eigen::Matrix3d r = rotation->toRotationMatrix();
  double cost = Linearise(k, r, *translation, points, uvs, active, delta, robust, &h, &g);
  double lambda = kInitialLambda;
  Matrix6 h_new;
  Vector6 g_new;
  for (int iteration = 0; iteration < max_iterations; ++iteration) {
    Matrix6 damped = h;
    damped.diagonal() += lambda * h.diagonal().cwiseMax(1e-12);
    const Vector6 step = -damped.ldlt().solve(g);
    if (!step.allFinite()) return false;
    const Eigen::Quaterniond dq = ExpRotation(step.tail<3>());
    const Eigen::Quaterniond candidate_rotation = (dq * *rotation).normalized();
    const Eigen::Vector3d candidate_translation = dq * *translation + step.head<3>();
    const Eigen::Matrix3d candidate_r = candidate_rotation.toRotationMatrix();
    const double candidate_cost = Linearise(k, candidate_r, candidate_translation, points, uvs,
                                            active, delta, robust, &h_new, &g_new);
    if (candidate_cost <= cost) {
      const bool small_decrease = cost - candidate_cost <= kRelativeCostTolerance * cost;
      *rotation = candidate_rotation;
      *translation = candidate_translation;
      r = candidate_r;
      cost = candidate_cost;
      h = h_new;
      g = g_new;
      lambda = std::max(lambda * 0.1, 1e-12);
      if (small_decrease || step.squaredNorm() < kStepTolerance) return true;
    } else {
      if (step.squaredNorm() < kStepTolerance) return true;
      lambda *= 10.0;
      if (lambda > kMaxLambda) return true;  // no downhill step exists: at a minimum
    }
  }
  return false;
}

// The same round on Ceres (reference implementation).
bool SolveRoundCeres(const Camera& camera, const PoseOnlyOptions& options,
                     const std::vector<Eigen::Vector3d>& points,
                     const std::vector<Eigen::Vector2d>& uvs, const std::vector<bool>& active,
                     bool robust, Eigen::Quaterniond* rotation, Eigen::Vector3d* translation) {
  std::array<double, kPoseParameterSize> pose = PoseToParameters(Pose3(*rotation, *translation));
  ceres::Problem problem;
  ceres::LossFunction* loss =
      robust ? new ceres::HuberLoss(options.huber_delta_px / options.pixel_sigma) : nullptr;
  const double inv_sigma = 1.0 / options.pixel_sigma;
  int residuals = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!active[i]) continue;
    if (!((*rotation * points[i] + *translation).z() > kMinDepth)) continue;
    problem.AddResidualBlock(
        PoseOnlyReprojectionError::Create(camera, points[i], uvs[i], inv_sigma), loss, pose.data());
    ++residuals;
  }
  if (residuals == 0) {
    delete loss;
    return false;
  }
  problem.SetManifold(pose.data(), new PoseManifold());
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.max_num_iterations = options.max_iterations_per_round;
  solver_options.logging_type = ceres::SILENT;
  solver_options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  const Pose3 solved = PoseFromParameters(pose.data());
  *rotation = solved.rotation();
  *translation = solved.translation();
  return summary.termination_type == ceres::CONVERGENCE;
}

}  // namespace

Status PoseOnlyOptions::Check() const {
  if (!(huber_delta_px > 0.0) || !std::isfinite(huber_delta_px)) {
    return Status::Error("PoseOnlyOptions: huber_delta_px must be positive and finite");
  }
  if (!(chi2_threshold > 0.0) || !std::isfinite(chi2_threshold)) {
    return Status::Error("PoseOnlyOptions: chi2_threshold must be positive and finite");
  }
  if (!(pixel_sigma > 0.0) || !std::isfinite(pixel_sigma)) {
    return Status::Error("PoseOnlyOptions: pixel_sigma must be positive and finite");
  }
  if (rounds < 1) return Status::Error("PoseOnlyOptions: rounds must be at least 1");
  if (max_iterations_per_round < 1) {
    return Status::Error("PoseOnlyOptions: max_iterations_per_round must be at least 1");
  }
  return Status::Ok();
}

PoseOnlyResult OptimizePose(const Camera& camera, const PoseOnlyOptions& options,
                            const std::vector<Eigen::Vector3d>& points_world,
                            const std::vector<Eigen::Vector2d>& observations_uv,
                            Pose3* camera_from_world) {
  PoseOnlyResult result;
  const size_t n = points_world.size();
  result.inlier.assign(n, false);
  if (camera_from_world == nullptr || observations_uv.size() != n ||
      !camera_from_world->AllFinite() || !options.Check() || !camera.Check()) {
    return result;
  }
  // Non-finite inputs are outliers from the start; everything else starts as an inlier.
  std::vector<bool>& active = result.inlier;
  for (size_t i = 0; i < n; ++i) {
    active[i] = points_world[i].allFinite() && observations_uv[i].allFinite();
  }
  const Intrinsics k{camera.fx, camera.fy, camera.cx, camera.cy, 1.0 / options.pixel_sigma};
  const double delta = options.huber_delta_px / options.pixel_sigma;
  Eigen::Quaterniond rotation = camera_from_world->rotation();
  Eigen::Vector3d translation = camera_from_world->translation();
  const int robust_rounds = std::max(1, options.rounds / 2);

  bool converged = false;
  bool changed = true;  // did the last classification change the active set?
  int num_inliers = static_cast<int>(std::count(active.begin(), active.end(), true));
  for (int round = 0; round < options.rounds && num_inliers >= kMinInliers; ++round) {
    const bool robust = round < robust_rounds;
    // Same inliers, same loss and a converged previous round: this round would change nothing.
    if (round > 0 && converged && !changed && robust == (round - 1 < robust_rounds)) continue;
    const Eigen::Quaterniond rotation_before = rotation;
    const Eigen::Vector3d translation_before = translation;
    converged = options.use_ceres
                    ? SolveRoundCeres(camera, options, points_world, observations_uv, active,
                                      robust, &rotation, &translation)
                    : SolveRound(k, points_world, observations_uv, active, delta, robust,
                                 options.max_iterations_per_round, &rotation, &translation);
    if (!rotation.coeffs().allFinite() || !translation.allFinite()) {
      rotation = rotation_before;
      translation = translation_before;
      converged = false;
      break;
    }
    // Classify every finite observation (outliers of earlier rounds may come back).
    const Eigen::Matrix3d r = rotation.toRotationMatrix();
    Eigen::Vector3d p;
    Eigen::Vector2d e;
    num_inliers = 0;
    changed = false;
    for (size_t i = 0; i < n; ++i) {
      const bool finite = points_world[i].allFinite() && observations_uv[i].allFinite();
      const bool inlier =
          finite && Residual(k, r, translation, points_world[i], observations_uv[i], &p, &e) &&
          e.squaredNorm() <= options.chi2_threshold;
      changed = changed || inlier != active[i];
      active[i] = inlier;
      num_inliers += inlier ? 1 : 0;
    }
  }

  result.num_inliers = num_inliers;
  result.converged = converged && num_inliers >= kMinInliers;
  if (num_inliers > 0) {
    const Eigen::Matrix3d r = rotation.toRotationMatrix();
    const Intrinsics pixels{k.fx, k.fy, k.cx, k.cy, 1.0};
    Eigen::Vector3d p;
    Eigen::Vector2d e;
    double sum = 0.0;
    for (size_t i = 0; i < n; ++i) {
      if (active[i] &&
          Residual(pixels, r, translation, points_world[i], observations_uv[i], &p, &e)) {
        sum += e.squaredNorm();
      }
    }
    result.final_rmse_px = std::sqrt(sum / num_inliers);
  }
  *camera_from_world = Pose3(rotation, translation);
  return result;
}

}  // namespace m2s::slam
