#include "gpu_depth_pass.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace m2s {
namespace {

constexpr const char* kVertexShaderBody = R"(
layout(location = 0) in vec3 a_position;
void main() { gl_Position = ClipFromCamera(CameraFromWorld(a_position)); }
)";

constexpr const char* kFragmentShader = R"(#version 310 es
void main() {}
)";

// GL state the pass changes, restored afterwards so a host render loop is unaffected.
class SavedState {
 public:
  SavedState() {
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &draw_framebuffer_);
    glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &read_framebuffer_);
    glGetIntegerv(GL_VIEWPORT, viewport_);
    glGetIntegerv(GL_CURRENT_PROGRAM, &program_);
    glGetIntegerv(GL_VERTEX_ARRAY_BINDING, &vertex_array_);
    glGetIntegerv(GL_DEPTH_FUNC, &depth_func_);
    glGetBooleanv(GL_DEPTH_WRITEMASK, &depth_mask_);
    glGetFloatv(GL_DEPTH_CLEAR_VALUE, &depth_clear_);
    depth_test_ = glIsEnabled(GL_DEPTH_TEST);
    cull_face_ = glIsEnabled(GL_CULL_FACE);
    blend_ = glIsEnabled(GL_BLEND);
    scissor_ = glIsEnabled(GL_SCISSOR_TEST);
    polygon_offset_ = glIsEnabled(GL_POLYGON_OFFSET_FILL);
  }
  ~SavedState() {
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, draw_framebuffer_);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, read_framebuffer_);
    glViewport(viewport_[0], viewport_[1], viewport_[2], viewport_[3]);
    glUseProgram(program_);
    glBindVertexArray(vertex_array_);
    glDepthFunc(depth_func_);
    glDepthMask(depth_mask_);
    glClearDepthf(depth_clear_);
    Set(GL_DEPTH_TEST, depth_test_);
    Set(GL_CULL_FACE, cull_face_);
    Set(GL_BLEND, blend_);
    Set(GL_SCISSOR_TEST, scissor_);
    Set(GL_POLYGON_OFFSET_FILL, polygon_offset_);
  }

 private:
  static void Set(GLenum cap, GLboolean on) { on ? glEnable(cap) : glDisable(cap); }
  GLint draw_framebuffer_ = 0, read_framebuffer_ = 0, viewport_[4] = {0, 0, 0, 0}, program_ = 0,
        vertex_array_ = 0, depth_func_ = GL_LESS;
  GLboolean depth_mask_ = GL_TRUE, depth_test_ = GL_FALSE, cull_face_ = GL_FALSE, blend_ = GL_FALSE,
            scissor_ = GL_FALSE, polygon_offset_ = GL_FALSE;
  GLfloat depth_clear_ = 1.f;
};

}  // namespace

int OcclusionBufferSize(int image_size, double scale) {
  return std::max(1, static_cast<int>(std::lround(scale * image_size)));
}

