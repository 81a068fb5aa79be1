// libm2s_plugin_python.so: the plug-in ABI (m2s/plugin/m2s_plugin.h) implemented by a tracker
// class written in Python, run in an embedded CPython interpreter.
//
// Configuration (the method's config JSON):
//   {"module": "path/to/tracker.py" or "package.module", "class": "Tracker", "options": {...}}
// A path (ending in .py or containing '/') has its directory put first on sys.path and is
// imported by its file name; a dotted name is imported from sys.path as it is. The class is
// called as cls(camera, options) with camera a dict of CAMERA.json's keys and options the
// "options" object (a dict). Its methods:
//   process_frame(seq, timestamp, ids, u, v) -> (state, pose) or (state, pose, num_inliers)
//       ids: (N,) uint32, u, v: (N,) float32 numpy arrays; state: "ok", "lost",
//       "not_initialized", "relocalized", "rejected" (or the m2s_track_state number); pose: a 4x4
//       world_from_camera array-like, or None (required for "ok" and "relocalized").
//   map_points() -> (ids (N,), positions (N,3))                    optional (none: no map)
//   trajectory() -> [(seq, timestamp, state, pose or None), ...]   optional (none: per-frame
//                                                                  results)
//   relocalise()                                                   optional
//   reset()                                                        optional (none: the class is
//                                                                  instantiated again)
//
// The interpreter starts once per process (or the host's running interpreter is used) and is
// never finalised; every call takes the GIL, so instances may be used from any host thread.
// A Python exception becomes the call's error string: "python: <Type>: <message>" (one line).
#include <dlfcn.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <pybind11/embed.h>
#include <pybind11/numpy.h>
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "m2s/plugin/m2s_plugin.h"

namespace {

namespace py = pybind11;

constexpr double kRigidTolerance = 1e-6;

void WriteError(std::string message, char* error, size_t error_size) {
  if (error == nullptr || error_size == 0) return;
  for (char& c : message) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  std::snprintf(error, error_size, "%s", message.c_str());
}

// "python: <Type>: <message>" for the exception being handled.
std::string PythonError(const py::error_already_set& e) {
  std::string type = "Exception";
  if (e.type()) type = py::str(e.type().attr("__name__"));
  return "python: " + type + ": " + std::string(py::str(e.value()));
}

// Starts the interpreter unless the process already runs one; then releases the GIL, which
// each call takes with gil_scoped_acquire. libpython is made global first: a host that loads
// plug-ins with RTLD_LOCAL would otherwise hide its symbols from extension modules (numpy).
void EnsureInterpreter() {
  static std::once_flag once;
  std::call_once(once, [] {
    Dl_info info;
    if (dladdr(reinterpret_cast<void*>(&Py_IsInitialized), &info) != 0 && info.dli_fname) {
      dlopen(info.dli_fname, RTLD_NOW | RTLD_GLOBAL | RTLD_NOLOAD);
    }
    if (Py_IsInitialized()) return;
    py::initialize_interpreter(/*init_signal_handlers=*/false);
    PyEval_SaveThread();
  });
}

struct Instance {
  py::object tracker_class;
  py::object tracker;
  py::dict camera;
  py::object options;
  bool has_pose = false;
  m2s_pose last_pose{};
  std::vector<m2s_trajectory_entry> results;  // one per processed frame
};

py::object ImportTrackerClass(const std::string& module, const std::string& class_name) {
  const bool is_path = module.ends_with(".py") || module.find('/') != std::string::npos;
  std::string module_name = module;
  if (is_path) {
    const std::filesystem::path path = std::filesystem::absolute(module);
    if (!std::filesystem::is_regular_file(path)) {
      throw std::runtime_error("python tracker file " + module + " not found");
    }
    py::list sys_path = py::module_::import("sys").attr("path");
    const py::str dir(path.parent_path().string());
    if (!sys_path.contains(dir)) sys_path.insert(0, dir);
    module_name = path.stem().string();
  }
  py::module_ imported = py::module_::import(module_name.c_str());
  if (!py::hasattr(imported, class_name.c_str())) {
    throw std::runtime_error("python module " + module + " has no class " + class_name);
  }
  return imported.attr(class_name.c_str());
}

int32_t StateFrom(const py::handle& state) {
  static const char* const kNames[] = {"not_initialized", "ok", "lost", "relocalized", "rejected"};
  if (py::isinstance<py::str>(state)) {
    const std::string name = py::str(state);
    for (int32_t i = 0; i < 5; ++i) {
      if (name == kNames[i]) return i;
    }
    throw std::runtime_error("tracker returned state '" + name +
                             "' (ok, lost, not_initialized, relocalized or rejected)");
  }
  const int value = state.cast<int>();
  if (value < 0 || value > 4) {
    throw std::runtime_error("tracker returned state " + std::to_string(value) + " (0 to 4)");
  }
  return value;
}

m2s_pose PoseFrom(const py::handle& matrix) {
  auto array = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(matrix);
  if (!array || array.ndim() != 2 || array.shape(0) != 4 || array.shape(1) != 4) {
    throw std::runtime_error("tracker pose must be a 4x4 array");
  }
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) m(r, c) = array.at(r, c);
  }
  const Eigen::Matrix3d rotation = m.topLeftCorner<3, 3>();
  if (!m.allFinite() ||
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() >
          kRigidTolerance ||
      rotation.determinant() < 0) {
    throw std::runtime_error("tracker pose is not a finite rigid transform");
  }
  const Eigen::Quaterniond q(rotation);
  m2s_pose pose{{q.w(), q.x(), q.y(), q.z()}, {m(0, 3), m(1, 3), m(2, 3)}};
  return pose;
}

