#include "m2s/gpu/gpu_projector.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "gpu_depth_pass.h"

namespace m2s {
namespace {

static_assert(sizeof(ProjectedVertex) == 16, "ProjectedVertex must match the shader's Feature");

constexpr GLuint kLocalSize = 256;
// Vertices are culled in groups of this many consecutive ids (16 workgroups each).
constexpr GLuint kCullGroupSize = 4096;
static_assert(kCullGroupSize % kLocalSize == 0, "a cull group is whole workgroups");
// FrustumCuller margin: the CPU projector's (its kernel and the shader round alike).
constexpr double kCullMarginPx = 2.0;
constexpr GLuint kMaxGroupsX = 65535;  // GLES 3.1 guaranteed minimum
// Collect() gives up when the GPU has not finished a frame after this long.
constexpr GLuint64 kFenceTimeoutNs = 60ull * 1000 * 1000 * 1000;

// With occlusion, a listed group's footprint in the depth buffer is tested against it before
// its vertices (up to this many texels; a larger footprint is not tested).
constexpr int kMaxTestedFootprint = 16384;

// Binding points: 0 positions, 1 counters, 2 features, 3 the cull groups in view, 4 (with
// occlusion) their footprints; texture unit 0 = occlusion depth. Workgroup w projects ids
// groups[w / 16] * 4096 + (w % 16) * 256 + i.
constexpr const char* kComputeShader = R"(
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Positions { float positions[]; };
layout(std430, binding = 1) buffer Counter { uint count; uint hidden_groups; };
struct Feature { uint id; float u; float v; float depth; };
layout(std430, binding = 2) writeonly buffer Features { Feature features[]; };
layout(std430, binding = 3) readonly buffer Groups { uint groups[]; };

uniform vec4 u_intrinsics;  // fx fy cx cy
uniform vec4 u_range;       // width height near far
uniform uint u_num_vertices;
uniform uint u_num_groups;  // entries of groups[]
uniform uint u_capacity;    // entries of features[]
#ifdef M2S_OCCLUSION
uniform highp sampler2D u_depth;  // window depth, row 0 = image top
uniform vec2 u_depth_size;        // depth buffer width, height in texels
uniform vec2 u_bias;              // relative, absolute (metres)
// A group's footprint (texels x0, y0, x1, y1, inclusive) and a lower bound of its vertices'
// camera depth; mode 0: not tested, 1: tested, 2: nothing of it can be in the image.
struct Footprint { ivec4 box; float min_depth; int mode; int pad0; int pad1; };
layout(std430, binding = 4) readonly buffer Footprints { Footprint footprints[]; };
shared bool s_hidden;

// The threshold of the vertex test at a texel: the 3x3 maximum of the buffer around it
// (clipped to the buffer) as camera depth, with the bias; +inf where a texel is uncovered.
float Threshold(ivec2 texel) {
  ivec2 size = ivec2(u_depth_size);
  ivec2 lo = max(texel - 1, ivec2(0));
  ivec2 hi = min(texel + 1, size - 1);
  float d_max = 0.0;
  for (int y = lo.y; y <= hi.y; ++y) {
    for (int x = lo.x; x <= hi.x; ++x) d_max = max(d_max, texelFetch(u_depth, ivec2(x, y), 0).r);
  }
  if (d_max >= 1.0) return uintBitsToFloat(0x7f800000u);
  // Window depth -> camera Z (monotonic, so the max commutes with it).
  float near = u_range.z, far = u_range.w;
  float z_buffer = near * far / (far - d_max * (far - near));
  return z_buffer * (1.0 + u_bias.x) + u_bias.y;
}
#endif

void main() {
  uint workgroup = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
  uint slot = workgroup / 16u;
  uint id = slot < u_num_groups
                ? groups[slot] * 4096u + (workgroup % 16u) * 256u + gl_LocalInvocationIndex
                : u_num_vertices;
#ifdef M2S_OCCLUSION
  // Occlusion culling of the group (the CPU projector's rule): when every texel of its
  // footprint holds a threshold below the group's smallest depth, no vertex of it passes the
  // test below. The workgroup's invocations share the texels.
  int mode = slot < u_num_groups ? footprints[slot].mode : 0;
  if (gl_LocalInvocationIndex == 0u) s_hidden = mode != 0;
  memoryBarrierShared();
  barrier();
  if (mode == 1) {
    ivec4 box = footprints[slot].box;
    float min_depth = footprints[slot].min_depth;
    int width = box.z - box.x + 1;
    int area = width * (box.w - box.y + 1);
    for (int t = int(gl_LocalInvocationIndex); t < area; t += 256) {
      if (!(Threshold(ivec2(box.x + t % width, box.y + t / width)) < min_depth)) {
        s_hidden = false;
        break;
      }
    }
  }
  memoryBarrierShared();
  barrier();
  if (s_hidden) {
    if (gl_LocalInvocationIndex == 0u && workgroup % 16u == 0u) atomicAdd(hidden_groups, 1u);
    return;
  }
#endif
  bool visible = false;
  float u = 0.0, v = 0.0, z = 0.0;
  if (id < u_num_vertices) {
    vec3 p = vec3(positions[3u * id], positions[3u * id + 1u], positions[3u * id + 2u]);
    vec3 c = CameraFromWorld(p);
    z = c.z;
    if (z >= u_range.z && z <= u_range.w) {
      u = u_intrinsics.x * c.x / z + u_intrinsics.z;
      v = u_intrinsics.y * c.y / z + u_intrinsics.w;
      visible = u >= 0.0 && v >= 0.0 && u < u_range.x && v < u_range.y;
    }
#ifdef M2S_OCCLUSION
    if (visible) {
      // The CPU projector's rule: M = max of the linear depth over the 3x3 texels around the
      // vertex's texel (clipped to the buffer; uncovered texels are +inf, i.e. d == 1).
      ivec2 size = ivec2(u_depth_size);
      ivec2 texel = min(ivec2(floor(vec2(u, v) * u_depth_size / u_range.xy)), size - 1);
      visible = z <= Threshold(texel);
    }
#endif
  }
  // One atomic per visible vertex on a uniform address: GPU compilers aggregate these per
  // subgroup themselves (see gpu_projector.h, "How it runs").
  if (visible) {
    uint slot = atomicAdd(count, 1u);
    if (slot < u_capacity) features[slot] = Feature(id, u, v, z);
  }
}
)";

}  // namespace

