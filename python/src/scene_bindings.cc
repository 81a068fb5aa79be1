// mesh2slam: scenes, cameras, trajectories and projection (the m2s_features code path).
#include <map>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include "bindings.h"
#include "convert.h"
#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_noise.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"

namespace m2s::python {
namespace {

// A loaded scene and the projectors made for it (one per projector setting, created on first
// use and reused). Projection releases the GIL; the mutex serialises it per scene, since a
// projector is not thread-safe.
class PyScene {
 public:
  explicit PyScene(Scene scene) : scene_(std::move(scene)) {}

  const Scene& scene() const { return scene_; }

  // The features m2s_features writes for this pose: project, then ApplyFeatureNoise (which
  // also sorts by id), then the balanced selection of `budget` features.
  std::vector<ProjectedVertex> Project(const Camera& camera, const Pose3& world_from_camera,
                                       const ProjectorOptions& projector_options,
                                       const FeatureNoiseOptions& noise, uint64_t frame_index,
                                       int budget) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto key =
        std::make_pair(projector_options.occlusion, projector_options.occlusion_resolution_scale);
    std::unique_ptr<CpuProjector>& projector = projectors_[key];
    if (!projector) {
      Expected<std::unique_ptr<CpuProjector>> created =
          CpuProjector::Create(scene_, projector_options);
      if (!created) RaiseRuntimeError(created.status());
      projector = std::move(*created);
    }
    std::vector<ProjectedVertex> features;
    if (Status s = projector->Project(world_from_camera, camera, &features); !s) {
      RaiseValueError(s);
    }
    ApplyFeatureNoise(noise, camera, static_cast<uint32_t>(scene_.num_vertices()), frame_index,
                      &features);
    if (budget <= 0 || features.size() <= static_cast<size_t>(budget)) return features;
    const FeatureGrid grid = FeatureGrid::ForImage(camera.width, camera.height);
    std::vector<VertexId> ids(features.size());
    std::vector<int> cells(features.size());
    for (size_t i = 0; i < features.size(); ++i) {
      ids[i] = features[i].id;
      cells[i] = grid.CellOf(features[i].u, features[i].v);
    }
    std::vector<ProjectedVertex> selected;
    for (const uint32_t index : SelectBalanced(ids, cells, budget)) {
      selected.push_back(features[index]);  // ascending indices: still sorted by id
    }
    return selected;
  }

