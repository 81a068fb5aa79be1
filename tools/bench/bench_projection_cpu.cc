// bench_projection, CPU part: the paper's Table 1 sizes for the CPU projector (with and
// without occlusion, all cores and one thread), a naive one-vertex-at-a-time Eigen loop in
// double, and a memcpy of the same vertex buffer (the memory-bandwidth floor).
//
// Each iteration is one frame (a new pose of the turning camera). Times are wall-clock
// (UseRealTime, the projector runs on several threads); the `median_ms` counter is the
// median frame time and `visible` the mean number of features per frame.
//
//   build/bin/bench_projection --benchmark_filter='Cpu|Naive|Memcpy'
//   build/bin/bench_projection --benchmark_format=json
#include <algorithm>
#include <chrono>
#include <cstring>
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench_projection_scene.h"
#include "m2s/common/cpu_projector.h"

namespace m2s::bench {
namespace {

// Fixed frame counts: at least 100 frames per size, more for the small sizes.
int64_t FramesFor(int64_t num_vertices) {
  if (num_vertices <= 1000) return 20000;
  if (num_vertices <= 100000) return 1000;
  return 100;
}

// Occlusion frames cost milliseconds even for small scenes (the depth buffer fill).
constexpr int64_t kOcclusionFrames = 100;

// Times each frame and reports the median as a counter.
class FrameTimer {
 public:
  explicit FrameTimer(size_t frames) { times_.reserve(frames); }
  void Start() { start_ = std::chrono::steady_clock::now(); }
  void Stop() {
    times_.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_)
            .count());
  }
  void Report(benchmark::State& state) {
    if (times_.empty()) return;
    std::nth_element(times_.begin(), times_.begin() + times_.size() / 2, times_.end());
    state.counters["median_ms"] = times_[times_.size() / 2];
  }

 private:
  std::vector<double> times_;
  std::chrono::steady_clock::time_point start_;
};

void ProjectCpu(benchmark::State& state, bool occlusion, int threads) {
  const int64_t n = state.range(0);
  const Scene& scene = CachedBenchScene(n);
  ProjectorOptions options;
  options.occlusion = occlusion;
  options.num_threads = threads;
  auto projector = CpuProjector::Create(scene, options);
  if (!projector) {
    state.SkipWithError(projector.error().c_str());
    return;
  }
  const Camera camera = BenchCamera();
  std::vector<ProjectedVertex> features;
  (void)(*projector)->Project(BenchPose(0), camera, &features);  // warm up: sizes the buffers
  FrameTimer timer(static_cast<size_t>(state.max_iterations));
  int64_t frame = 0, visible = 0;
  for (auto _ : state) {
    timer.Start();
    const Status status = (*projector)->Project(BenchPose(frame++), camera, &features);
    timer.Stop();
    if (!status) state.SkipWithError(status.message().c_str());
    visible += static_cast<int64_t>(features.size());
    benchmark::DoNotOptimize(features.data());
  }
  timer.Report(state);
  state.counters["visible"] =
      static_cast<double>(visible) / static_cast<double>(std::max<int64_t>(frame, 1));
  state.counters["threads"] = (*projector)->num_threads();
  state.SetItemsProcessed(state.iterations() * n);
}

void BM_ProjectCpu(benchmark::State& state) { ProjectCpu(state, false, 0); }
void BM_ProjectCpuSingleThread(benchmark::State& state) { ProjectCpu(state, false, 1); }
void BM_ProjectCpuOcclusion(benchmark::State& state) { ProjectCpu(state, true, 0); }

// One vertex at a time, Eigen in double, push_back into a reserved vector.
void BM_ProjectNaive(benchmark::State& state) {
  const int64_t n = state.range(0);
  const Scene& scene = CachedBenchScene(n);
  const Camera camera = BenchCamera();
  std::vector<ProjectedVertex> features;
  features.reserve(scene.num_vertices());
  FrameTimer timer(static_cast<size_t>(state.max_iterations));
  int64_t frame = 0;
  for (auto _ : state) {
    timer.Start();
    const Pose3 camera_from_world = BenchPose(frame++).Inverse();
    features.clear();
    for (size_t i = 0; i < scene.positions.size(); ++i) {
      const Eigen::Vector3d p = camera_from_world * scene.positions[i].cast<double>();
      if (p.z() < camera.near || p.z() > camera.far) continue;
      const Eigen::Vector2d uv = camera.Project(p);
      if (!camera.InImage(uv.x(), uv.y())) continue;
      features.push_back({static_cast<VertexId>(i), static_cast<float>(uv.x()),
                          static_cast<float>(uv.y()), static_cast<float>(p.z())});
    }
    timer.Stop();
    benchmark::DoNotOptimize(features.data());
  }
  timer.Report(state);
  state.SetItemsProcessed(state.iterations() * n);
}

// memcpy of the projector's vertex buffer (x, y, z floats: 12 bytes per vertex).
void BM_Memcpy(benchmark::State& state) {
  const int64_t n = state.range(0);
  const size_t bytes = static_cast<size_t>(n) * 3 * sizeof(float);
  std::vector<float> source(static_cast<size_t>(n) * 3, 1.f),
      destination(static_cast<size_t>(n) * 3, 0.f);
  FrameTimer timer(static_cast<size_t>(state.max_iterations));
  for (auto _ : state) {
    timer.Start();
    std::memcpy(destination.data(), source.data(), bytes);
    benchmark::ClobberMemory();
    timer.Stop();
  }
  timer.Report(state);
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(bytes));
}

// Registered per size so each size gets its own fixed frame count.
void RegisterAll() {
  struct Entry {
    const char* name;
    void (*fn)(benchmark::State&);
  };
  const Entry entries[] = {{"BM_ProjectCpu", BM_ProjectCpu},
                           {"BM_ProjectCpuSingleThread", BM_ProjectCpuSingleThread},
                           {"BM_ProjectNaive", BM_ProjectNaive},
                           {"BM_Memcpy", BM_Memcpy},
                           {"BM_ProjectCpuOcclusion", BM_ProjectCpuOcclusion}};
  for (const Entry& e : entries) {
    for (int64_t n : TableSizes()) {
      benchmark::RegisterBenchmark(e.name, e.fn)
          ->Arg(n)
          ->Iterations(e.fn == BM_ProjectCpuOcclusion ? kOcclusionFrames : FramesFor(n))
          ->UseRealTime()
          ->Unit(benchmark::kMillisecond);
    }
  }
}

const bool kRegistered = (RegisterAll(), true);

}  // namespace
}  // namespace m2s::bench
