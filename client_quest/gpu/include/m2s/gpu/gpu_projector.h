// GpuProjector: the Projector (m2s/common/projector.h) on a GLES 3.1 compute shader.
//
// Contract, identical in meaning to CpuProjector: every scene vertex with near <= Z <= far
// (Z = camera-frame depth) whose (u, v) lies in [0, width) x [0, height) is returned as
// (id, u, v, depth = Z); with ProjectorOptions::occlusion, vertices hidden behind nearer scene
// triangles are removed by the same rule as the CPU projector (see "Occlusion" below).
//
// How it runs
//  * Create() uploads the scene once: positions into a shader storage buffer (tightly packed
//    floats, 12 bytes per vertex, shared with the occlusion pass as its vertex buffer) and,
//    with occlusion, the triangle indices into an index buffer. Output buffers are sized for
//    every vertex (or, where GL_MAX_SHADER_STORAGE_BLOCK_SIZE is smaller, as many as one
//    block holds: llvmpipe's 128 MiB is 8.4M features; a frame that sees more fails with a
//    clear error), so nothing is allocated per frame (a GL fence object per frame is the only
//    driver object created).
//  * Culling: Create() groups the vertices in runs of 4096 consecutive ids, each with its
//    bounding box (m2s/common/frustum_culling.h, as the CPU projector). Per frame the groups
//    whose box may be in view (FrustumCuller, 2 px margin, in double) are listed in a small
//    storage buffer and only their vertices are dispatched; a culled group holds no vertex the
//    shader could find in view, so the output is the same as projecting every vertex.
//    With occlusion, each listed group's footprint in the depth buffer is tested first (by
//    its workgroups together, the rule below at every texel): a group whose every threshold
//    lies below its smallest depth cannot keep a vertex and ends there (last_groups_hidden()).
//  * Per frame only uniforms and that list change. The compute shader transforms each vertex into
//  camera
//    coordinates, applies the depth-range and image tests, and compacts the visible ones: each
//    visible vertex reserves its output slot with atomicAdd on one global counter and writes
//    (id, u, v, depth) there. Only the counter and the used prefix of the output are read back
//    (glMapBufferRange). An atomic on a uniform address is aggregated per subgroup by the
//    compilers (NVIDIA; Mesa's nir_opt_uniform_atomics), so explicit shared-memory compaction
//    (a workgroup count, one global atomic, two barriers) is left out: on llvmpipe it measured
//    1.8x slower (CPU time, 240k vertices); it is untested on a real GPU here.
//  * Numerics. The paper's chain is clip = P V M p, ndc = clip.xy / clip.w,
//    u = (x_ndc/2 + 1/2) w, v = (-y_ndc/2 + 1/2) h with V = GlFromCv() * camera_from_world and
//    P = Camera::GlProjection(); substituting P gives exactly u = fx X/Z + cx, v = fy Y/Z + cy
//    and clip.w = Z. The compute shader evaluates that closed form in camera coordinates, so the
//    near/far test is exact on Z (not on the non-linear NDC depth) and float32 rounding stays
//    below 1e-3 px of the CPU's result. Camera coordinates are formed as
//    R_cw ((p - c_hi) - c_lo), the camera centre c split into two floats, so the float error
//    scales with the vertex's distance to the camera, not with its distance to the world origin.
//    The occlusion pass does use the paper's matrices literally (gl_Position = P GlFromCv X_c).
//
// Occlusion: the scene's triangles are rasterised with the same camera (GL clips them at near
// and far; parts beyond far cannot hide a visible vertex, so this matches the CPU's near-only
// clipping) into a DEPTH_COMPONENT32F texture of bw x bh = max(1, lround(scale * width)) x
// max(1, lround(scale * height)) texels, row 0 = image top, scale = occlusion_resolution_scale.
// The rule is CpuProjector's (common/cpu_projector.h): the vertex's texel is
// (floor(u bw / width), floor(v bh / height)), M is the maximum depth over the 3x3 texels around
// it (clipped to the buffer), and the vertex is kept when
//   Z <= M (1 + occlusion_depth_bias_relative) + occlusion_depth_bias_m,
// or when one of those texels is uncovered (window depth 1, i.e. M = +inf). The window depth d
// is converted to camera depth in the shader, Z = near far / (far - d (far - near)), after
// taking the maximum (the map is monotonic); with d stored in float32 the relative error is
// about 6e-8 Z / near (6e-5 at Z = far for the default 0.05 m / 50 m range), far below the
// default 1% bias; keep far / near below ~1e5 for the bias to dominate. We chose the depth texture
// over an R32F colour attachment holding linear Z because depth textures are renderable on every
// GLES 3.0+ device, R32F only with EXT_color_buffer_float. Rasterisation tie-breaks on triangle
// edges differ from the CPU rasteriser's, so the id sets agree to > 99.5% (99.997% measured on the
// default scene) rather than exactly; on the test scene with a known hidden set both are exact.
//
// Synchronous and asynchronous use. Project() dispatches and waits for the result; it is what
// the paper measures ("dispatch to features in host memory") and what tools and tests use.
// Render loops use Dispatch() / Collect(): two output slots, each with a fence, so frame N is
// computed while frame N-1 is read back; Collect() waits (glClientWaitSync) only for the oldest
// frame, which has normally finished, so the loop never stalls on the frame it just issued.
// That is double buffering with fences: fences alone would still leave the CPU waiting on the
// one buffer, a second buffer alone could not tell when it is safe to read.
//
// GL state: the projector needs its GlContext current on the calling thread (it binds it when
// it is not). It restores the framebuffer, viewport, program, vertex array and depth/cull/
// blend/scissor state it changes; it leaves indexed SSBO bindings 0..2 and texture unit 0 as
// it used them. Not thread-safe: one thread at a time, the one owning the context.
//
//   auto projector = GpuProjector::Create(scene, options, /*context=*/nullptr);
//   std::vector<ProjectedVertex> features;
//   Status s = (*projector)->Project(world_from_camera, camera, &features);
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include "m2s/common/frustum_culling.h"
#include "m2s/common/projector.h"
#include "m2s/common/scene.h"
#include "m2s/gpu/camera_uniforms.h"
#include "m2s/gpu/gl_context.h"
#include "m2s/gpu/gl_util.h"