Expected<std::unique_ptr<GpuProjector>> GpuProjector::Create(const Scene& scene,
                                                             const ProjectorOptions& options,
                                                             GlContext* context) {
  if (Status s = options.Check(); !s) return s.Prefixed("GpuProjector: ");
  if (scene.positions.empty()) return Status::Error("GpuProjector: the scene has no vertices");
  if (scene.triangles.size() % 3 != 0) {
    return Status::Error("GpuProjector: the triangle index count is not a multiple of 3");
  }
  const size_t n = scene.positions.size();
  for (uint32_t index : scene.triangles) {
    if (index >= n) {
      return Status::Error("GpuProjector: triangle index " + std::to_string(index) +
                           " out of range (" + std::to_string(n) + " vertices)");
    }
  }
  for (size_t i = 0; i < n; ++i) {
    if (!scene.positions[i].allFinite()) {
      return Status::Error("GpuProjector: scene vertex " + std::to_string(i) +
                           " has a non-finite position");
    }
  }
  std::unique_ptr<GpuProjector> projector(new GpuProjector());
  if (context == nullptr) {
    Expected<std::unique_ptr<GlContext>> own = GlContext::CreateHeadless();
    if (!own) return Status::Error("GpuProjector: " + own.error());
    projector->owned_context_ = std::move(*own);
    context = projector->owned_context_.get();
  }
  projector->context_ = context;
  if (Status s = context->MakeCurrent(); !s) return Status::Error("GpuProjector: " + s.message());
  if (Status s = projector->Init(scene, options); !s) {
    return Status::Error("GpuProjector: " + s.message());
  }
  return projector;
}

