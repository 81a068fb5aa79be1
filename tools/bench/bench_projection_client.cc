// bench_projection, the client's frame: what m2s_client's front end does per frame on the
// embedded default scene (MakeDefaultScene, DefaultTrajectory, 640 x 480 at 90 degrees): the
// CPU projector's balanced selection of at most 2000 features (ProjectBalanced), with
// occlusion (ProjectorOptions::Occluding, the clients' default) and without (the paper's
// setting). One iteration per pose of the trajectory, in order; `median_ms` and `p95_ms` are
// the frame times, `features` the mean number selected.
//
//   build/bin/bench_projection --benchmark_filter=ClientFrame
#include <algorithm>
#include <chrono>
#include <vector>

#include <benchmark/benchmark.h>

#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"

namespace m2s::bench {
namespace {

constexpr int kSendBudget = 2000;  // m2s_client's default --budget

void BM_ClientFrameDefaultScene(benchmark::State& state) {
  const bool occlusion = state.range(0) != 0;
  static const Scene scene = MakeDefaultScene();
  static const Trajectory trajectory = DefaultTrajectory();
  const ProjectorOptions options = occlusion ? ProjectorOptions::Occluding() : ProjectorOptions();
  auto projector = CpuProjector::Create(scene, options);
  if (!projector) {
    state.SkipWithError(projector.error().c_str());
    return;
  }
  const Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  const FeatureGrid grid = FeatureGrid::ForImage(camera.width, camera.height);
  std::vector<ProjectedVertex> features;
  std::vector<double> times;
  times.reserve(trajectory.size());
  size_t frame = 0, selected = 0;
  for (auto _ : state) {
    const Pose3& pose = trajectory[frame++ % trajectory.size()].world_from_camera;
    const auto start = std::chrono::steady_clock::now();
    const Status status = (*projector)->ProjectBalanced(pose, camera, grid, kSendBudget, &features);
    times.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
            .count());
    if (!status) state.SkipWithError(status.message().c_str());
    selected += features.size();
    benchmark::DoNotOptimize(features.data());
  }
  std::sort(times.begin(), times.end());
  state.counters["median_ms"] = times[times.size() / 2];
  state.counters["p95_ms"] = times[times.size() * 95 / 100];
  state.counters["features"] = static_cast<double>(selected) / static_cast<double>(frame);
}

const bool kRegistered = [] {
  const int64_t frames = static_cast<int64_t>(DefaultTrajectory().size());
  for (const int occlusion : {1, 0}) {
    benchmark::RegisterBenchmark("BM_ClientFrameDefaultScene", BM_ClientFrameDefaultScene)
        ->ArgName("occlusion")
        ->Arg(occlusion)
        ->Iterations(frames)
        ->UseRealTime()
        ->Unit(benchmark::kMillisecond);
  }
  return true;
}();

}  // namespace
}  // namespace m2s::bench
