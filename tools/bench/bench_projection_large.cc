// bench_projection, large-scene part: a mesh file of ~10^7 vertices given by path, its load
// time (parsed, then through the scene cache) and the CPU projector on it, with the culling
// of vertex and triangle groups, with and without occlusion, and the client's frame (the
// balanced selection of 2000, ProjectBalanced, with occlusion), at 640x480 (the clients'
// default camera). Skipped when no file is given.
//
//   export M2S_BENCH_LARGE_SCENE=~/.cache/m2s-corpus/large/dragons.ply
//   export M2S_BENCH_LARGE_TRAJECTORY=~/.cache/m2s-corpus/large/walk.tum
//   build/bin/bench_projection --benchmark_filter=Large
//
// Frames are the trajectory's poses (every 10th of it, when given), else a camera turning at
// the scene's centre. Counters: median_ms (median frame), visible (features per frame),
// considered (vertices of the groups not culled, per frame; CpuProjector's measure of work).
// BM_LargeSceneLoad reports the parse (use_cache = false; the first load, which also writes
// the cache entry, costs about as much) and the cached load, one iteration each.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"

namespace m2s::bench {
namespace {

constexpr int kTrajectoryStride = 10;
constexpr int kTurningFrames = 36;

std::string EnvPath(const char* name) {
  const char* value = std::getenv(name);
  return value == nullptr ? std::string() : std::string(value);
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The scene of M2S_BENCH_LARGE_SCENE, loaded once (through the cache) for the projection runs.
const Scene* LargeScene(std::string* error) {
  static const Expected<Scene> scene = LoadScene(EnvPath("M2S_BENCH_LARGE_SCENE"));
  if (!scene) *error = scene.error();
  return scene ? &*scene : nullptr;
}

std::vector<Pose3> LargePoses(const Scene& scene) {
  std::vector<Pose3> poses;
  const std::string trajectory_path = EnvPath("M2S_BENCH_LARGE_TRAJECTORY");
  if (!trajectory_path.empty()) {
    if (Expected<Trajectory> trajectory = ReadTum(trajectory_path)) {
      for (size_t i = 0; i < trajectory->size(); i += kTrajectoryStride)
        poses.push_back((*trajectory)[i].world_from_camera);
      return poses;
    }
  }
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  for (const Eigen::Vector3f& p : scene.positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector3d centre = (0.5f * (lo + hi)).cast<double>();
  for (int k = 0; k < kTurningFrames; ++k) {
    const double yaw = 2.0 * M_PI * k / kTurningFrames;
    poses.emplace_back(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY())),
                       centre);
  }
  return poses;
}

void BM_LargeSceneLoad(benchmark::State& state) {
  const std::string path = EnvPath("M2S_BENCH_LARGE_SCENE");
  if (path.empty()) {
    state.SkipWithError("set M2S_BENCH_LARGE_SCENE to a large mesh file to run this benchmark");
    return;
  }
  const bool cached = state.range(0) != 0;
  SceneLoadOptions options;
  options.use_cache = cached;
  size_t vertices = 0;
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    const Expected<Scene> scene = LoadScene(path, options);
    seconds = SecondsSince(start);
    if (!scene) {
      state.SkipWithError(scene.error().c_str());
      return;
    }
    vertices = scene->num_vertices();
  }
  state.counters["load_s"] = seconds;
  state.counters["vertices"] = static_cast<double>(vertices);
}

constexpr int kSendBudget = 2000;  // m2s_client's default --budget

void BM_LargeProjectCpu(benchmark::State& state) {
  if (EnvPath("M2S_BENCH_LARGE_SCENE").empty()) {
    state.SkipWithError("set M2S_BENCH_LARGE_SCENE to a large mesh file to run this benchmark");
    return;
  }
  std::string error;
  const Scene* scene = LargeScene(&error);
  if (scene == nullptr) {
    state.SkipWithError(error.c_str());
    return;
  }
  // With occlusion, the clients' settings (a depth buffer of half the image's resolution).
  ProjectorOptions options =
      state.range(0) != 0 ? ProjectorOptions::Occluding() : ProjectorOptions{};
  auto projector = CpuProjector::Create(*scene, options);
  if (!projector) {
    state.SkipWithError(projector.error().c_str());
    return;
  }
  const Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  // balanced: the client's frame, the balanced selection of m2s_client's default budget.
  const bool balanced = state.range(1) != 0;
  const FeatureGrid grid = FeatureGrid::ForImage(camera.width, camera.height);
  const std::vector<Pose3> poses = LargePoses(*scene);
  std::vector<ProjectedVertex> features;
  std::vector<double> times;
  double visible = 0, considered = 0;
  size_t frame = 0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    const Pose3& pose = poses[frame++ % poses.size()];
    const Status status =
        balanced ? (*projector)->ProjectBalanced(pose, camera, grid, kSendBudget, &features)
                 : (*projector)->Project(pose, camera, &features);
    times.push_back(SecondsSince(start) * 1e3);
    if (!status) state.SkipWithError(status.message().c_str());
    visible += static_cast<double>(features.size());
    considered += static_cast<double>((*projector)->last_vertices_considered());
  }
  std::nth_element(times.begin(), times.begin() + times.size() / 2, times.end());
  state.counters["median_ms"] = times[times.size() / 2];
  state.counters["visible"] = visible / static_cast<double>(frame);
  state.counters["considered"] = considered / static_cast<double>(frame);
  state.counters["vertices"] = static_cast<double>(scene->num_vertices());
}

BENCHMARK(BM_LargeSceneLoad)->ArgName("cached")->Arg(0)->Arg(1)->Iterations(1)->UseRealTime();
BENCHMARK(BM_LargeProjectCpu)
    ->ArgNames({"occlusion", "balanced"})
    ->Args({0, 0})
    ->Args({1, 0})
    ->Args({1, 1})
    ->Iterations(61)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace m2s::bench
