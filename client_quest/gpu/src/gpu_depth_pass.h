// The occlusion pass of GpuProjector: rasterises the scene's triangles with the frame's camera
// into a DEPTH_COMPONENT32F texture (row 0 = image top), which the compute shader samples.
// Internal to m2s::gpu; same context and threading rules as GpuProjector.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "m2s/common/status.h"
#include "m2s/gpu/camera_uniforms.h"
#include "m2s/gpu/gl_util.h"

namespace m2s {

class GpuDepthPass {
 public:
  // `positions` is the projector's position buffer (3 floats per vertex), used as the vertex
  // buffer; `triangles` (3 indices each, already range-checked) are uploaded once.
  static Expected<std::unique_ptr<GpuDepthPass>> Create(GLuint positions,
                                                        const std::vector<uint32_t>& triangles);

  // Renders the depth of the scene for one camera into a width x height texture (reallocated
  // only when the size changes). Saves and restores the GL state it touches.
  Status Render(const CameraUniforms& camera, int width, int height);

  GLuint texture() const { return texture_.id(); }
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  GpuDepthPass() = default;
  Status Resize(int width, int height);

  GlProgram program_;
  GlVertexArray vertex_array_;
  GlBuffer indices_;
  GlTexture texture_;
  GlFramebuffer framebuffer_;
  GLsizei num_indices_ = 0;
  int width_ = 0;
  int height_ = 0;
  CameraUniformLocations camera_uniforms_;
};

// The depth buffer resolution for an image and a resolution scale: round(scale * size),
// at least 1 (shared with the CPU rule; see gpu_projector.h).
int OcclusionBufferSize(int image_size, double scale);

}  // namespace m2s
