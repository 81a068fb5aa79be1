// Rigid (SE3) and similarity (Sim3) transforms on Eigen.
//
// Convention, stated once for the whole project: a transform is named by direction,
// `a_from_b`, and maps coordinates in frame b to frame a:
//   Pose3 world_from_camera;  x_world = world_from_camera * x_camera
//   Pose3 camera_from_world = world_from_camera.Inverse();
// Composition reads right to left: a_from_c = a_from_b * b_from_c.
// Camera axes are OpenCV / TUM: x right, y down, z forward.
//
// Both types are small immutable-by-convention values, safe to copy across threads.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace m2s {

// A rigid transform: rotation (unit quaternion) and translation.
class Pose3 {
 public:
  Pose3() : rotation_(Eigen::Quaterniond::Identity()), translation_(Eigen::Vector3d::Zero()) {}
  Pose3(const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation)
      : rotation_(rotation.normalized()), translation_(translation) {}
  Pose3(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation)
      : rotation_(Eigen::Quaterniond(rotation).normalized()), translation_(translation) {}

  static Pose3 Identity() { return Pose3(); }
  // From a 4x4 homogeneous matrix (the top-left block must be a rotation).
  static Pose3 FromMatrix(const Eigen::Matrix4d& m) {
    return Pose3(Eigen::Matrix3d(m.topLeftCorner<3, 3>()),
                 Eigen::Vector3d(m.topRightCorner<3, 1>()));
  }
  // Exponential map of a twist (rho: translation part, phi: rotation vector), SE3 proper.
  static Pose3 Exp(const Eigen::Matrix<double, 6, 1>& rho_phi);

  const Eigen::Quaterniond& rotation() const { return rotation_; }
  const Eigen::Vector3d& translation() const { return translation_; }
  Eigen::Matrix3d RotationMatrix() const { return rotation_.toRotationMatrix(); }
  Eigen::Matrix4d Matrix() const;

  Pose3 Inverse() const {
    const Eigen::Quaterniond inv = rotation_.conjugate();
    return Pose3(inv, -(inv * translation_));
  }
  Pose3 operator*(const Pose3& other) const {
    return Pose3(rotation_ * other.rotation_, rotation_ * other.translation_ + translation_);
  }
  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const { return rotation_ * p + translation_; }

  // Logarithm: (rho, phi) with Exp(Log()) == *this.
  Eigen::Matrix<double, 6, 1> Log() const;
  bool AllFinite() const { return rotation_.coeffs().allFinite() && translation_.allFinite(); }

 private:
  Eigen::Quaterniond rotation_;
  Eigen::Vector3d translation_;
};

// A similarity transform: x' = scale * R x + t.
class Sim3 {
 public:
  Sim3() : scale_(1.0) {}
  Sim3(double scale, const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation)
      : scale_(scale), rigid_(rotation, translation) {}
  explicit Sim3(const Pose3& rigid) : scale_(1.0), rigid_(rigid) {}

  static Sim3 Identity() { return Sim3(); }

  double scale() const { return scale_; }
  const Eigen::Quaterniond& rotation() const { return rigid_.rotation(); }
  const Eigen::Vector3d& translation() const { return rigid_.translation(); }
  Eigen::Matrix4d Matrix() const;

  Sim3 Inverse() const {
    const Eigen::Quaterniond inv = rotation().conjugate();
    return Sim3(1.0 / scale_, inv, -(inv * translation()) / scale_);
  }
  Sim3 operator*(const Sim3& o) const {
    return Sim3(scale_ * o.scale_, rotation() * o.rotation(),
                scale_ * (rotation() * o.translation()) + translation());
  }
  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const {
    return scale_ * (rotation() * p) + translation();
  }
  // Applies the similarity to a camera pose: the pose of the same camera in the target frame,
  // with the translation scaled and the rotation rotated (scale does not enter the rotation).
  Pose3 TransformPose(const Pose3& world_from_camera) const {
    return Pose3(rotation() * world_from_camera.rotation(),
                 (*this) * world_from_camera.translation());
  }

 private:
  double scale_;
  Pose3 rigid_;
};

// Interpolates between two poses: linear in translation, slerp in rotation, alpha in [0, 1].
Pose3 Interpolate(const Pose3& a, const Pose3& b, double alpha);

// Skew-symmetric matrix of v: Hat(v) * w == v.cross(w).
Eigen::Matrix3d Hat(const Eigen::Vector3d& v);

// Angle of a rotation in radians, in [0, pi].
double RotationAngle(const Eigen::Quaterniond& q);

}  // namespace m2s
