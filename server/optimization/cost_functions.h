// Ceres cost functors of the SLAM back-end, one per residual, in the style of Ceres's own
// examples: templated operator(), the measurement stored as const members, static Create().
//
// Parameter layouts (shared with the solvers in this folder):
//   pose (7):  camera_from_world as [qx, qy, qz, qw, tx, ty, tz] (Eigen quaternion order),
//              optimised on PoseManifold() = EigenQuaternionManifold x EuclideanManifold<3>.
//   point (3): position in the world frame.
//   sim3 (8):  world_from_camera as [qx, qy, qz, qw, tx, ty, tz, log(scale)], optimised on
//              Sim3Manifold() = EigenQuaternionManifold x EuclideanManifold<4>.
// Residuals are whitened: pixel errors are divided by the feature noise sigma, so the squared
// norm of a reprojection residual is the chi-square statistic.
//
//   ceres::CostFunction* cost = ReprojectionError::Create(camera, uv, 1.0 / sigma);
//   problem.AddResidualBlock(cost, loss, pose7, point3);
//
// Thread-safety: the functors are immutable after construction.
#pragma once

#include <array>
#include <cmath>

#include <ceres/autodiff_cost_function.h>
#include <ceres/manifold.h>
#include <ceres/product_manifold.h>
#include <ceres/sized_cost_function.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"

namespace m2s::slam {

inline constexpr int kPoseParameterSize = 7;
inline constexpr int kSim3ParameterSize = 8;

using PoseManifold =
    ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>;
using Sim3Manifold =
    ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<4>>;

// Packs / unpacks a Pose3 to the 7-parameter layout above.
inline std::array<double, kPoseParameterSize> PoseToParameters(const Pose3& pose) {
  const Eigen::Quaterniond& q = pose.rotation();
  const Eigen::Vector3d& t = pose.translation();
  return {q.x(), q.y(), q.z(), q.w(), t.x(), t.y(), t.z()};
}
inline Pose3 PoseFromParameters(const double* p) {
  return Pose3(Eigen::Quaterniond(p[3], p[0], p[1], p[2]), Eigen::Vector3d(p[4], p[5], p[6]));
}
// Packs / unpacks a Sim3 to the 8-parameter layout above (scale must be positive).
std::array<double, kSim3ParameterSize> Sim3ToParameters(const Sim3& sim3);
Sim3 Sim3FromParameters(const double* p);

namespace internal {

// Projects a camera-frame point; false when it is not in front of the camera.
template <typename T>
bool ProjectToPixels(const T* intrinsics, const Eigen::Matrix<T, 3, 1>& p_camera, T* uv) {
  if (!(p_camera[2] > T(0))) return false;
  const T inv_z = T(1) / p_camera[2];
  uv[0] = intrinsics[0] * p_camera[0] * inv_z + intrinsics[2];
  uv[1] = intrinsics[1] * p_camera[1] * inv_z + intrinsics[3];
  return true;
}

}  // namespace internal

// Reprojection of a map point into a keyframe: both the pose and the point are optimised.
class ReprojectionError {
 public:
  ReprojectionError(const Camera& camera, const Eigen::Vector2d& observed_uv, double inv_sigma)
      : fx_(camera.fx),
        fy_(camera.fy),
        cx_(camera.cx),
        cy_(camera.cy),
        observed_u_(observed_uv.x()),
        observed_v_(observed_uv.y()),
        inv_sigma_(inv_sigma) {}

  template <typename T>
  bool operator()(const T* const camera_from_world, const T* const point_world,
                  T* residuals) const {
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(camera_from_world);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(camera_from_world + 4);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> point(point_world);
    const Eigen::Matrix<T, 3, 1> p_camera = rotation * point + translation;
    const T intrinsics[4] = {T(fx_), T(fy_), T(cx_), T(cy_)};
    T uv[2];
    if (!internal::ProjectToPixels(intrinsics, p_camera, uv)) return false;
    residuals[0] = (uv[0] - T(observed_u_)) * T(inv_sigma_);
    residuals[1] = (uv[1] - T(observed_v_)) * T(inv_sigma_);
    return true;
  }

  static ceres::CostFunction* Create(const Camera& camera, const Eigen::Vector2d& observed_uv,
                                     double inv_sigma) {
    return new ceres::AutoDiffCostFunction<ReprojectionError, 2, kPoseParameterSize, 3>(
        new ReprojectionError(camera, observed_uv, inv_sigma));
  }

