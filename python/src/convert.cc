#include "convert.h"

#include <cmath>
#include <vector>

#include <Eigen/Core>

namespace m2s::python {

void RaiseValueError(const Status& status) { throw py::value_error(status.message()); }
void RaiseRuntimeError(const Status& status) { throw std::runtime_error(status.message()); }

namespace {

constexpr double kRigidTolerance = 1e-6;

template <typename T>
T CameraField(const py::dict& dict, const char* key) {
  try {
    return dict[key].cast<T>();
  } catch (const py::cast_error&) {
    throw py::value_error(std::string("camera: '") + key + "' must be a number");
  }
}

}  // namespace

Camera CameraFromDict(const py::handle& camera_object) {
  if (!py::isinstance<py::dict>(camera_object)) {
    throw py::value_error(
        "camera must be a dict with CAMERA.json's keys "
        "(width, height, fx, fy, cx, cy, near, far)");
  }
  const py::dict dict = py::reinterpret_borrow<py::dict>(camera_object);
  static const char* const kRequired[] = {"width", "height", "fx", "fy", "cx", "cy"};
  static const char* const kOptional[] = {"near", "far"};
  for (const char* key : kRequired) {
    if (!dict.contains(key))
      throw py::value_error(std::string("camera: missing key '") + key + "'");
  }
  for (const auto& item : dict) {
    const std::string key = py::str(item.first);
    bool known = false;
    for (const char* k : kRequired) known = known || key == k;
    for (const char* k : kOptional) known = known || key == k;
    if (!known) throw py::value_error("camera: unknown key '" + key + "'");
  }
  Camera camera;
  camera.width = CameraField<int>(dict, "width");
  camera.height = CameraField<int>(dict, "height");
  camera.fx = CameraField<double>(dict, "fx");
  camera.fy = CameraField<double>(dict, "fy");
  camera.cx = CameraField<double>(dict, "cx");
  camera.cy = CameraField<double>(dict, "cy");
  if (dict.contains("near")) camera.near = CameraField<double>(dict, "near");
  if (dict.contains("far")) camera.far = CameraField<double>(dict, "far");
  if (Status s = camera.Check(); !s) RaiseValueError(s.Prefixed("camera: "));
  return camera;
}

py::dict CameraToDict(const Camera& camera) {
  py::dict dict;
  dict["width"] = camera.width;
  dict["height"] = camera.height;
  dict["fx"] = camera.fx;
  dict["fy"] = camera.fy;
  dict["cx"] = camera.cx;
  dict["cy"] = camera.cy;
  dict["near"] = camera.near;
  dict["far"] = camera.far;
  return dict;
}

Pose3 PoseFromArray(const py::handle& matrix, const std::string& what) {
  auto array = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(matrix);
  if (!array || array.ndim() != 2 || array.shape(0) != 4 || array.shape(1) != 4) {
    throw py::value_error(what + " must be a 4x4 array");
  }
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) m(r, c) = array.at(r, c);
  }
  if (!m.allFinite()) throw py::value_error(what + " has non-finite entries");
  if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > kRigidTolerance) {
    throw py::value_error(what + ": last row must be (0, 0, 0, 1)");
  }
  const Eigen::Matrix3d rotation = m.topLeftCorner<3, 3>();
  const double orthogonality =
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (orthogonality > kRigidTolerance || rotation.determinant() < 0) {
    throw py::value_error(what + ": the rotation block is not a rotation (R^T R = I, det R = +1 " +
                          "within 1e-6)");
  }
  return Pose3::FromMatrix(m);
}

py::array_t<double> PoseToArray(const Pose3& pose) { return MatrixToArray(pose.Matrix()); }

py::array_t<double> MatrixToArray(const Eigen::Matrix4d& m) {
  py::array_t<double> array({4, 4});
  auto out = array.mutable_unchecked<2>();
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) out(r, c) = m(r, c);
  }
  return array;
}

py::array_t<double> PosesToArray(const std::vector<Pose3>& poses) {
  py::array_t<double> array(
      {static_cast<py::ssize_t>(poses.size()), py::ssize_t{4}, py::ssize_t{4}});
  auto out = array.mutable_unchecked<3>();
  for (size_t i = 0; i < poses.size(); ++i) {
    const Eigen::Matrix4d m = poses[i].Matrix();
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) out(i, r, c) = m(r, c);
    }
  }
  return array;
}

Trajectory TrajectoryFromArrays(const py::handle& timestamps, const py::handle& poses,
                                const std::string& what) {
  const auto times = Vector<double>(timestamps, what + " timestamps");
  auto matrices = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(poses);
  if (!matrices || matrices.ndim() != 3 || matrices.shape(1) != 4 || matrices.shape(2) != 4 ||
      matrices.shape(0) != times.shape(0)) {
    throw py::value_error(what + " poses must be an (N,4,4) array with one pose per timestamp");
  }
  std::vector<TimedPose> timed(static_cast<size_t>(times.shape(0)));
  for (py::ssize_t i = 0; i < times.shape(0); ++i) {
    timed[i].timestamp = times.at(i);
    timed[i].world_from_camera =
        PoseFromArray(matrices[py::int_(i)], what + " pose " + std::to_string(i));
  }
  Expected<Trajectory> trajectory = Trajectory::FromPoses(std::move(timed));
  if (!trajectory) RaiseValueError(trajectory.status().Prefixed(what + ": "));
  return std::move(*trajectory);
}

py::tuple TrajectoryToArrays(const Trajectory& trajectory) {
  py::array_t<double> times(static_cast<py::ssize_t>(trajectory.size()));
  std::vector<Pose3> poses;
  auto t = times.mutable_unchecked<1>();
  for (size_t i = 0; i < trajectory.size(); ++i) {
    t(i) = trajectory[i].timestamp;
    poses.push_back(trajectory[i].world_from_camera);
  }
  return py::make_tuple(times, PosesToArray(poses));
}

}  // namespace m2s::python
