#include "m2s/gpu/projector_factory.h"

#include <string>

#include "m2s/common/cpu_projector.h"
#include "m2s/gpu/gpu_projector.h"

namespace m2s {

Expected<ProjectorKind> ParseProjectorKind(std::string_view text) {
  if (text == "cpu") return ProjectorKind::kCpu;
  if (text == "gpu") return ProjectorKind::kGpu;
  return Expected<ProjectorKind>::Error("unknown projector \"" + std::string(text) +
                                        "\" (expected cpu or gpu)");
}

std::string_view ToString(ProjectorKind kind) {
  return kind == ProjectorKind::kGpu ? "gpu" : "cpu";
}

Expected<std::unique_ptr<Projector>> MakeProjector(ProjectorKind kind, const Scene& scene,
                                                   const ProjectorOptions& options,
                                                   GlContext* context) {
  if (kind == ProjectorKind::kGpu) {
    auto gpu = GpuProjector::Create(scene, options, context);
    if (!gpu) return gpu.status();
    return std::unique_ptr<Projector>(std::move(*gpu));
  }
  auto cpu = CpuProjector::Create(scene, options);
  if (!cpu) return cpu.status();
  return std::unique_ptr<Projector>(std::move(*cpu));
}

}  // namespace m2s