 private:
  const double fx_, fy_, cx_, cy_;
  const double observed_u_, observed_v_;
  const double inv_sigma_;
};

// ReprojectionError with hand-written Jacobians (same residual, same parameter layout): about
// 3x cheaper to evaluate than autodiff, used by BundleAdjust. With q = (v, w) unit,
// R p = p + 2 w (v x p) + 2 v x (v x p), so d(Rp)/dw = 2 (v x p) and
// d(Rp)/dv = -2 w [p]x + 2 ((v.p) I + v p^T - 2 p v^T).
class AnalyticReprojectionError final : public ceres::SizedCostFunction<2, kPoseParameterSize, 3> {
 public:
  AnalyticReprojectionError(const Camera& camera, const Eigen::Vector2d& observed_uv,
                            double inv_sigma)
      : fx_(camera.fx),
        fy_(camera.fy),
        cx_(camera.cx),
        cy_(camera.cy),
        observed_(observed_uv),
        inv_sigma_(inv_sigma) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Eigen::Map<const Eigen::Vector3d> v(parameters[0]);
    const double w = parameters[0][3];
    const Eigen::Map<const Eigen::Vector3d> t(parameters[0] + 4);
    const Eigen::Map<const Eigen::Vector3d> p(parameters[1]);
    const Eigen::Vector3d vxp = v.cross(p);
    const Eigen::Vector3d rotated = p + 2.0 * w * vxp + 2.0 * v.cross(vxp);
    const Eigen::Vector3d pc = rotated + t;
    if (!(pc.z() > 0.0)) return false;
    const double inv_z = 1.0 / pc.z();
    residuals[0] = (fx_ * pc.x() * inv_z + cx_ - observed_.x()) * inv_sigma_;
    residuals[1] = (fy_ * pc.y() * inv_z + cy_ - observed_.y()) * inv_sigma_;
    if (jacobians == nullptr) return true;
    Eigen::Matrix<double, 2, 3> d_pc;  // d residual / d p_camera
    d_pc << fx_ * inv_z, 0.0, -fx_ * pc.x() * inv_z * inv_z, 0.0, fy_ * inv_z,
        -fy_ * pc.y() * inv_z * inv_z;
    d_pc *= inv_sigma_;
    if (jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 2, kPoseParameterSize, Eigen::RowMajor>> j(jacobians[0]);
      Eigen::Matrix<double, 3, 4> d_rotated;
      Eigen::Matrix3d p_hat;
      p_hat << 0.0, -p.z(), p.y(), p.z(), 0.0, -p.x(), -p.y(), p.x(), 0.0;
      d_rotated.leftCols<3>() =
          -2.0 * w * p_hat + 2.0 * (v.dot(p) * Eigen::Matrix3d::Identity() + v * p.transpose() -
                                    2.0 * p * v.transpose());
      d_rotated.col(3) = 2.0 * vxp;
      j.leftCols<4>() = d_pc * d_rotated;
      j.rightCols<3>() = d_pc;
    }
    if (jacobians[1] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> j(jacobians[1]);
      const Eigen::Quaterniond q(w, v.x(), v.y(), v.z());
      j = d_pc * q.toRotationMatrix();
    }
    return true;
  }

 private:
  const double fx_, fy_, cx_, cy_;
  const Eigen::Vector2d observed_;
  const double inv_sigma_;
};

// Reprojection of a fixed 3-D point (held as a member): only the pose is optimised (tracking).
class PoseOnlyReprojectionError {
 public:
  PoseOnlyReprojectionError(const Camera& camera, const Eigen::Vector3d& point_world,
                            const Eigen::Vector2d& observed_uv, double inv_sigma)
      : fx_(camera.fx),
        fy_(camera.fy),
        cx_(camera.cx),
        cy_(camera.cy),
        point_world_(point_world),
        observed_u_(observed_uv.x()),
        observed_v_(observed_uv.y()),
        inv_sigma_(inv_sigma) {}

  template <typename T>
  bool operator()(const T* const camera_from_world, T* residuals) const {
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(camera_from_world);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(camera_from_world + 4);
    const Eigen::Matrix<T, 3, 1> p_camera = rotation * point_world_.cast<T>() + translation;
    const T intrinsics[4] = {T(fx_), T(fy_), T(cx_), T(cy_)};
    T uv[2];
    if (!internal::ProjectToPixels(intrinsics, p_camera, uv)) return false;
    residuals[0] = (uv[0] - T(observed_u_)) * T(inv_sigma_);
    residuals[1] = (uv[1] - T(observed_v_)) * T(inv_sigma_);
    return true;
  }

  static ceres::CostFunction* Create(const Camera& camera, const Eigen::Vector3d& point_world,
                                     const Eigen::Vector2d& observed_uv, double inv_sigma) {
    return new ceres::AutoDiffCostFunction<PoseOnlyReprojectionError, 2, kPoseParameterSize>(
        new PoseOnlyReprojectionError(camera, point_world, observed_uv, inv_sigma));
  }

 private:
  const double fx_, fy_, cx_, cy_;
  const Eigen::Vector3d point_world_;
  const double observed_u_, observed_v_;
  const double inv_sigma_;
};