 private:
  Scene scene_;
  std::mutex mutex_;
  std::map<std::pair<bool, double>, std::unique_ptr<CpuProjector>> projectors_;
};

FeatureNoiseOptions NoiseFromDict(const py::object& noise_object) {
  FeatureNoiseOptions noise;
  if (noise_object.is_none()) return noise;
  if (!py::isinstance<py::dict>(noise_object)) {
    throw py::value_error(
        "noise must be None or a dict (pixel_noise_sigma, quantization_px, "
        "dropout_probability, wrong_id_fraction, seed)");
  }
  for (const auto& item : py::reinterpret_borrow<py::dict>(noise_object)) {
    const std::string key = py::str(item.first);
    const py::handle value = item.second;
    try {
      if (key == "pixel_noise_sigma") {
        noise.pixel_noise_sigma = value.cast<double>();
      } else if (key == "quantization_px") {
        noise.quantization_px = value.cast<double>();
      } else if (key == "dropout_probability") {
        noise.dropout_probability = value.cast<double>();
      } else if (key == "wrong_id_fraction") {
        noise.wrong_id_fraction = value.cast<double>();
      } else if (key == "seed") {
        noise.seed = value.cast<uint64_t>();
      } else {
        throw py::value_error("noise: unknown key '" + key + "'");
      }
    } catch (const py::cast_error&) {
      throw py::value_error("noise: '" + key + "' must be a number (seed: an integer >= 0)");
    }
  }
  if (Status s = noise.Check(); !s) RaiseValueError(s.Prefixed("noise: "));
  return noise;
}

py::dict FeaturesToDict(const std::vector<ProjectedVertex>& features) {
  const auto n = static_cast<py::ssize_t>(features.size());
  py::array_t<uint32_t> id(n);
  py::array_t<float> u(n), v(n), depth(n);
  auto id_out = id.mutable_unchecked<1>();
  auto u_out = u.mutable_unchecked<1>();
  auto v_out = v.mutable_unchecked<1>();
  auto depth_out = depth.mutable_unchecked<1>();
  for (py::ssize_t i = 0; i < n; ++i) {
    id_out(i) = features[i].id;
    u_out(i) = features[i].u;
    v_out(i) = features[i].v;
    depth_out(i) = features[i].depth;
  }
  py::dict dict;
  dict["id"] = id;
  dict["u"] = u;
  dict["v"] = v;
  dict["depth"] = depth;
  return dict;
}

std::shared_ptr<PyScene> LoadScenePy(const py::object& path, double scale,
                                     const py::object& rotation_wxyz,
                                     const py::object& translation) {
  SceneLoadOptions options;
  options.scale = scale;
  if (!rotation_wxyz.is_none()) {
    const auto q = Vector<double>(rotation_wxyz, "rotation_wxyz", 4);
    options.rotation = Eigen::Quaterniond(q.at(0), q.at(1), q.at(2), q.at(3));
  }
  if (!translation.is_none()) {
    const auto t = Vector<double>(translation, "translation", 3);
    options.translation = Eigen::Vector3d(t.at(0), t.at(1), t.at(2));
  }
  const std::string file = path.is_none() ? std::string() : path.cast<std::string>();
  const bool transformed = scale != 1.0 || !rotation_wxyz.is_none() || !translation.is_none();
  if (file.empty() && transformed) {
    throw py::value_error("scale, rotation_wxyz and translation apply to a scene file only");
  }
  if (Status s = options.Check(); !s) RaiseValueError(s);
  Expected<Scene> scene = Expected<Scene>::Error("unreachable");
  {
    py::gil_scoped_release release;
    scene = file.empty() ? Expected<Scene>(MakeDefaultScene()) : LoadScene(file, options);
  }
  if (!scene) RaiseRuntimeError(scene.status());
  return std::make_shared<PyScene>(std::move(*scene));
}

// A read-only numpy view of `rows` x `cols` elements at `data`, kept alive by `owner`.
template <typename T>
py::array ReadOnlyView(const T* data, size_t rows, size_t cols, const py::object& owner) {
  py::array array(py::dtype::of<T>(),
                  {static_cast<py::ssize_t>(rows), static_cast<py::ssize_t>(cols)},
                  {static_cast<py::ssize_t>(cols * sizeof(T)), static_cast<py::ssize_t>(sizeof(T))},
                  data, owner);
  py::detail::array_proxy(array.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return array;
}

}  // namespace

void RegisterScene(py::module_& m) {
  py::class_<PyScene, std::shared_ptr<PyScene>>(
      m, "Scene", "A loaded scene: vertices with stable ids (index == id) and triangles.")
      .def_property_readonly("name", [](const PyScene& s) { return s.scene().name; })
      .def_property_readonly("num_vertices",
                             [](const PyScene& s) { return s.scene().num_vertices(); })
      .def_property_readonly("num_triangles",
                             [](const PyScene& s) { return s.scene().num_triangles(); })
      .def_property_readonly(
          "positions",
          [](py::object self) {
            const Scene& scene = self.cast<const PyScene&>().scene();
            static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
            return ReadOnlyView(scene.positions.empty() ? nullptr : scene.positions[0].data(),
                                scene.num_vertices(), 3, self);
          },
          "(N,3) float32 world positions (read-only view), row i is vertex id i")
      .def_property_readonly(
          "triangles",
          [](py::object self) {
            const Scene& scene = self.cast<const PyScene&>().scene();
            return ReadOnlyView(scene.triangles.data(), scene.num_triangles(), 3, self);
          },
          "(M,3) uint32 vertex ids of each triangle (read-only view)")
      .def("__repr__", [](const PyScene& s) {
        return "<mesh2slam.Scene '" + s.scene().name +
               "': " + std::to_string(s.scene().num_vertices()) + " vertices, " +
               std::to_string(s.scene().num_triangles()) + " triangles>";
      });

  m.def("load_scene", &LoadScenePy, py::arg("path") = py::none(), py::arg("scale") = 1.0,
        py::arg("rotation_wxyz") = py::none(), py::arg("translation") = py::none(),
        "Loads a scene file (any format assimp reads); None or '': the embedded default room. "
        "The transform x' = scale * R x + t applies to files. ValueError on bad options, "
        "RuntimeError when the file cannot be loaded.");

  m.def(
      "project",
      [](PyScene& scene, const py::object& camera_dict, const py::object& world_from_camera,
         bool occlusion, double occlusion_scale, int budget, const py::object& noise_dict,
         uint64_t frame_index) {
        const Camera camera = CameraFromDict(camera_dict);
        const Pose3 pose = PoseFromArray(world_from_camera, "world_from_camera");
        ProjectorOptions options;
        options.occlusion = occlusion;
        options.occlusion_resolution_scale = occlusion_scale;
        if (Status s = options.Check(); !s) RaiseValueError(s);
        if (budget < 0) throw py::value_error("budget must be >= 0 (0: every feature)");
        const FeatureNoiseOptions noise = NoiseFromDict(noise_dict);
        std::vector<ProjectedVertex> features;
        {
          py::gil_scoped_release release;
          features = scene.Project(camera, pose, options, noise, frame_index, budget);
        }
        return FeaturesToDict(features);
      },
      py::arg("scene"), py::arg("camera"), py::arg("world_from_camera"),
      py::arg("occlusion") = false, py::arg("occlusion_scale") = 1.0, py::arg("budget") = 0,
      py::arg("noise") = py::none(), py::arg("frame_index") = 0,
      "The visible vertex features for a pose, sorted by id: a dict of numpy arrays id "
      "(uint32), u, v, depth (float32), the numbers m2s_features writes for the same options.");

  m.def(
      "default_camera", [] { return CameraToDict(Camera::FromHorizontalFov(640, 480, 90.0)); },
      "The tools' default camera (640x480, 90 degrees horizontal field of view) as a dict.");
  m.def(
      "default_trajectory", [] { return TrajectoryToArrays(DefaultTrajectory()); },
      "The default scene's head motion (60 s at 30 Hz): (timestamps (N,), poses (N,4,4)).");
  m.def(
      "load_trajectory",
      [](const std::string& path) {
        Expected<Trajectory> trajectory = ReadTum(path);
        if (!trajectory) RaiseRuntimeError(trajectory.status());
        return TrajectoryToArrays(*trajectory);
      },
      py::arg("path"), "Reads a TUM file: (timestamps (N,), world_from_camera poses (N,4,4)).");
  m.def(
      "save_trajectory",
      [](const std::string& path, const py::object& timestamps, const py::object& poses) {
        const Trajectory trajectory = TrajectoryFromArrays(timestamps, poses, "trajectory");
        if (Status s = WriteTum(path, trajectory); !s) RaiseRuntimeError(s);
      },
      py::arg("path"), py::arg("timestamps"), py::arg("poses"),
      "Writes a TUM file (17 significant digits: load_trajectory reads it back exactly).");
}

}  // namespace m2s::python
