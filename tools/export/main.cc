// m2s_export: renders a scene along a trajectory (colour and metric depth, one headless EGL
// context) and writes a TUM RGB-D or EuRoC dataset of it, with ORB-SLAM settings, so that
// image-based methods run on exactly the scene and poses the vertex-feature SLAM sees.
//
//   m2s_export --format tum-rgbd --out room_tum                 # default scene and trajectory
//   m2s_export --mesh office.glb --trajectory gt.tum --camera CAMERA.json --fps 20
//              --format euroc --out office_euroc
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "dataset_writer.h"
#include "m2s/common/camera.h"
#include "m2s/common/camera_io.h"
#include "m2s/common/render_mesh.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"
#include "m2s/gpu/gl_context.h"
#include "m2s/render/scene_renderer.h"

namespace m2s::export_tool {
namespace {

using Clock = std::chrono::steady_clock;

struct Args {
  std::string mesh;        // empty: the default scene
  std::string trajectory;  // empty: DefaultTrajectory()
  std::string camera_json;
  int width = 640, height = 480;  // without --camera: the client's default camera
  double fov_deg = 90.0;
  double fps = 0;  // 0: one image per trajectory pose
  std::string format;
  std::string out;
  int64_t max_frames = 0;  // 0: all
  double mesh_scale = 1.0;
  std::vector<double> mesh_offset = {0, 0, 0};
};

// The frames to render: the trajectory's poses, or its resampling at --fps, at most
// --max-frames of them.
Expected<Trajectory> FrameTimes(const Args& args) {
  Expected<Trajectory> loaded = LoadTrajectoryOrDefault(args.trajectory);
  if (!loaded) return loaded.status();
  Trajectory trajectory = std::move(*loaded);
  if (trajectory.empty()) {
    return Expected<Trajectory>::Error("trajectory '" + args.trajectory + "' has no poses");
  }
  if (args.fps > 0) {
    Expected<Trajectory> resampled = trajectory.Resample(args.fps);
    if (!resampled) return resampled.status();
    trajectory = std::move(*resampled);
  }
  if (args.max_frames > 0 && trajectory.size() > static_cast<size_t>(args.max_frames)) {
    std::vector<TimedPose> kept(trajectory.begin(), trajectory.begin() + args.max_frames);
    return Trajectory::FromPoses(std::move(kept));
  }
  return trajectory;
}

// --fps, or the trajectory's median frame rate (30 for a single frame).
double NominalRate(const Args& args, const Trajectory& frames) {
  if (args.fps > 0) return args.fps;
  std::vector<double> periods;
  for (size_t k = 1; k < frames.size(); ++k) {
    periods.push_back(frames[k].timestamp - frames[k - 1].timestamp);
  }
  if (periods.empty()) return 30.0;
  std::nth_element(periods.begin(), periods.begin() + periods.size() / 2, periods.end());
  return 1.0 / periods[periods.size() / 2];
}

Expected<RenderMesh> LoadMesh(const Args& args) {
  if (args.mesh.empty()) return MakeRenderMesh(MakeDefaultScene());
  SceneLoadOptions options;
  options.scale = args.mesh_scale;
  options.translation =
      Eigen::Vector3d(args.mesh_offset[0], args.mesh_offset[1], args.mesh_offset[2]);
  return LoadRenderMesh(args.mesh, options);
}

Status Run(const Args& args) {
  Expected<DatasetFormat> format = ParseDatasetFormat(args.format);
  if (!format) return format.status();
  if (args.fps < 0 || !std::isfinite(args.fps)) return Status::Error("--fps must be positive");
  if (args.max_frames < 0) return Status::Error("--max-frames must be >= 0 (0: all)");
  if (args.mesh.empty() &&
      (args.mesh_scale != 1.0 || args.mesh_offset != std::vector<double>{0, 0, 0})) {
    return Status::Error("--mesh-scale and --mesh-offset need --mesh");
  }
  Camera camera = Camera::FromHorizontalFov(args.width, args.height, args.fov_deg);
  if (!args.camera_json.empty()) {
    Expected<Camera> read = ReadCameraJson(args.camera_json);
    if (!read) return read.status();
    camera = *read;
  } else if (Status s = camera.Check(); !s) {
    return s;
  }
  Expected<Trajectory> frames = FrameTimes(args);
  if (!frames) return frames.status();
  Expected<RenderMesh> mesh = LoadMesh(args);
  if (!mesh) return mesh.status();

  if (!GlContext::AnyEglDisplayAvailable()) {
    return Status::Error(
        "no EGL display: rendering needs EGL with GLES 3.1 (Mesa's llvmpipe "
        "works headless: install libegl-mesa0)");
  }
  Expected<std::unique_ptr<GlContext>> context = GlContext::CreateHeadless();
  if (!context) return context.status().Prefixed("cannot create a GL context: ");
  Expected<std::unique_ptr<SceneRenderer>> renderer = SceneRenderer::Create(*mesh, camera);
  if (!renderer) return renderer.status();

  const double rate = NominalRate(args, *frames);
  if (Status s = WriteDatasetIndex(*format, args.out, *frames, camera, rate); !s) return s;
  const auto start = Clock::now();
  auto next_progress = start;
  RenderedFrame image;
  for (size_t k = 0; k < frames->size(); ++k) {
    const TimedPose& frame = (*frames)[k];
    if (Status s = (*renderer)->Render(frame.world_from_camera, &image); !s) return s;
    if (Status s = WriteDatasetFrame(*format, args.out, frame.timestamp, image); !s) return s;
    if (Clock::now() >= next_progress || k + 1 == frames->size()) {
      std::fprintf(stderr, "\rm2s_export: frame %zu/%zu", k + 1, frames->size());
      next_progress = Clock::now() + std::chrono::seconds(1);
    }
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  std::fprintf(stderr, "\n");
  std::printf("m2s_export: %zu frames (%dx%d, %s) in %.1f s to %s\n", frames->size(), camera.width,
              camera.height, args.format.c_str(), seconds, args.out.c_str());
  return Status::Ok();
}

}  // namespace
}  // namespace m2s::export_tool

int main(int argc, char** argv) {
  m2s::export_tool::Args args;
  CLI::App app{"Renders a scene along a trajectory and writes a TUM RGB-D or EuRoC dataset."};
  app.add_option("--mesh", args.mesh,
                 "Scene file (any format assimp reads); default: the embedded default scene");
  app.add_option("--mesh-scale", args.mesh_scale, "Scale applied to the mesh on load")
      ->capture_default_str();
  app.add_option("--mesh-offset", args.mesh_offset,
                 "Translation x y z (m) applied to the mesh on load, after the scale")
      ->expected(3);
  app.add_option("--trajectory", args.trajectory,
                 "TUM trajectory (world_from_camera); default: the client's default trajectory");
  auto* camera = app.add_option("--camera", args.camera_json,
                                "CAMERA.json: {width,height,fx,fy,cx,cy,near,far}");
  auto* width = app.add_option("--width", args.width, "Image width (px)")->capture_default_str();
  auto* height =
      app.add_option("--height", args.height, "Image height (px)")->capture_default_str();
  auto* fov = app.add_option("--fov-deg", args.fov_deg, "Horizontal field of view (degrees)")
                  ->capture_default_str();
  for (CLI::Option* o : {width, height, fov}) camera->excludes(o);
  app.add_option("--fps", args.fps, "Resample the trajectory at this rate (default: every pose)");
  app.add_option("--format", args.format, "tum-rgbd or euroc")->required();
  app.add_option("--out", args.out, "Output folder (created)")->required();
  app.add_option("--max-frames", args.max_frames, "At most this many frames (0: all)")
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::cerr << "m2s_export: " << e.what() << "\n";
    return 2;
  }
  const m2s::Status status = m2s::export_tool::Run(args);
  if (!status) {
    std::cerr << "m2s_export: " << status.message() << "\n";
    return 2;
  }
  return 0;
}