// The acceleration of the camera's centre at the middle of three consecutive camera_from_world
// poses (times t0 < t1 < t2), as the second divided difference of the centres
// c = -R^T t: 2 ((c2 - c1) / (t2 - t1) - (c1 - c0) / (t1 - t0)) / (t2 - t0), in m/s^2,
// multiplied by inv_sigma (the prior's 1 / sigma).
class CentreAccelerationError {
 public:
  CentreAccelerationError(double dt01, double dt12, double inv_sigma)
      : dt01_(dt01), dt12_(dt12), inv_sigma_(inv_sigma) {}

  template <typename T>
  bool operator()(const T* const pose0, const T* const pose1, const T* const pose2,
                  T* residuals) const {
    const Eigen::Matrix<T, 3, 1> c0 = Centre(pose0), c1 = Centre(pose1), c2 = Centre(pose2);
    const Eigen::Matrix<T, 3, 1> a =
        ((c2 - c1) / T(dt12_) - (c1 - c0) / T(dt01_)) * T(2.0 / (dt01_ + dt12_));
    for (int i = 0; i < 3; ++i) residuals[i] = a[i] * T(inv_sigma_);
    return true;
  }

  static ceres::CostFunction* Create(double dt01, double dt12, double inv_sigma) {
    return new ceres::AutoDiffCostFunction<CentreAccelerationError, 3, kPoseParameterSize,
                                           kPoseParameterSize, kPoseParameterSize>(
        new CentreAccelerationError(dt01, dt12, inv_sigma));
  }

 private:
  template <typename T>
  static Eigen::Matrix<T, 3, 1> Centre(const T* camera_from_world) {
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(camera_from_world);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(camera_from_world + 4);
    return -(rotation.conjugate() * translation);
  }

  const double dt01_, dt12_;
  const double inv_sigma_;
};

// Relative Sim3 constraint between two world_from_camera nodes (pose graph). With the
// estimate E = from^-1 * to and the measurement M = from_from_to, the error M^-1 * E is mapped
// to 7 residuals: 2 * vec(q) of its rotation (w >= 0), its translation, and its log scale, all
// multiplied by sqrt(weight).
class RelativeSim3Error {
 public:
  RelativeSim3Error(const Sim3& from_from_to, double weight)
      : measured_rotation_inverse_(from_from_to.rotation().conjugate()),
        measured_translation_(from_from_to.translation()),
        measured_log_scale_(std::log(from_from_to.scale())),
        sqrt_weight_(std::sqrt(weight)) {}

  template <typename T>
  bool operator()(const T* const world_from_from, const T* const world_from_to,
                  T* residuals) const {
    using std::exp;
    using Vector3 = Eigen::Matrix<T, 3, 1>;
    const Eigen::Map<const Eigen::Quaternion<T>> q_a(world_from_from);
    const Eigen::Map<const Vector3> t_a(world_from_from + 4);
    const T& log_s_a = world_from_from[7];
    const Eigen::Map<const Eigen::Quaternion<T>> q_b(world_from_to);
    const Eigen::Map<const Vector3> t_b(world_from_to + 4);
    const T& log_s_b = world_from_to[7];

    // Estimated from_from_to = a^-1 * b.
    const Eigen::Quaternion<T> q_a_inverse = q_a.conjugate();
    const Eigen::Quaternion<T> q_estimate = q_a_inverse * q_b;
    const Vector3 t_estimate = (q_a_inverse * (t_b - t_a)) * exp(-log_s_a);
    const T log_s_estimate = log_s_b - log_s_a;

    // Error M^-1 * E.
    const Eigen::Quaternion<T> m_inverse = measured_rotation_inverse_.cast<T>();
    Eigen::Quaternion<T> q_error = m_inverse * q_estimate;
    if (q_error.w() < T(0)) q_error.coeffs() = -q_error.coeffs();
    const Vector3 t_error = (m_inverse * (t_estimate - measured_translation_.cast<T>())) *
                            T(std::exp(-measured_log_scale_));
    const T w(sqrt_weight_);
    residuals[0] = T(2) * q_error.x() * w;
    residuals[1] = T(2) * q_error.y() * w;
    residuals[2] = T(2) * q_error.z() * w;
    residuals[3] = t_error.x() * w;
    residuals[4] = t_error.y() * w;
    residuals[5] = t_error.z() * w;
    residuals[6] = (log_s_estimate - T(measured_log_scale_)) * w;
    return true;
  }

  static ceres::CostFunction* Create(const Sim3& from_from_to, double weight) {
    return new ceres::AutoDiffCostFunction<RelativeSim3Error, 7, kSim3ParameterSize,
                                           kSim3ParameterSize>(
        new RelativeSim3Error(from_from_to, weight));
  }

 private:
  const Eigen::Quaterniond measured_rotation_inverse_;
  const Eigen::Vector3d measured_translation_;
  const double measured_log_scale_;
  const double sqrt_weight_;
};

}  // namespace m2s::slam