bool HasPose(int32_t state) { return state == M2S_TRACK_OK || state == M2S_TRACK_RELOCALIZED; }

// Runs `body` with the GIL held; Python and C++ exceptions become the ABI's error string.
template <typename Body>
int Guarded(char* error, size_t error_size, Body body) {
  py::gil_scoped_acquire gil;
  try {
    body();
    return 0;
  } catch (py::error_already_set& e) {
    WriteError(PythonError(e), error, error_size);
  } catch (const std::exception& e) {
    WriteError(std::string("python: ") + e.what(), error, error_size);
  }
  return 1;
}

void* Create(const m2s_camera* camera, const char* config_json, char* error, size_t error_size) {
  std::string module, class_name = "Tracker", options_json = "{}";
  try {
    const nlohmann::json config = nlohmann::json::parse(config_json ? config_json : "{}");
    if (!config.is_object()) throw std::runtime_error("the config must be a JSON object");
    for (const auto& [key, value] : config.items()) {
      if (key != "module" && key != "class" && key != "options") {
        throw std::runtime_error("unknown config key '" + key + "' (module, class, options)");
      }
    }
    if (!config.contains("module")) {
      throw std::runtime_error("config needs \"module\": a .py file or a module name");
    }
    module = config.at("module").get<std::string>();
    class_name = config.value("class", class_name);
    if (config.contains("options")) {
      if (!config["options"].is_object()) throw std::runtime_error("\"options\" must be an object");
      options_json = config["options"].dump();
    }
  } catch (const std::exception& e) {
    WriteError(std::string("python plug-in config: ") + e.what(), error, error_size);
    return nullptr;
  }
  EnsureInterpreter();
  Instance* instance = nullptr;
  const int failed = Guarded(error, error_size, [&] {
    auto owned = std::make_unique<Instance>();
    owned->camera["width"] = camera->width;
    owned->camera["height"] = camera->height;
    owned->camera["fx"] = camera->fx;
    owned->camera["fy"] = camera->fy;
    owned->camera["cx"] = camera->cx;
    owned->camera["cy"] = camera->cy;
    owned->camera["near"] = camera->near_m;
    owned->camera["far"] = camera->far_m;
    owned->options = py::module_::import("json").attr("loads")(options_json);
    owned->tracker_class = ImportTrackerClass(module, class_name);
    owned->tracker = owned->tracker_class(owned->camera, owned->options);
    instance = owned.release();
  });
  return failed ? nullptr : instance;
}

int ProcessFrame(void* handle, const m2s_frame* frame, m2s_track_result* result, char* error,
                 size_t error_size) {
  auto* instance = static_cast<Instance*>(handle);
  return Guarded(error, error_size, [&] {
    const auto n = static_cast<py::ssize_t>(frame->num_features);
    py::array_t<uint32_t> ids(n);
    py::array_t<float> u(n), v(n);
    for (py::ssize_t i = 0; i < n; ++i) {
      ids.mutable_at(i) = frame->features[i].id;
      u.mutable_at(i) = frame->features[i].u;
      v.mutable_at(i) = frame->features[i].v;
    }
    const py::object out =
        instance->tracker.attr("process_frame")(frame->seq, frame->timestamp, ids, u, v);
    if (!py::isinstance<py::sequence>(out) || py::isinstance<py::str>(out) ||
        (py::len(out) != 2 && py::len(out) != 3)) {
      throw std::runtime_error("process_frame must return (state, pose[, num_inliers])");
    }
    const py::sequence values = py::reinterpret_borrow<py::sequence>(out);
    m2s_track_result r{};
    r.state = StateFrom(values[0]);
    if (HasPose(r.state)) {
      if (values[1].is_none()) throw std::runtime_error("tracker returned a pose of None");
      r.world_from_camera = PoseFrom(values[1]);
      instance->last_pose = r.world_from_camera;
      instance->has_pose = true;
    }
    if (py::len(values) == 3) r.num_inliers = values[2].cast<int32_t>();
    *result = r;
    instance->results.push_back({frame->seq, frame->timestamp, r.state, r.world_from_camera});
  });
}

