// The feature budget's cost per frame: the balanced selection (KeepBalanced) against the plain
// rank selection (KeepLowestRanked) it replaces, on the densest 640x480 view of the default
// scene along its trajectory (sampled every 25 poses), keeping 2000.
//
//   build/bin/bench_feature_budget
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>

#include "m2s/common/camera.h"
#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"

namespace m2s {
namespace {

// The features of the default scene seen from the middle of its trajectory.
const std::vector<VertexFeature>& DefaultView() {
  static const std::vector<VertexFeature> view = [] {
    const Scene scene = MakeDefaultScene();
    const Trajectory trajectory = DefaultTrajectory();
    const Camera camera;
    auto projector = CpuProjector::Create(scene, ProjectorOptions{});
    std::vector<ProjectedVertex> projected;
    std::vector<VertexFeature> features;
    if (!projector) return features;
    for (size_t i = 0; i < trajectory.size(); i += 25) {  // the densest of these views
      if (!(*projector)->Project(trajectory[i].world_from_camera, camera, &projected)) continue;
      if (projected.size() <= features.size()) continue;
      features.clear();
      for (const ProjectedVertex& p : projected) features.push_back({p.id, {p.u, p.v}});
    }
    return features;
  }();
  return view;
}

void BM_KeepBalanced(benchmark::State& state) {
  const FeatureGrid grid = FeatureGrid::ForImage(Camera().width, Camera().height);
  std::vector<VertexFeature> features;
  for (auto _ : state) {
    features = DefaultView();
    KeepBalanced(static_cast<int>(state.range(0)), grid, &features);
    benchmark::DoNotOptimize(features.data());
  }
  state.counters["features"] = static_cast<double>(DefaultView().size());
}
BENCHMARK(BM_KeepBalanced)->Arg(2000)->Unit(benchmark::kMicrosecond);

void BM_KeepLowestRanked(benchmark::State& state) {
  std::vector<VertexFeature> features;
  for (auto _ : state) {
    features = DefaultView();
    KeepLowestRanked(static_cast<int>(state.range(0)), &features);
    benchmark::DoNotOptimize(features.data());
  }
  state.counters["features"] = static_cast<double>(DefaultView().size());
}
BENCHMARK(BM_KeepLowestRanked)->Arg(2000)->Unit(benchmark::kMicrosecond);

// The copy both loops pay, to subtract.
void BM_CopyView(benchmark::State& state) {
  std::vector<VertexFeature> features;
  for (auto _ : state) {
    features = DefaultView();
    benchmark::DoNotOptimize(features.data());
  }
}
BENCHMARK(BM_CopyView)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace m2s
