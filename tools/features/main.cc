// m2s_features: projects a scene into the camera at one trajectory pose and writes the
// visible vertex features as CSV (`id,u,v,depth,x,y,z`, sorted by id; x, y, z: the vertex's
// world position as loaded).
//
//   m2s_features --mesh room.obj --trajectory gt.tum --index 10 --out features.csv
//   m2s_features --default-scene --time 12.5 --occlusion --noise-sigma 0.5 --out f.csv
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "m2s/common/camera.h"
#include "m2s/common/camera_io.h"
#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_noise.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"
#include "m2s/gpu/projector_factory.h"

namespace m2s {
namespace {

struct Args {
  std::string mesh;
  bool default_scene = false;
  std::string trajectory;
  std::optional<int64_t> index;
  std::optional<double> time;
  std::string camera_json;
  int width = 640;
  int height = 480;
  double fov_deg = 90.0;
  double near = 0.05;
  double far = 50.0;
  ProjectorOptions projector;
  std::string projector_kind = "cpu";  // --projector cpu|gpu
  FeatureNoiseOptions noise;
  int budget = 0;  // the balanced selection of feature_rank.h; 0: every feature
  std::optional<uint64_t> frame_index;
  std::string out;
};

Expected<Camera> MakeCamera(const Args& args) {
  if (!args.camera_json.empty()) return ReadCameraJson(args.camera_json);
  if (!(args.fov_deg > 0 && args.fov_deg < 180)) {
    return Expected<Camera>::Error("--fov-deg must be in (0, 180)");
  }
  const Camera camera =
      Camera::FromHorizontalFov(args.width, args.height, args.fov_deg, args.near, args.far);
  if (Status s = camera.Check(); !s) return s;
  return camera;
}

// The projector this tool uses: CPU or GPU (a headless EGL context of its own), by --projector.
Expected<std::unique_ptr<Projector>> MakeFeatureProjector(const Scene& scene,
                                                          const std::string& kind_name,
                                                          const ProjectorOptions& options) {
  Expected<ProjectorKind> kind = ParseProjectorKind(kind_name);
  if (!kind) return kind.status();
  return MakeProjector(*kind, scene, options, /*context=*/nullptr);
}

struct Frame {
  Pose3 world_from_camera;
  uint64_t index = 0;  // the frame index given to the noise model
};

Expected<Frame> SelectFrame(const Trajectory& trajectory, const Args& args) {
  if (trajectory.empty()) return Expected<Frame>::Error("trajectory has no poses");
  Frame frame;
  if (args.index) {
    if (*args.index < 0 || static_cast<size_t>(*args.index) >= trajectory.size()) {
      return Expected<Frame>::Error("--index " + std::to_string(*args.index) +
                                    " out of range (trajectory has " +
                                    std::to_string(trajectory.size()) + " poses)");
    }
    frame.index = static_cast<uint64_t>(*args.index);
    frame.world_from_camera = trajectory[frame.index].world_from_camera;
  } else {
    Expected<Pose3> pose = trajectory.Interpolate(*args.time);
    if (!pose) return pose.status();
    frame.world_from_camera = *pose;
    // The nearest stored pose's index.
    size_t nearest = 0;
    for (size_t i = 1; i < trajectory.size(); ++i) {
      if (std::abs(trajectory[i].timestamp - *args.time) <
          std::abs(trajectory[nearest].timestamp - *args.time)) {
        nearest = i;
      }
    }
    frame.index = nearest;
  }
  if (args.frame_index) frame.index = *args.frame_index;
  return frame;
}

Status WriteCsv(const std::string& path, const Scene& scene,
                const std::vector<ProjectedVertex>& features) {
  std::FILE* file = path == "-" ? stdout : std::fopen(path.c_str(), "w");
  if (file == nullptr) return Status::Error("cannot write " + path);
  std::fputs("id,u,v,depth,x,y,z\n", file);
  // As printf's %.9g (every float with enough digits to be read back exactly), through
  // std::to_chars: several times faster, which matters for views of millions of vertices.
  std::vector<char> line(256);
  for (const ProjectedVertex& f : features) {
    const Eigen::Vector3f& p = scene.positions[f.id];
    char* out = std::to_chars(line.data(), line.data() + line.size(), f.id).ptr;
    for (float value : {f.u, f.v, f.depth, p.x(), p.y(), p.z()}) {
      *out++ = ',';
      out = std::to_chars(out, line.data() + line.size(), value, std::chars_format::general, 9).ptr;
    }
    *out++ = '\n';
    std::fwrite(line.data(), 1, static_cast<size_t>(out - line.data()), file);
  }
  const bool ok = std::ferror(file) == 0;
  if (file != stdout && std::fclose(file) != 0) return Status::Error("cannot write " + path);
  return ok ? Status::Ok() : Status::Error("cannot write " + path);
}

Status Run(const Args& args) {
  if (Status s = args.projector.Check(); !s) return s;
  if (Status s = args.noise.Check(); !s) return s;
  const bool use_default = args.default_scene || args.mesh.empty();
  if (args.default_scene && !args.mesh.empty()) {
    return Status::Error("--default-scene and --mesh are exclusive");
  }
  if (!use_default && args.trajectory.empty())
    return Status::Error("--trajectory is required with --mesh");

  Expected<Scene> loaded_scene = LoadSceneOrDefault(use_default ? std::string() : args.mesh);
  if (!loaded_scene) return loaded_scene.status();
  Scene scene = std::move(*loaded_scene);
  Expected<Trajectory> trajectory = LoadTrajectoryOrDefault(args.trajectory);
  if (!trajectory) return trajectory.status();
  Expected<Frame> frame = SelectFrame(*trajectory, args);
  if (!frame) return frame.status();
  Expected<Camera> camera = MakeCamera(args);
  if (!camera) return camera.status();

  Expected<std::unique_ptr<Projector>> projector =
      MakeFeatureProjector(scene, args.projector_kind, args.projector);
  if (!projector) return projector.status();
  std::vector<ProjectedVertex> features;
  Status projected = (*projector)->Project(frame->world_from_camera, *camera, &features);
  if (!projected) return projected;
  // Sorts by id too (with every option off it only sorts).
  ApplyFeatureNoise(args.noise, *camera, static_cast<uint32_t>(scene.num_vertices()), frame->index,
                    &features);
  if (args.budget > 0 && features.size() > static_cast<size_t>(args.budget)) {
    const FeatureGrid grid = FeatureGrid::ForImage(camera->width, camera->height);
    std::vector<VertexId> ids;
    std::vector<int> cells;
    for (const ProjectedVertex& f : features) {
      ids.push_back(f.id);
      cells.push_back(grid.CellOf(f.u, f.v));
    }
    std::vector<ProjectedVertex> kept;
    for (const uint32_t i : SelectBalanced(ids, cells, args.budget)) kept.push_back(features[i]);
    features.swap(kept);  // still sorted by id: SelectBalanced returns ascending indices
  }
  return WriteCsv(args.out, scene, features);
}

}  // namespace
}  // namespace m2s