Status GpuProjector::Init(const Scene& scene, const ProjectorOptions& options) {
  options_ = options;
  num_vertices_ = scene.positions.size();
  // Positions must fit one storage block; the output holds every vertex where the device
  // allows, else as many as one block holds (a frame that sees more fails in Collect()).
  GLint64 max_block = 0;
  glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &max_block);
  const GLint64 positions_bytes = static_cast<GLint64>(num_vertices_) * 12;
  if (positions_bytes > max_block || num_vertices_ > std::numeric_limits<uint32_t>::max() / 3) {
    return Status::Error("scene of " + std::to_string(num_vertices_) +
                         " vertices exceeds GL_MAX_SHADER_STORAGE_BLOCK_SIZE (" +
                         std::to_string(max_block) + " bytes)");
  }
  capacity_ = std::min<size_t>(num_vertices_, static_cast<size_t>(max_block / 16));
  const GLint64 features_bytes = static_cast<GLint64>(capacity_) * 16;
  const std::string header = std::string("#version 310 es\nprecision highp float;\n") +
                             (options.occlusion ? "#define M2S_OCCLUSION 1\n" : "") + kCameraGlsl;
  Expected<GlProgram> program = CompileProgram({{GL_COMPUTE_SHADER, header + kComputeShader}});
  if (!program) return program.status();
  program_ = std::move(*program);
  const GLuint id = program_.id();
  camera_uniforms_ = CameraUniformLocations::Find(id);
  loc_intrinsics_ = glGetUniformLocation(id, "u_intrinsics");
  loc_range_ = glGetUniformLocation(id, "u_range");
  loc_num_vertices_ = glGetUniformLocation(id, "u_num_vertices");
  loc_num_groups_ = glGetUniformLocation(id, "u_num_groups");
  loc_capacity_ = glGetUniformLocation(id, "u_capacity");
  loc_depth_ = glGetUniformLocation(id, "u_depth");
  loc_depth_size_ = glGetUniformLocation(id, "u_depth_size");
  loc_bias_ = glGetUniformLocation(id, "u_bias");

  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "positions must be packed");
  positions_ = MakeGlBuffer();
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, positions_.id());
  glBufferData(GL_SHADER_STORAGE_BUFFER, static_cast<GLsizeiptr>(num_vertices_ * 3 * sizeof(float)),
               scene.positions.data(), GL_STATIC_DRAW);
  vertex_groups_ = MakeVertexGroups(scene.positions, kCullGroupSize);
  visible_groups_.reserve(vertex_groups_.size());
  for (Slot& slot : slots_) {
    slot.groups = MakeGlBuffer();
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.groups.id());
    glBufferData(GL_SHADER_STORAGE_BUFFER,
                 static_cast<GLsizeiptr>(vertex_groups_.size() * sizeof(GLuint)), nullptr,
                 GL_DYNAMIC_DRAW);
    slot.footprints = MakeGlBuffer();
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.footprints.id());
    glBufferData(GL_SHADER_STORAGE_BUFFER,
                 static_cast<GLsizeiptr>(vertex_groups_.size() * sizeof(GroupFootprint)), nullptr,
                 GL_DYNAMIC_DRAW);
    slot.counter = MakeGlBuffer();
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.counter.id());
    glBufferData(GL_SHADER_STORAGE_BUFFER, 2 * sizeof(GLuint), nullptr, GL_DYNAMIC_READ);
    slot.features = MakeGlBuffer();
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.features.id());
    glBufferData(GL_SHADER_STORAGE_BUFFER, static_cast<GLsizeiptr>(features_bytes), nullptr,
                 GL_DYNAMIC_READ);
  }
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
  if (Status s = CheckGlError("uploading the scene"); !s) return s;
  if (options.occlusion) {
    Expected<std::unique_ptr<GpuDepthPass>> pass =
        GpuDepthPass::Create(positions_.id(), scene.positions, scene.triangles);
    if (!pass) return pass.status();
    depth_pass_ = std::move(*pass);
  }
  return Status::Ok();
}

size_t GpuProjector::last_triangles_drawn() const {
  return depth_pass_ ? depth_pass_->last_triangles_drawn() : 0;
}

GpuProjector::~GpuProjector() {
  if (context_ == nullptr || !context_->MakeCurrent()) return;
  for (Slot& slot : slots_) {
    if (slot.fence != nullptr) glDeleteSync(static_cast<GLsync>(slot.fence));
  }
  // GL objects are released by their handles while the context is still current.
}

