// Speed of the SLAM back-end (Google Benchmark):
//   BM_OptimizePose/N       pose-only optimisation with N features (hand-written LM)
//   BM_OptimizePoseCeres/N  the same problem on Ceres (reference)
//   BM_LocalBA/K            local bundle adjustment over K keyframes (~1000 features each)
//   BM_TrackFrame           System::Track() per frame on the default scene and trajectory,
//                           mapping inline; counters give the per-frame median and 90th
//                           percentile (ms, wall and thread CPU) over non-keyframe frames.
#include <algorithm>
#include <chrono>
#include <ctime>
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>

#include "m2s/slam/system.h"
#include "sequence.h"
#include "synthetic_problems.h"

namespace m2s::bench {
namespace {

// CPU time of the calling thread (ms): robust to other processes sharing the machine.
double ThreadCpuMs() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

void BM_OptimizePose(benchmark::State& state, bool use_ceres) {
  const PoseOnlyProblem problem =
      MakePoseOnlyProblem(static_cast<int>(state.range(0)), 0.5, 0.01, 1);
  slam::PoseOnlyOptions options;
  options.use_ceres = use_ceres;
  int inliers = 0;
  for (auto _ : state) {
    Pose3 pose = problem.prediction;
    const slam::PoseOnlyResult result =
        slam::OptimizePose(problem.camera, options, problem.points, problem.uv, &pose);
    inliers = result.num_inliers;
    benchmark::DoNotOptimize(pose);
  }
  state.counters["inliers"] = inliers;
}
BENCHMARK_CAPTURE(BM_OptimizePose, lm, false)
    ->Arg(100)
    ->Arg(1000)
    ->Arg(5000)
    ->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_OptimizePose, ceres, true)->Arg(1000)->Unit(benchmark::kMicrosecond);

void BM_LocalBA(benchmark::State& state) {
  const LocalBaWindow window = MakeLocalBaWindow(static_cast<int>(state.range(0)), 1000, 0.5, 2);
  slam::BundleAdjustmentOptions options;
  options.max_iterations = 10;  // as ORB-SLAM2's local BA (5 + 10)
  int iterations = 0;
  for (auto _ : state) {
    state.PauseTiming();
    slam::BaProblem problem = window.problem;
    state.ResumeTiming();
    const slam::BundleAdjustmentResult result =
        slam::BundleAdjust(window.camera, options, &problem);
    iterations = result.iterations;
    benchmark::DoNotOptimize(problem);
  }
  state.counters["observations"] = static_cast<double>(window.problem.observations.size());
  state.counters["iterations"] = iterations;
}
BENCHMARK(BM_LocalBA)->Arg(5)->Arg(10)->Arg(20)->Unit(benchmark::kMillisecond);

// Tracking time per frame with about 1000 features: every 10th vertex of the default scene (a
// consistent subsample, ~1000 visible per frame), so frames share points as with a sparser mesh.
constexpr int kTrackVertexStride = 10;

void BM_TrackFrame(benchmark::State& state) {
  const Scene scene = MakeDefaultScene();
  const Camera camera = BenchCamera();
  Expected<Trajectory> gt = DefaultTrajectory().Resample(static_cast<double>(state.range(0)));
  if (!gt) {
    state.SkipWithError(gt.error().c_str());
    return;
  }
  FrameSourceOptions source_options;
  source_options.vertex_stride = kTrackVertexStride;
  Expected<std::unique_ptr<FrameSource>> source =
      FrameSource::Create(scene, camera, *gt, source_options);
  if (!source) {
    state.SkipWithError(source.error().c_str());
    return;
  }
  // Frames are made once, outside the timed region.
  std::vector<slam::Frame> frames((*source)->size());
  double features = 0.0;
  for (size_t i = 0; i < frames.size(); ++i) {
    if (const Status made = (*source)->MakeFrame(i, &frames[i]); !made.ok()) {
      state.SkipWithError(made.message().c_str());
      return;
    }
    features += frames[i].features.size();
  }

  slam::Options options;
  options.camera = camera;
  // Mapping inline: frames are fed far faster than real time here, and a threaded mapper would
  // fall behind and let the tracker run out of the map. Keyframe frames (which then include
  // the local mapping) are left out of the per-frame statistics.
  options.deterministic = true;
  std::unique_ptr<slam::System> system;
  size_t next = 0;
  std::vector<double> times_ms, cpu_ms;
  int lost = 0;
  int keyframes = 0;
  for (auto _ : state) {
    if (system == nullptr || next == frames.size()) {
      state.PauseTiming();
      system.reset();
      Expected<std::unique_ptr<slam::System>> created = slam::System::Create(options);
      if (!created) {
        state.SkipWithError(created.error().c_str());
        return;
      }
      system = std::move(*created);
      next = 0;
      state.ResumeTiming();
    }
    const auto start = std::chrono::steady_clock::now();
    const double cpu_start = ThreadCpuMs();
    const slam::TrackResult result = system->Track(frames[next++]);
    const double cpu = ThreadCpuMs() - cpu_start;
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const bool tracked = result.state == slam::TrackingState::kOk ||
                         result.state == slam::TrackingState::kRelocalized;
    if (tracked && result.keyframe_created) ++keyframes;
    if (tracked && !result.keyframe_created) {
      times_ms.push_back(ms);
      cpu_ms.push_back(cpu);
    } else if (!tracked && result.state == slam::TrackingState::kLost) {
      ++lost;
    }
  }
  if (!times_ms.empty()) {
    std::sort(times_ms.begin(), times_ms.end());
    state.counters["median_ms"] = times_ms[times_ms.size() / 2];
    state.counters["p90_ms"] = times_ms[times_ms.size() * 9 / 10];
    state.counters["max_ms"] = times_ms.back();
    std::sort(cpu_ms.begin(), cpu_ms.end());
    state.counters["cpu_median_ms"] = cpu_ms[cpu_ms.size() / 2];
    state.counters["cpu_p90_ms"] = cpu_ms[cpu_ms.size() * 9 / 10];
    state.counters["tracked"] = static_cast<double>(times_ms.size());
  }
  state.counters["lost"] = lost;
  state.counters["keyframes"] = keyframes;
  state.counters["features"] = features / std::max<size_t>(1, frames.size());
}
BENCHMARK(BM_TrackFrame)->Arg(30)->Iterations(1500)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace m2s::bench

BENCHMARK_MAIN();
