#include "m2s/common/geometry.h"

#include <cmath>

namespace m2s {
namespace {

// Left Jacobian of SO(3) and its inverse, used by the SE3 exponential and logarithm.
Eigen::Matrix3d LeftJacobian(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d w = Hat(phi);
  if (theta < 1e-8) return Eigen::Matrix3d::Identity() + 0.5 * w;
  const double t2 = theta * theta;
  return Eigen::Matrix3d::Identity() + (1.0 - std::cos(theta)) / t2 * w +
         (theta - std::sin(theta)) / (t2 * theta) * w * w;
}

Eigen::Matrix3d LeftJacobianInverse(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d w = Hat(phi);
  if (theta < 1e-8) return Eigen::Matrix3d::Identity() - 0.5 * w;
  const double half = 0.5 * theta;
  const double coef = (1.0 - half * std::cos(half) / std::sin(half)) / (theta * theta);
  return Eigen::Matrix3d::Identity() - 0.5 * w + coef * w * w;
}

}  // namespace

Eigen::Matrix3d Hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

double RotationAngle(const Eigen::Quaterniond& q) {
  const double w = std::min(1.0, std::abs(q.normalized().w()));
  return 2.0 * std::acos(w);
}

Pose3 Pose3::Exp(const Eigen::Matrix<double, 6, 1>& rho_phi) {
  const Eigen::Vector3d rho = rho_phi.head<3>();
  const Eigen::Vector3d phi = rho_phi.tail<3>();
  const double theta = phi.norm();
  Eigen::Quaterniond q = theta < 1e-12
                             ? Eigen::Quaterniond(1, 0.5 * phi.x(), 0.5 * phi.y(), 0.5 * phi.z())
                             : Eigen::Quaterniond(Eigen::AngleAxisd(theta, phi / theta));
  return Pose3(q.normalized(), LeftJacobian(phi) * rho);
}

Eigen::Matrix<double, 6, 1> Pose3::Log() const {
  const Eigen::AngleAxisd aa(rotation_);
  Eigen::Vector3d phi = aa.angle() * aa.axis();
  if (aa.angle() > M_PI) phi = (aa.angle() - 2.0 * M_PI) * aa.axis();
  Eigen::Matrix<double, 6, 1> out;
  out.head<3>() = LeftJacobianInverse(phi) * translation_;
  out.tail<3>() = phi;
  return out;
}

Eigen::Matrix4d Pose3::Matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = RotationMatrix();
  m.topRightCorner<3, 1>() = translation_;
  return m;
}

Eigen::Matrix4d Sim3::Matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = scale_ * rigid_.RotationMatrix();
  m.topRightCorner<3, 1>() = translation();
  return m;
}

Pose3 Interpolate(const Pose3& a, const Pose3& b, double alpha) {
  return Pose3(a.rotation().slerp(alpha, b.rotation()),
               (1.0 - alpha) * a.translation() + alpha * b.translation());
}

}  // namespace m2s
