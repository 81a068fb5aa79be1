#include "m2s/render/scene_renderer.h"

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "m2s/gpu/camera_uniforms.h"
#include "m2s/gpu/gl_util.h"

namespace m2s {
namespace {

constexpr const char* kVertexShaderBody = R"(
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec2 a_uv;
layout(location = 3) in vec4 a_color;
out vec3 v_camera;
out vec3 v_normal;
out vec2 v_uv;
out vec4 v_color;
void main() {
  // As the occlusion depth pass: camera-centred for float precision.
  vec3 x_camera = CameraFromWorld(a_position);
  v_camera = x_camera;
  v_normal = u_rotation * a_normal;
  v_uv = a_uv;
  v_color = a_color;
  gl_Position = ClipFromCamera(x_camera);
}
)";

constexpr const char* kFragmentShader = R"(#version 310 es
precision highp float;
in vec3 v_camera;
in vec3 v_normal;
in vec2 v_uv;
in vec4 v_color;
uniform sampler2D u_texture;
uniform int u_textured;
uniform int u_has_normals;
uniform vec3 u_diffuse;
uniform float u_ambient;
layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_depth;  // R32F: camera Z
void main() {
  vec3 n = u_has_normals != 0 ? v_normal : cross(dFdx(v_camera), dFdy(v_camera));
  float len = length(n);
  float shade = len > 0.0 ? u_ambient + (1.0 - u_ambient) * abs(n.z / len) : 1.0;
  vec3 albedo = u_textured != 0 ? texture(u_texture, vec2(v_uv.x, 1.0 - v_uv.y)).rgb : u_diffuse;
  o_color = vec4(clamp(albedo * v_color.rgb * shade, 0.0, 1.0), 1.0);
  o_depth = vec4(v_camera.z, 0.0, 0.0, 0.0);
}
)";

// One material's geometry on the GPU.
struct GpuBatch {
  GlVertexArray vertex_array;
  GlBuffer positions, normals, uvs, colors, indices;
  GlTexture texture;
  GLsizei num_indices = 0;
  bool has_normals = false;
  Eigen::Vector3f diffuse;
};

template <typename T>
GlBuffer Upload(GLenum target, const std::vector<T>& data) {
  GlBuffer buffer = MakeGlBuffer();
  glBindBuffer(target, buffer.id());
  glBufferData(target, static_cast<GLsizeiptr>(data.size() * sizeof(T)), data.data(),
               GL_STATIC_DRAW);
  return buffer;
}

// Binds `data` (one Eigen vector per vertex) to `location`, or sets the constant `fallback`.
template <typename V>
GlBuffer Attribute(GLuint location, const std::vector<V>& data, const Eigen::Vector4f& fallback) {
  if (data.empty()) {
    glDisableVertexAttribArray(location);
    glVertexAttrib4f(location, fallback[0], fallback[1], fallback[2], fallback[3]);
    return GlBuffer();
  }
  GlBuffer buffer = Upload(GL_ARRAY_BUFFER, data);
  glEnableVertexAttribArray(location);
  glVertexAttribPointer(location, V::RowsAtCompileTime, GL_FLOAT, GL_FALSE, sizeof(V), nullptr);
  return buffer;
}

// The texture's pixels as RGB8, top row first.
Expected<cv::Mat> DecodeTexture(const RenderTexture& texture) {
  cv::Mat bgr;
  try {
    if (!texture.rgba.empty()) {
      if (texture.width <= 0 || texture.height <= 0 ||
          texture.rgba.size() != static_cast<size_t>(texture.width) * texture.height * 4) {
        return Expected<cv::Mat>::Error("embedded texture '" + texture.name +
                                        "' has an inconsistent size");
      }
      const cv::Mat rgba(texture.height, texture.width, CV_8UC4,
                         const_cast<uint8_t*>(texture.rgba.data()));
      cv::Mat rgb;
      cv::cvtColor(rgba, rgb, cv::COLOR_RGBA2RGB);
      return rgb;
    }
    if (!texture.encoded.empty()) {
      bgr = cv::imdecode(texture.encoded, cv::IMREAD_COLOR);
    } else {
      bgr = cv::imread(texture.path, cv::IMREAD_COLOR);
    }
  } catch (const cv::Exception& e) {
    bgr = cv::Mat();
  }
  if (bgr.empty()) {
    return Expected<cv::Mat>::Error(
        texture.path.empty() ? "embedded texture '" + texture.name + "' cannot be decoded"
                             : "texture '" + texture.path + "' cannot be read or decoded");
  }
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  return rgb;
}

Expected<GlTexture> UploadTexture(const RenderTexture& source) {
  Expected<cv::Mat> rgb = DecodeTexture(source);
  if (!rgb) return rgb.status();
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  cv::Mat image = *rgb;
  if (image.cols > max_size || image.rows > max_size) {
    const double s = static_cast<double>(max_size) / std::max(image.cols, image.rows);
    cv::resize(*rgb, image, cv::Size(), s, s, cv::INTER_AREA);
  }
  if (!image.isContinuous()) image = image.clone();
  GlTexture texture = MakeGlTexture();
  glBindTexture(GL_TEXTURE_2D, texture.id());
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, image.cols, image.rows, 0, GL_RGB, GL_UNSIGNED_BYTE,
               image.data);
  glGenerateMipmap(GL_TEXTURE_2D);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_REPEAT);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_REPEAT);
  glBindTexture(GL_TEXTURE_2D, 0);
  return texture;
}