Status GpuProjector::Project(const Pose3& world_from_camera, const Camera& camera,
                             std::vector<ProjectedVertex>* out) {
  if (out == nullptr) return Status::Error("GpuProjector::Project: null output");
  if (in_flight_ != 0) {
    return Status::Error("GpuProjector::Project: asynchronous frames in flight; Collect() them");
  }
  if (Status s = Dispatch(world_from_camera, camera, 0); !s) return s;
  return Collect(out, nullptr);
}

Status GpuProjector::Dispatch(const Pose3& world_from_camera, const Camera& camera, int64_t tag) {
  if (Status s = camera.Check(); !s) return s.Prefixed("GpuProjector: ");
  if (!world_from_camera.AllFinite()) return Status::Error("GpuProjector: pose is not finite");
  if (in_flight_ >= kMaxFramesInFlight) {
    return Status::Error("GpuProjector::Dispatch: " + std::to_string(kMaxFramesInFlight) +
                         " frames already in flight; Collect() first");
  }
  if (Status s = context_->MakeCurrent(); !s) return s;
  const CameraUniforms uniforms = MakeCameraUniforms(world_from_camera, camera);
  const FrustumCuller culler(world_from_camera, camera, kCullMarginPx);
  if (depth_pass_) {
    const int width = OcclusionBufferSize(camera.width, options_.occlusion_resolution_scale);
    const int height = OcclusionBufferSize(camera.height, options_.occlusion_resolution_scale);
    if (Status s = depth_pass_->Render(uniforms, culler, width, height); !s) return s;
  }
  Slot& slot = slots_[next_slot_];
  const GLuint zeros[2] = {0, 0};
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.counter.id());
  glBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof(zeros), zeros);
  // The groups whose box may be in view; only their vertices are dispatched.
  visible_groups_.clear();
  last_vertices_considered_ = 0;
  for (size_t g = 0; g < vertex_groups_.size(); ++g) {
    if (!culler.MayBeVisible(vertex_groups_[g])) continue;
    visible_groups_.push_back(static_cast<GLuint>(g));
    last_vertices_considered_ += vertex_groups_[g].end - vertex_groups_[g].begin;
  }
  if (!visible_groups_.empty()) {
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.groups.id());
    glBufferSubData(GL_SHADER_STORAGE_BUFFER, 0,
                    static_cast<GLsizeiptr>(visible_groups_.size() * sizeof(GLuint)),
                    visible_groups_.data());
  }
  if (depth_pass_ && !visible_groups_.empty()) {
    // Their footprints in the depth buffer, for the shader's occlusion culling of groups.
    footprints_.clear();
    for (const GLuint g : visible_groups_) {
      const ScreenBox box =
          culler.Footprint(vertex_groups_[g], depth_pass_->width(), depth_pass_->height());
      GroupFootprint f;
      if (box.bounded && box.empty()) {
        f.mode = 2;  // its box projects outside the buffer
      } else if (box.bounded && static_cast<int64_t>(box.x1 - box.x0 + 1) * (box.y1 - box.y0 + 1) <=
                                    kMaxTestedFootprint) {
        f.mode = 1;
        f.box = {box.x0, box.y0, box.x1, box.y1};
        // Rounded down: a lower bound of the vertices' depth in float too.
        f.min_depth = static_cast<float>(box.min_depth);
        if (static_cast<double>(f.min_depth) > box.min_depth)
          f.min_depth = std::nextafter(f.min_depth, 0.f);
      }
      footprints_.push_back(f);
    }
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.footprints.id());
    glBufferSubData(GL_SHADER_STORAGE_BUFFER, 0,
                    static_cast<GLsizeiptr>(footprints_.size() * sizeof(GroupFootprint)),
                    footprints_.data());
  }
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);

  GLint previous_program = 0;
  glGetIntegerv(GL_CURRENT_PROGRAM, &previous_program);
  glUseProgram(program_.id());
  camera_uniforms_.Set(uniforms);
  glUniform4fv(loc_intrinsics_, 1, uniforms.intrinsics.data());
  glUniform4fv(loc_range_, 1, uniforms.range.data());
  glUniform1ui(loc_num_vertices_, static_cast<GLuint>(num_vertices_));
  glUniform1ui(loc_num_groups_, static_cast<GLuint>(visible_groups_.size()));
  glUniform1ui(loc_capacity_, static_cast<GLuint>(capacity_));
  if (depth_pass_) {
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, depth_pass_->texture());
    glUniform1i(loc_depth_, 0);
    glUniform2f(loc_depth_size_, static_cast<float>(depth_pass_->width()),
                static_cast<float>(depth_pass_->height()));
    glUniform2f(loc_bias_, static_cast<float>(options_.occlusion_depth_bias_relative),
                static_cast<float>(options_.occlusion_depth_bias_m));
  }
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, positions_.id());
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, slot.counter.id());
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, slot.features.id());
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, slot.groups.id());
  if (depth_pass_) glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 4, slot.footprints.id());
  const GLuint workgroups =
      static_cast<GLuint>(visible_groups_.size()) * (kCullGroupSize / kLocalSize);
  if (workgroups > 0) {
    const GLuint groups_x = std::min(workgroups, kMaxGroupsX);
    const GLuint groups_y = (workgroups + groups_x - 1) / groups_x;
    glDispatchCompute(groups_x, groups_y, 1);
  }
  // Make the shader's buffer writes visible to glMapBufferRange.
  glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
  glUseProgram(static_cast<GLuint>(previous_program));
  slot.fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
  glFlush();  // start the work now; Collect() may come a frame later
  slot.tag = tag;
  if (Status s = CheckGlError("GpuProjector::Dispatch"); !s) {
    glDeleteSync(static_cast<GLsync>(slot.fence));
    slot.fence = nullptr;
    return s;
  }
  next_slot_ = (next_slot_ + 1) % kMaxFramesInFlight;
  ++in_flight_;
  return Status::Ok();
}