namespace m2s {

class GpuDepthPass;

class GpuProjector : public Projector {
 public:
  static constexpr int kMaxFramesInFlight = 2;

  // `context` may be null: the projector then creates and owns a headless context. Otherwise
  // the context must outlive the projector. Errors: invalid options, an empty scene (the CPU
  // projector accepts one; a GPU buffer cannot be empty), triangle indices out of range,
  // non-finite positions, a scene too large for the device, no GLES 3.1.
  static Expected<std::unique_ptr<GpuProjector>> Create(const Scene& scene,
                                                        const ProjectorOptions& options,
                                                        GlContext* context);
  ~GpuProjector() override;

  // Synchronous: Dispatch() + Collect() of this very frame. Fails when frames are in flight.
  Status Project(const Pose3& world_from_camera, const Camera& camera,
                 std::vector<ProjectedVertex>* out) override;
  std::string_view name() const override { return "gpu"; }

  // Asynchronous: issues the projection of one frame and returns without waiting. `tag` comes
  // back from Collect() (e.g. the frame number). Fails when kMaxFramesInFlight frames are
  // already in flight: collect first.
  Status Dispatch(const Pose3& world_from_camera, const Camera& camera, int64_t tag = 0);
  // Reads back the oldest frame in flight (waits for its fence). Fails when none is in flight.
  Status Collect(std::vector<ProjectedVertex>* out, int64_t* tag = nullptr);
  int frames_in_flight() const { return in_flight_; }

  GlContext& context() { return *context_; }
  size_t num_vertices() const { return num_vertices_; }
  // Vertices in the groups the last Dispatch() sent to the shader (the rest were culled).
  size_t last_vertices_considered() const { return last_vertices_considered_; }
  // With occlusion: triangles the last Dispatch() drew into the depth buffer (the rest were
  // culled); 0 without.
  size_t last_triangles_drawn() const;
  // With occlusion: groups of the last Collect()ed frame whose footprint lay wholly behind the
  // depth buffer (or outside it), so that none of their vertices was tested; 0 without.
  size_t last_groups_hidden() const { return last_groups_hidden_; }

 private:
  struct Slot {
    GlBuffer groups;        // the indices of the groups in view (a uint each)
    GlBuffer footprints;    // with occlusion: theirs (a GroupFootprint each)
    GlBuffer counter;       // two uints: features written, groups hidden
    GlBuffer features;      // num_vertices * 16 bytes
    void* fence = nullptr;  // GLsync
    int64_t tag = 0;
  };

  // The shader's Footprint (std430): a group's texels, its smallest depth, whether to test.
  struct GroupFootprint {
    std::array<int32_t, 4> box = {0, 0, -1, -1};  // x0, y0, x1, y1
    float min_depth = 0.f;
    int32_t mode = 0;  // 0: not tested, 1: tested, 2: outside the buffer
    int32_t pad[2] = {0, 0};
  };
  static_assert(sizeof(GroupFootprint) == 32, "GroupFootprint must match the shader's");

  GpuProjector() = default;
  Status Init(const Scene& scene, const ProjectorOptions& options);

  std::unique_ptr<GlContext> owned_context_;
  GlContext* context_ = nullptr;
  ProjectorOptions options_;
  size_t num_vertices_ = 0;
  size_t capacity_ = 0;  // features the output buffers hold
  GlBuffer positions_;
  std::vector<CullGroup> vertex_groups_;
  std::vector<uint32_t> visible_groups_;  // this frame's, uploaded to the slot's buffer
  size_t last_vertices_considered_ = 0;
  std::vector<GroupFootprint> footprints_;  // this frame's, as visible_groups_
  size_t last_groups_hidden_ = 0;
  GlProgram program_;
  std::unique_ptr<GpuDepthPass> depth_pass_;  // null without occlusion
  std::array<Slot, kMaxFramesInFlight> slots_;
  int next_slot_ = 0;  // slot the next Dispatch() writes
  int in_flight_ = 0;  // frames dispatched and not collected, oldest at next_slot_ - in_flight_
  // Uniform locations.
  CameraUniformLocations camera_uniforms_;
  GLint loc_intrinsics_ = -1, loc_range_ = -1, loc_num_vertices_ = -1, loc_num_groups_ = -1,
        loc_capacity_ = -1, loc_depth_size_ = -1, loc_bias_ = -1, loc_depth_ = -1;
};

}  // namespace m2s