Status CheckBatch(const RenderBatch& batch, size_t index) {
  const size_t n = batch.positions.size();
  const std::string where = "render mesh batch " + std::to_string(index) + ": ";
  if (batch.triangles.size() % 3 != 0)
    return Status::Error(where + "index count not a multiple of 3");
  for (const uint32_t i : batch.triangles) {
    if (i >= n) return Status::Error(where + "triangle index out of range");
  }
  if ((!batch.normals.empty() && batch.normals.size() != n) ||
      (!batch.uvs.empty() && batch.uvs.size() != n) ||
      (!batch.colors.empty() && batch.colors.size() != n)) {
    return Status::Error(where + "attribute count differs from the position count");
  }
  return Status::Ok();
}

}  // namespace

struct SceneRenderer::Impl {
  GlProgram program;
  CameraUniformLocations camera_uniforms;
  GLint loc_textured = -1, loc_has_normals = -1, loc_diffuse = -1, loc_ambient = -1,
        loc_texture = -1;
  std::vector<GpuBatch> batches;
  GlFramebuffer framebuffer;
  GlRenderbuffer color, depth_value, depth;
  std::vector<uint8_t> rgba_scratch;
  std::vector<float> depth_scratch;

  Status MakeTarget(int width, int height);
};

Status SceneRenderer::Impl::MakeTarget(int width, int height) {
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_size);
  if (width > max_size || height > max_size) {
    return Status::Error("SceneRenderer: image " + std::to_string(width) + "x" +
                         std::to_string(height) + " exceeds GL_MAX_RENDERBUFFER_SIZE " +
                         std::to_string(max_size));
  }
  color = MakeGlRenderbuffer();
  depth_value = MakeGlRenderbuffer();
  depth = MakeGlRenderbuffer();
  const std::pair<GLuint, GLenum> storage[] = {
      {color.id(), GL_RGBA8}, {depth_value.id(), GL_R32F}, {depth.id(), GL_DEPTH_COMPONENT32F}};
  for (const auto& [id, format] : storage) {
    glBindRenderbuffer(GL_RENDERBUFFER, id);
    glRenderbufferStorage(GL_RENDERBUFFER, format, width, height);
  }
  glBindRenderbuffer(GL_RENDERBUFFER, 0);
  framebuffer = MakeGlFramebuffer();
  GLint previous = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &previous);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, framebuffer.id());
  glFramebufferRenderbuffer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color.id());
  glFramebufferRenderbuffer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_RENDERBUFFER,
                            depth_value.id());
  glFramebufferRenderbuffer(GL_DRAW_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth.id());
  const GLenum buffers[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
  glDrawBuffers(2, buffers);
  const GLenum status = glCheckFramebufferStatus(GL_DRAW_FRAMEBUFFER);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, static_cast<GLuint>(previous));
  glGetError();  // an R32F refusal is reported by the status below
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    return Status::Error("SceneRenderer: framebuffer incomplete (status " + std::to_string(status) +
                         "); an R32F colour attachment needs GLES 3.2 or EXT_color_buffer_float");
  }
  return Status::Ok();
}

SceneRenderer::SceneRenderer(std::unique_ptr<Impl> impl, const Camera& camera)
    : impl_(std::move(impl)), camera_(camera) {}
SceneRenderer::~SceneRenderer() = default;

