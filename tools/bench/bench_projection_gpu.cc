// bench_projection, GPU part: GpuProjector on the paper's Table 1 sizes, on the same scene,
// camera and poses as the CPU rows (bench_projection_scene.h).
//
//  * BM_ProjectGpu/N, BM_ProjectGpuOcclusion/N: synchronous Project(), timed as the paper did,
//    from dispatch to the features being in host memory (uniform update, optional depth pass,
//    compute dispatch, fence wait, readback of the counter and the used prefix).
//  * BM_ProjectGpuPipelined/N: the render-loop pattern, Dispatch(frame k) then Collect(frame
//    k - 1); the time per iteration is the host cost per frame once the GPU overlaps with it.
//
// `process_cpu_ms` is the process CPU time per frame (see ProcessCpuMs()).
// One headless context for the whole process (GlContext::CreateHeadless: the first EGL display
// that offers GLES 3.1). `median_ms` is the median frame time, `visible` the mean feature count.
// The renderer string is printed once to stderr so a result can be traced to its device.
//
//   build/bin/bench_projection --benchmark_filter=Gpu
#include <algorithm>
#include <chrono>
#include <ctime>
#include <iostream>
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench_projection_scene.h"
#include "m2s/gpu/gpu_projector.h"

namespace m2s::bench {
namespace {

// At least 100 frames per size, more for the small sizes.
int64_t GpuFramesFor(int64_t num_vertices) {
  if (num_vertices <= 1000) return 2000;
  if (num_vertices <= 100000) return 500;
  return 100;
}

GlContext* BenchContext() {
  static Expected<std::unique_ptr<GlContext>> context = [] {
    auto c = GlContext::CreateHeadless();
    if (c)
      std::cerr << "GPU projector on: " << (*c)->renderer() << " (" << (*c)->version() << ")\n";
    return c;
  }();
  return context ? context->get() : nullptr;
}

// CPU time of the whole process (all threads). On llvmpipe the "GPU" work runs on the
// driver's threads inside this process, so this measures the work itself and is far less
// sensitive than wall time to other processes competing for the cores.
double ProcessCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return 1e3 * static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_nsec);
}

class FrameTimes {
 public:
  explicit FrameTimes(size_t frames) { times_.reserve(frames); }
  void Add(std::chrono::steady_clock::duration d) {
    times_.push_back(std::chrono::duration<double, std::milli>(d).count());
  }
  void Report(benchmark::State& state) {
    if (times_.empty()) return;
    std::nth_element(times_.begin(), times_.begin() + times_.size() / 2, times_.end());
    state.counters["median_ms"] = times_[times_.size() / 2];
  }

 private:
  std::vector<double> times_;
};

std::unique_ptr<GpuProjector> MakeBenchProjector(benchmark::State& state, bool occlusion) {
  GlContext* context = BenchContext();
  if (context == nullptr) {
    state.SkipWithError(GlContext::CreateHeadless().error().c_str());
    return nullptr;
  }
  ProjectorOptions options;
  options.occlusion = occlusion;
  auto projector = GpuProjector::Create(CachedBenchScene(state.range(0)), options, context);
  if (!projector) {
    state.SkipWithError(projector.error().c_str());
    return nullptr;
  }
  return std::move(*projector);
}

void ProjectGpu(benchmark::State& state, bool occlusion) {
  std::unique_ptr<GpuProjector> projector = MakeBenchProjector(state, occlusion);
  if (!projector) return;
  const Camera camera = BenchCamera();
  std::vector<ProjectedVertex> features;
  // Warm up: compiles lazily-built driver state and sizes `features`.
  for (int i = 0; i < 3; ++i) (void)projector->Project(BenchPose(i), camera, &features);
  FrameTimes times(static_cast<size_t>(state.max_iterations));
  int64_t frame = 0, visible = 0;
  const double cpu_start = ProcessCpuMs();
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    const Status status = projector->Project(BenchPose(frame++), camera, &features);
    times.Add(std::chrono::steady_clock::now() - start);
    if (!status) {
      state.SkipWithError(status.message().c_str());
      break;
    }
    visible += static_cast<int64_t>(features.size());
    benchmark::DoNotOptimize(features.data());
  }
  times.Report(state);
  state.counters["process_cpu_ms"] =
      (ProcessCpuMs() - cpu_start) / static_cast<double>(std::max<int64_t>(frame, 1));
  state.counters["visible"] =
      static_cast<double>(visible) / static_cast<double>(std::max<int64_t>(frame, 1));
  state.SetItemsProcessed(state.iterations() * state.range(0));
}

void BM_ProjectGpu(benchmark::State& state) { ProjectGpu(state, false); }
void BM_ProjectGpuOcclusion(benchmark::State& state) { ProjectGpu(state, true); }

void BM_ProjectGpuPipelined(benchmark::State& state) {
  std::unique_ptr<GpuProjector> projector = MakeBenchProjector(state, false);
  if (!projector) return;
  const Camera camera = BenchCamera();
  std::vector<ProjectedVertex> features;
  (void)projector->Project(BenchPose(0), camera, &features);
  FrameTimes times(static_cast<size_t>(state.max_iterations));
  int64_t frame = 0;
  if (!projector->Dispatch(BenchPose(frame), camera, frame)) {
    state.SkipWithError("Dispatch failed");
    return;
  }
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    ++frame;
    const Status dispatched = projector->Dispatch(BenchPose(frame), camera, frame);
    const Status collected = projector->Collect(&features);
    times.Add(std::chrono::steady_clock::now() - start);
    if (!dispatched || !collected) {
      state.SkipWithError((dispatched ? collected : dispatched).message().c_str());
      break;
    }
    benchmark::DoNotOptimize(features.data());
  }
  while (projector->frames_in_flight() > 0) (void)projector->Collect(&features);
  times.Report(state);
  state.SetItemsProcessed(state.iterations() * state.range(0));
}

void RegisterAll() {
  struct Entry {
    const char* name;
    void (*fn)(benchmark::State&);
  };
  const Entry entries[] = {{"BM_ProjectGpu", BM_ProjectGpu},
                           {"BM_ProjectGpuOcclusion", BM_ProjectGpuOcclusion},
                           {"BM_ProjectGpuPipelined", BM_ProjectGpuPipelined}};
  for (const Entry& e : entries) {
    for (int64_t n : TableSizes()) {
      benchmark::RegisterBenchmark(e.name, e.fn)
          ->Arg(n)
          ->Iterations(GpuFramesFor(n))
          ->UseRealTime()
          ->Unit(benchmark::kMillisecond);
    }
  }
}

const bool kRegistered = (RegisterAll(), true);

}  // namespace
}  // namespace m2s::bench
