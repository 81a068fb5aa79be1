// The occlusion pass of GpuProjector: rasterises the scene's triangles with the frame's camera
// into a DEPTH_COMPONENT32F texture (row 0 = image top), which the compute shader samples.
// Triangles come in groups of kTriangleGroupSize with bounding boxes; a frame draws only the
// groups whose box may be in view (FrustumCuller, as the CPU projector), one draw call per run
// of consecutive groups. A culled group lies entirely outside one frustum plane (with margins),
// where it covers no pixel or only hides what lies beyond far: the depth texture's values at
// every pixel a visible vertex samples are those of drawing everything.
// Internal to m2s::gpu; same context and threading rules as GpuProjector.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/frustum_culling.h"
#include "m2s/common/status.h"
#include "m2s/gpu/camera_uniforms.h"
#include "m2s/gpu/gl_util.h"

namespace m2s {

class GpuDepthPass {
 public:
  static constexpr size_t kTriangleGroupSize = 4096;

  // `positions_buffer` is the projector's position buffer (3 floats per vertex, `positions`
  // on the host), used as the vertex buffer; `triangles` (3 indices each, already
  // range-checked) are uploaded once.
  static Expected<std::unique_ptr<GpuDepthPass>> Create(GLuint positions_buffer,
                                                        std::span<const Eigen::Vector3f> positions,
                                                        const std::vector<uint32_t>& triangles);

  // Renders the depth of the scene for one camera into a width x height texture (reallocated
  // only when the size changes), drawing the triangle groups `culler` may see. Saves and
  // restores the GL state it touches.
  Status Render(const CameraUniforms& camera, const FrustumCuller& culler, int width, int height);

  // Triangles the last Render() drew.
  size_t last_triangles_drawn() const { return last_triangles_drawn_; }

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
  std::vector<CullGroup> triangle_groups_;
  size_t last_triangles_drawn_ = 0;
  int width_ = 0;
  int height_ = 0;
  CameraUniformLocations camera_uniforms_;
};

// The depth buffer resolution for an image and a resolution scale: round(scale * size),
// at least 1 (shared with the CPU rule; see gpu_projector.h).
int OcclusionBufferSize(int image_size, double scale);

}  // namespace m2s