Expected<std::unique_ptr<SceneRenderer>> SceneRenderer::Create(const RenderMesh& mesh,
                                                               const Camera& camera) {
  if (Status s = camera.Check(); !s) return s.Prefixed("SceneRenderer: camera: ");
  for (size_t b = 0; b < mesh.batches.size(); ++b) {
    if (Status s = CheckBatch(mesh.batches[b], b); !s) return s;
  }
  if (glGetString(GL_VERSION) == nullptr) {
    return Status::Error("SceneRenderer: no current GL context (create a GlContext first)");
  }
  auto impl = std::make_unique<Impl>();
  const std::string vertex_shader =
      std::string("#version 310 es\n") + kCameraGlsl + kVertexShaderBody;
  Expected<GlProgram> program =
      CompileProgram({{GL_VERTEX_SHADER, vertex_shader}, {GL_FRAGMENT_SHADER, kFragmentShader}});
  if (!program) return Status::Error("SceneRenderer: " + program.error());
  impl->program = std::move(*program);
  const GLuint id = impl->program.id();
  impl->camera_uniforms = CameraUniformLocations::Find(id);
  impl->loc_textured = glGetUniformLocation(id, "u_textured");
  impl->loc_has_normals = glGetUniformLocation(id, "u_has_normals");
  impl->loc_diffuse = glGetUniformLocation(id, "u_diffuse");
  impl->loc_ambient = glGetUniformLocation(id, "u_ambient");
  impl->loc_texture = glGetUniformLocation(id, "u_texture");
  if (Status s = impl->MakeTarget(camera.width, camera.height); !s) return s;

  GLint previous_vertex_array = 0;
  glGetIntegerv(GL_VERTEX_ARRAY_BINDING, &previous_vertex_array);
  for (const RenderBatch& batch : mesh.batches) {
    if (batch.triangles.empty()) continue;
    GpuBatch gpu;
    gpu.diffuse = batch.diffuse;
    gpu.has_normals = !batch.normals.empty();
    if (!batch.texture.empty() && !batch.uvs.empty()) {
      Expected<GlTexture> texture = UploadTexture(batch.texture);
      if (!texture) return texture.status().Prefixed("SceneRenderer: ");
      gpu.texture = std::move(*texture);
    }
    gpu.vertex_array = MakeGlVertexArray();
    glBindVertexArray(gpu.vertex_array.id());
    gpu.positions = Attribute(0, batch.positions, Eigen::Vector4f::Zero());
    gpu.normals = Attribute(1, batch.normals, Eigen::Vector4f::Zero());
    gpu.uvs = Attribute(2, batch.uvs, Eigen::Vector4f::Zero());
    gpu.colors = Attribute(3, batch.colors, Eigen::Vector4f::Ones());
    gpu.indices = Upload(GL_ELEMENT_ARRAY_BUFFER, batch.triangles);
    gpu.num_indices = static_cast<GLsizei>(batch.triangles.size());
    glBindVertexArray(static_cast<GLuint>(previous_vertex_array));
    impl->batches.push_back(std::move(gpu));
  }
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  if (Status s = CheckGlError("SceneRenderer::Create"); !s) return s;
  return std::unique_ptr<SceneRenderer>(new SceneRenderer(std::move(impl), camera));
}

Status SceneRenderer::Render(const Pose3& world_from_camera, RenderedFrame* frame) {
  if (!world_from_camera.AllFinite()) return Status::Error("SceneRenderer: non-finite pose");
  Impl& m = *impl_;
  const int width = camera_.width, height = camera_.height;
  const CameraUniforms u = MakeCameraUniforms(world_from_camera, camera_);
  GLint previous_framebuffer = 0, previous_read = 0, viewport[4] = {0, 0, 0, 0};
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &previous_framebuffer);
  glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &previous_read);
  glGetIntegerv(GL_VIEWPORT, viewport);

  glBindFramebuffer(GL_FRAMEBUFFER, m.framebuffer.id());
  glViewport(0, 0, width, height);
  glDisable(GL_CULL_FACE);  // two-sided
  glDisable(GL_BLEND);
  glDisable(GL_SCISSOR_TEST);
  glDisable(GL_POLYGON_OFFSET_FILL);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  const float black[4] = {0.f, 0.f, 0.f, 1.f}, zero[4] = {0.f, 0.f, 0.f, 0.f}, one = 1.f;
  glClearBufferfv(GL_COLOR, 0, black);
  glClearBufferfv(GL_COLOR, 1, zero);
  glClearBufferfv(GL_DEPTH, 0, &one);
  glUseProgram(m.program.id());
  m.camera_uniforms.Set(u);
  glUniform1f(m.loc_ambient, kAmbient);
  glUniform1i(m.loc_texture, 0);
  glActiveTexture(GL_TEXTURE0);
  for (const GpuBatch& batch : m.batches) {
    glUniform1i(m.loc_textured, batch.texture ? 1 : 0);
    glUniform1i(m.loc_has_normals, batch.has_normals ? 1 : 0);
    glUniform3fv(m.loc_diffuse, 1, batch.diffuse.data());
    glBindTexture(GL_TEXTURE_2D, batch.texture.id());
    glBindVertexArray(batch.vertex_array.id());
    glDrawElements(GL_TRIANGLES, batch.num_indices, GL_UNSIGNED_INT, nullptr);
  }
  glBindVertexArray(0);
  glBindTexture(GL_TEXTURE_2D, 0);

  // Row 0 of the framebuffer is the image's top row (the projection flips y): no flip here.
  const size_t n = static_cast<size_t>(width) * height;
  m.rgba_scratch.resize(n * 4);
  m.depth_scratch.resize(n * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, m.rgba_scratch.data());
  glReadBuffer(GL_COLOR_ATTACHMENT1);
  glReadPixels(0, 0, width, height, GL_RGBA, GL_FLOAT, m.depth_scratch.data());
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, static_cast<GLuint>(previous_framebuffer));
  glBindFramebuffer(GL_READ_FRAMEBUFFER, static_cast<GLuint>(previous_read));
  glViewport(viewport[0], viewport[1], viewport[2], viewport[3]);
  if (Status s = CheckGlError("SceneRenderer::Render"); !s) return s;

  frame->width = width;
  frame->height = height;
  frame->rgb.resize(n * 3);
  frame->depth.resize(n);
  for (size_t i = 0; i < n; ++i) {
    std::memcpy(&frame->rgb[3 * i], &m.rgba_scratch[4 * i], 3);
    frame->depth[i] = m.depth_scratch[4 * i];
  }
  return Status::Ok();
}

}  // namespace m2s