Status GpuProjector::Collect(std::vector<ProjectedVertex>* out, int64_t* tag) {
  if (out == nullptr) return Status::Error("GpuProjector::Collect: null output");
  if (in_flight_ == 0) return Status::Error("GpuProjector::Collect: no frame in flight");
  if (Status s = context_->MakeCurrent(); !s) return s;
  Slot& slot = slots_[(next_slot_ - in_flight_ + kMaxFramesInFlight) % kMaxFramesInFlight];
  --in_flight_;
  GLsync fence = static_cast<GLsync>(slot.fence);
  slot.fence = nullptr;
  const GLenum wait = glClientWaitSync(fence, GL_SYNC_FLUSH_COMMANDS_BIT, kFenceTimeoutNs);
  glDeleteSync(fence);
  if (wait == GL_TIMEOUT_EXPIRED || wait == GL_WAIT_FAILED) {
    return Status::Error(wait == GL_WAIT_FAILED ? "GpuProjector::Collect: glClientWaitSync failed"
                                                : "GpuProjector::Collect: GPU timed out");
  }
  if (tag != nullptr) *tag = slot.tag;

  glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.counter.id());
  const void* counter =
      glMapBufferRange(GL_SHADER_STORAGE_BUFFER, 0, 2 * sizeof(GLuint), GL_MAP_READ_BIT);
  if (counter == nullptr) {
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    return Status::Error("GpuProjector::Collect: mapping the counter failed");
  }
  GLuint counters[2] = {0, 0};
  std::memcpy(counters, counter, sizeof(counters));
  glUnmapBuffer(GL_SHADER_STORAGE_BUFFER);
  const GLuint count = counters[0];
  last_groups_hidden_ = counters[1];
  if (count > capacity_) {
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    out->clear();
    return Status::Error("GpuProjector::Collect: " + std::to_string(count) +
                         " vertices in view exceed the output buffer (" +
                         std::to_string(capacity_) +
                         " features: GL_MAX_SHADER_STORAGE_BLOCK_SIZE / 16 bytes)");
  }
  out->resize(count);  // capacity reused from frame to frame
  if (count > 0) {
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, slot.features.id());
    const void* features = glMapBufferRange(GL_SHADER_STORAGE_BUFFER, 0,
                                            static_cast<GLsizeiptr>(count) * 16, GL_MAP_READ_BIT);
    if (features == nullptr) {
      glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
      out->clear();
      return Status::Error("GpuProjector::Collect: mapping the features failed");
    }
    std::memcpy(out->data(), features, static_cast<size_t>(count) * sizeof(ProjectedVertex));
    glUnmapBuffer(GL_SHADER_STORAGE_BUFFER);
  }
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
  return CheckGlError("GpuProjector::Collect");
}

}  // namespace m2s