int CurrentPose(void* handle, m2s_pose* pose) {
  auto* instance = static_cast<Instance*>(handle);
  if (!instance->has_pose) return 1;
  *pose = instance->last_pose;
  return 0;
}

size_t MapPoints(void* handle, m2s_map_point* points, size_t capacity) {
  auto* instance = static_cast<Instance*>(handle);
  size_t total = 0;
  char error[256];
  const int failed = Guarded(error, sizeof(error), [&] {
    if (!py::hasattr(instance->tracker, "map_points")) return;
    const py::tuple out = instance->tracker.attr("map_points")();
    auto ids = py::array_t<uint32_t, py::array::c_style | py::array::forcecast>::ensure(out[0]);
    auto xyz = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(out[1]);
    if (!ids || !xyz || ids.ndim() != 1 || xyz.ndim() != 2 || xyz.shape(1) != 3 ||
        xyz.shape(0) != ids.shape(0)) {
      throw std::runtime_error("map_points must return (ids (N,), positions (N,3))");
    }
    total = static_cast<size_t>(ids.shape(0));
    for (size_t i = 0; i < total && i < capacity; ++i) {
      points[i] = {ids.at(i), xyz.at(i, 0), xyz.at(i, 1), xyz.at(i, 2)};
    }
  });
  if (failed) std::fprintf(stderr, "m2s_plugin_python: map_points: %s\n", error);
  return failed ? 0 : total;
}

size_t TrajectoryEntries(void* handle, m2s_trajectory_entry* entries, size_t capacity) {
  auto* instance = static_cast<Instance*>(handle);
  std::vector<m2s_trajectory_entry> trajectory;
  char error[256];
  const int failed = Guarded(error, sizeof(error), [&] {
    if (!py::hasattr(instance->tracker, "trajectory")) {
      trajectory = instance->results;
      return;
    }
    for (const py::handle item : instance->tracker.attr("trajectory")()) {
      const py::tuple entry = py::reinterpret_borrow<py::tuple>(item);
      m2s_trajectory_entry e{entry[0].cast<int64_t>(), entry[1].cast<double>(), StateFrom(entry[2]),
                             m2s_pose{}};
      if (HasPose(e.state)) e.world_from_camera = PoseFrom(entry[3]);
      trajectory.push_back(e);
    }
  });
  if (failed) {
    std::fprintf(stderr, "m2s_plugin_python: trajectory: %s (per-frame results used)\n", error);
    trajectory = instance->results;
  }
  for (size_t i = 0; i < trajectory.size() && i < capacity; ++i) entries[i] = trajectory[i];
  return trajectory.size();
}

int Relocalise(void* handle, char* error, size_t error_size) {
  auto* instance = static_cast<Instance*>(handle);
  return Guarded(error, error_size, [&] {
    if (!py::hasattr(instance->tracker, "relocalise")) {
      throw std::runtime_error("the tracker has no relocalise() method");
    }
    instance->tracker.attr("relocalise")();
  });
}

int Reset(void* handle, char* error, size_t error_size) {
  auto* instance = static_cast<Instance*>(handle);
  return Guarded(error, error_size, [&] {
    if (py::hasattr(instance->tracker, "reset")) {
      instance->tracker.attr("reset")();
    } else {
      instance->tracker = instance->tracker_class(instance->camera, instance->options);
    }
    instance->has_pose = false;
    instance->results.clear();
  });
}

void Destroy(void* handle) {
  py::gil_scoped_acquire gil;
  delete static_cast<Instance*>(handle);
}

const m2s_plugin kPlugin = {
    M2S_PLUGIN_ABI_VERSION,
    "python",
    "a tracker written in Python (config: module, class, options)",
    Create,
    ProcessFrame,
    CurrentPose,
    MapPoints,
    TrajectoryEntries,
    Relocalise,
    Reset,
    Destroy,
};

}  // namespace

extern "C" M2S_PLUGIN_EXPORT const m2s_plugin* m2s_plugin_entry(void) { return &kPlugin; }
