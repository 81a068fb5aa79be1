// OpenXR poses and fields of view in this project's camera conventions. Pure functions on
// Eigen types (no OpenXR headers), unit-tested against hand-computed cases.
//
// Axes:
//   OpenXR view space (and OpenGL eye space): x right, y up, z backward (looks down -z).
//   Our camera (OpenCV / TUM, common/geometry.h): x right, y down, z forward.
// The two share the origin and the x axis; y and z flip:
//   camera_xr_from_camera_cv = diag(1, -1, -1), a rotation of 180 degrees about x.
// So a VIEW-space pose located in the world space (LOCAL or STAGE) becomes
//   world_from_camera = world_from_view_xr * camera_xr_from_camera_cv,
// and the OpenGL view matrix of an eye is simply inverse(world_from_eye_xr).
//
// Field of view: OpenXR gives four angles in radians, left and down negative for a view
// centred on the forward axis. The pinhole camera of that view with a W x H image is
//   fx = W / (tan(right) - tan(left)),  cx = -tan(left) * fx,
//   fy = H / (tan(up) - tan(down)),     cy =  tan(up) * fy      (v grows downwards).
//
//   Pose3 world_from_camera = WorldFromCameraFromXrView(world_from_view_xr);
//   Camera camera = CameraFromXrFov(fov, 640, 480, 0.05, 50.0);
#pragma once

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"

namespace m2s::xr {

// OpenXR's XrFovf, in radians.
struct FieldOfView {
  double angle_left = -0.785398;
  double angle_right = 0.785398;
  double angle_up = 0.785398;
  double angle_down = -0.785398;
};

// diag(1, -1, -1) as a rigid transform: the camera (OpenCV axes) in the OpenXR view's axes.
Pose3 CameraXrFromCameraCv();

// world_from_view_xr (a VIEW or eye pose from xrLocateSpace / xrLocateViews) -> our camera pose.
Pose3 WorldFromCameraFromXrView(const Pose3& world_from_view_xr);
// The inverse mapping: our camera pose -> the OpenXR view pose with the same optical centre.
Pose3 XrViewFromWorldFromCamera(const Pose3& world_from_camera);

// OpenXR pose fields (quaternion x, y, z, w and position) as a Pose3 (the quaternion is
// normalised).
Pose3 PoseFromXr(const Eigen::Vector4d& orientation_xyzw, const Eigen::Vector3d& position);

// The pinhole camera of a view with an image of width x height pixels (see the header).
Camera CameraFromXrFov(const FieldOfView& fov, int width, int height, double near, double far);

// OpenGL projection (eye -> clip) of an asymmetric OpenXR field of view, depth range
// [near, far] mapped to NDC z in [-1, 1].
Eigen::Matrix4d GlProjectionFromXrFov(const FieldOfView& fov, double near, double far);

// OpenGL view matrix (world -> eye) of an OpenXR eye pose: inverse(world_from_eye_xr).
Eigen::Matrix4d GlViewFromXrPose(const Pose3& world_from_eye_xr);

}  // namespace m2s::xr
