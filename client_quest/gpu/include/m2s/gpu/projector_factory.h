// Choosing a projector by option: apps and tools switch between the CPU and the GPU path with
// one flag (`--projector cpu|gpu`) and get the same Projector interface either way.
//
//   Expected<ProjectorKind> kind = ParseProjectorKind(flag);             // "cpu" or "gpu"
//   auto projector = MakeProjector(*kind, scene, options, /*context=*/nullptr);
//   if (!projector) { std::cerr << projector.error() << "\n"; return 1; }
//   (*projector)->Project(world_from_camera, camera, &features);
#pragma once

#include <memory>
#include <string_view>

#include "m2s/common/projector.h"
#include "m2s/common/scene.h"
#include "m2s/common/status.h"
#include "m2s/gpu/gl_context.h"

namespace m2s {

enum class ProjectorKind { kCpu, kGpu };

// "cpu" or "gpu" (case-sensitive); anything else is an error naming the accepted values.
Expected<ProjectorKind> ParseProjectorKind(std::string_view text);
std::string_view ToString(ProjectorKind kind);

// kCpu: CpuProjector (`context` is ignored). kGpu: GpuProjector on `context`, which must stay
// alive and be used from the calling thread; null makes the projector create and own a
// headless context. Errors are the projectors' (bad options, empty scene, no GLES 3.1...).
Expected<std::unique_ptr<Projector>> MakeProjector(ProjectorKind kind, const Scene& scene,
                                                   const ProjectorOptions& options,
                                                   GlContext* context);

}  // namespace m2s