Expected<std::unique_ptr<GpuDepthPass>> GpuDepthPass::Create(
    GLuint positions_buffer, std::span<const Eigen::Vector3f> positions,
    const std::vector<uint32_t>& triangles) {
  std::unique_ptr<GpuDepthPass> pass(new GpuDepthPass());
  pass->triangle_groups_ = MakeTriangleGroups(triangles, positions, kTriangleGroupSize);
  const std::string vertex_shader =
      std::string("#version 310 es\n") + kCameraGlsl + kVertexShaderBody;
  Expected<GlProgram> program =
      CompileProgram({{GL_VERTEX_SHADER, vertex_shader}, {GL_FRAGMENT_SHADER, kFragmentShader}});
  if (!program) return Status::Error("occlusion depth pass: " + program.error());
  pass->program_ = std::move(*program);
  const GLuint id = pass->program_.id();
  pass->camera_uniforms_ = CameraUniformLocations::Find(id);

  GLint previous_vertex_array = 0;
  glGetIntegerv(GL_VERTEX_ARRAY_BINDING, &previous_vertex_array);
  pass->vertex_array_ = MakeGlVertexArray();
  pass->indices_ = MakeGlBuffer();
  glBindVertexArray(pass->vertex_array_.id());
  glBindBuffer(GL_ARRAY_BUFFER, positions_buffer);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, pass->indices_.id());
  glBufferData(GL_ELEMENT_ARRAY_BUFFER,
               static_cast<GLsizeiptr>(std::max<size_t>(triangles.size(), 1) * sizeof(uint32_t)),
               triangles.empty() ? nullptr : triangles.data(), GL_STATIC_DRAW);
  glBindVertexArray(static_cast<GLuint>(previous_vertex_array));
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  pass->num_indices_ = static_cast<GLsizei>(triangles.size());
  pass->framebuffer_ = MakeGlFramebuffer();
  if (Status s = CheckGlError("occlusion depth pass setup"); !s) return s;
  return pass;
}

Status GpuDepthPass::Resize(int width, int height) {
  if (width == width_ && height == height_ && texture_) return Status::Ok();
  texture_ = MakeGlTexture();  // immutable storage: a new texture per size
  glBindTexture(GL_TEXTURE_2D, texture_.id());
  glTexStorage2D(GL_TEXTURE_2D, 1, GL_DEPTH_COMPONENT32F, width, height);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_MODE, GL_NONE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glBindTexture(GL_TEXTURE_2D, 0);
  GLint previous = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &previous);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, framebuffer_.id());
  glFramebufferTexture2D(GL_DRAW_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, texture_.id(), 0);
  const GLenum none = GL_NONE;
  glDrawBuffers(1, &none);
  const GLenum status = glCheckFramebufferStatus(GL_DRAW_FRAMEBUFFER);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, static_cast<GLuint>(previous));
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    texture_.Reset();
    return Status::Error("occlusion depth framebuffer incomplete (status " +
                         std::to_string(status) + ")");
  }
  width_ = width;
  height_ = height;
  return CheckGlError("occlusion depth texture");
}

Status GpuDepthPass::Render(const CameraUniforms& camera, const FrustumCuller& culler, int width,
                            int height) {
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  if (width > max_size || height > max_size) {
    return Status::Error("occlusion depth buffer " + std::to_string(width) + "x" +
                         std::to_string(height) + " exceeds GL_MAX_TEXTURE_SIZE " +
                         std::to_string(max_size));
  }
  if (Status s = Resize(width, height); !s) return s;
  SavedState saved;
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, framebuffer_.id());
  glViewport(0, 0, width, height);
  glDisable(GL_CULL_FACE);  // occluders are two-sided
  glDisable(GL_BLEND);
  glDisable(GL_SCISSOR_TEST);
  glDisable(GL_POLYGON_OFFSET_FILL);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glClearDepthf(1.f);
  glClear(GL_DEPTH_BUFFER_BIT);
  last_triangles_drawn_ = 0;
  if (num_indices_ > 0) {
    glUseProgram(program_.id());
    camera_uniforms_.Set(camera);
    glBindVertexArray(vertex_array_.id());
    // One draw per run of consecutive groups in view.
    size_t g = 0;
    while (g < triangle_groups_.size()) {
      if (!culler.MayBeVisible(triangle_groups_[g])) {
        ++g;
        continue;
      }
      const size_t first = triangle_groups_[g].begin;
      while (g < triangle_groups_.size() && culler.MayBeVisible(triangle_groups_[g])) ++g;
      const size_t count = triangle_groups_[g - 1].end - first;
      glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(3 * count), GL_UNSIGNED_INT,
                     reinterpret_cast<const void*>(3 * first * sizeof(uint32_t)));
      last_triangles_drawn_ += count;
    }
  }
  return CheckGlError("occlusion depth pass");
}

}  // namespace m2s
