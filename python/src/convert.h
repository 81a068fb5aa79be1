// Conversions between Python values and the library's types, shared by the module's parts:
// camera dicts (CAMERA.json's keys), 4x4 numpy poses, (N,) timestamps with (N,4,4) poses, and
// Status errors raised as Python exceptions with the library's one-line message.
//
// Every function expects the GIL held.
//
//   const m2s::Camera camera = m2s::python::CameraFromDict(camera_dict);
//   const m2s::Pose3 pose = m2s::python::PoseFromArray(matrix, "world_from_camera");
#pragma once

#include <string>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/status.h"
#include "m2s/common/trajectory.h"

namespace m2s::python {

namespace py = pybind11;

// Raises ValueError (bad input) or RuntimeError (a failure of the operation) with the
// status's message. Precondition: !status.ok().
[[noreturn]] void RaiseValueError(const Status& status);
[[noreturn]] void RaiseRuntimeError(const Status& status);

// A camera from a dict with CAMERA.json's keys, as ReadCameraJson reads the file: width,
// height, fx, fy, cx, cy required, near and far optional (Camera's defaults); any other key
// and a camera that fails Camera::Check raise ValueError.
Camera CameraFromDict(const py::handle& camera);
py::dict CameraToDict(const Camera& camera);

// A rigid transform from a 4x4 array-like: finite, last row (0, 0, 0, 1), rotation block
// orthonormal with determinant +1 (within 1e-6). ValueError naming `what` otherwise.
Pose3 PoseFromArray(const py::handle& matrix, const std::string& what);
py::array_t<double> PoseToArray(const Pose3& pose);
py::array_t<double> MatrixToArray(const Eigen::Matrix4d& matrix);

// (N,) timestamps and (N,4,4) poses <-> a Trajectory (checked as Trajectory::FromPoses).
Trajectory TrajectoryFromArrays(const py::handle& timestamps, const py::handle& poses,
                                const std::string& what);
py::tuple TrajectoryToArrays(const Trajectory& trajectory);
// (N,4,4) array of the given poses.
py::array_t<double> PosesToArray(const std::vector<Pose3>& poses);

// A 1-D array of `n` elements of T converted from `value` (ValueError naming `what` on another
// shape); n < 0: any length.
template <typename T>
py::array_t<T, py::array::c_style | py::array::forcecast> Vector(const py::handle& value,
                                                                 const std::string& what,
                                                                 py::ssize_t n = -1) {
  auto array = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(value);
  if (!array || array.ndim() != 1 || (n >= 0 && array.shape(0) != n)) {
    const std::string shape = n >= 0 ? "(" + std::to_string(n) + ",)" : "(N,)";
    throw py::value_error(what + " must be a 1-D array of shape " + shape);
  }
  return array;
}

}  // namespace m2s::python