int main(int argc, char** argv) {
  m2s::Args args;
  CLI::App app{
      "Projects a scene's vertices at one trajectory pose and writes id,u,v,depth,x,y,z as CSV."};
  app.add_option("--mesh", args.mesh,
                 "Scene file (any format assimp reads); default: the embedded default scene")
      ->check(CLI::ExistingFile);
  app.add_flag("--default-scene", args.default_scene,
               "Use the embedded default scene (and its trajectory)");
  app.add_option("--trajectory", args.trajectory,
                 "TUM trajectory (world_from_camera); default with the default "
                 "scene: its built-in trajectory")
      ->check(CLI::ExistingFile);
  auto* index = app.add_option("--index", args.index, "Pose index in the trajectory");
  auto* time = app.add_option("--time", args.time, "Time (s) in the trajectory, interpolated");
  index->excludes(time);
  auto* camera = app.add_option("--camera", args.camera_json,
                                "CAMERA.json: {width,height,fx,fy,cx,cy,near,far}")
                     ->check(CLI::ExistingFile);
  auto* width = app.add_option("--width", args.width, "Image width (px)")->capture_default_str();
  auto* height =
      app.add_option("--height", args.height, "Image height (px)")->capture_default_str();
  auto* fov = app.add_option("--fov-deg", args.fov_deg, "Horizontal field of view (degrees)")
                  ->capture_default_str();
  auto* near = app.add_option("--near", args.near, "Near depth (m)")->capture_default_str();
  auto* far = app.add_option("--far", args.far, "Far depth (m)")->capture_default_str();
  for (CLI::Option* o : {width, height, fov, near, far}) camera->excludes(o);
  app.add_option("--projector", args.projector_kind, "Projector: cpu or gpu (GLES 3.1 via EGL)")
      ->check(CLI::IsMember({"cpu", "gpu"}))
      ->capture_default_str();
  app.add_flag("--occlusion", args.projector.occlusion,
               "Drop vertices hidden behind nearer triangles");
  app.add_option("--occlusion-scale", args.projector.occlusion_resolution_scale,
                 "Depth buffer resolution as a fraction of the image, in (0, 1]")
      ->capture_default_str();
  app.add_option("--threads", args.projector.num_threads, "Projector threads (0: all cores)")
      ->capture_default_str();
  app.add_option("--noise-sigma", args.noise.pixel_noise_sigma, "Gaussian pixel noise sigma (px)");
  app.add_option("--quantize", args.noise.quantization_px,
                 "Quantise u, v to cell centres of this size (px; 1: pixel centres)");
  app.add_option("--dropout", args.noise.dropout_probability,
                 "Probability of dropping each feature");
  app.add_option("--wrong-ids", args.noise.wrong_id_fraction,
                 "Fraction of features given a wrong id");
  app.add_option("--budget", args.budget,
                 "Most features kept: the balanced, id-stable selection SLAM uses (0: all)");
  app.add_option("--seed", args.noise.seed, "Noise seed")->capture_default_str();
  app.add_option(
      "--frame-index", args.frame_index,
      "Frame index for the noise model (default: --index, or the nearest pose to --time)");
  app.add_option("--out", args.out, "Output CSV ('-': stdout)")->required();
  try {
    app.parse(argc, argv);
    if (!args.index && !args.time) throw CLI::RequiredError("--index or --time");
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  const m2s::Status status = m2s::Run(args);
  if (!status) {
    std::cerr << "m2s_features: " << status.message() << "\n";
    return 1;
  }
  return 0;
}
