#include "m2s/render/map_renderer.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <utility>

namespace m2s {
namespace {

constexpr const char* kShadedVertex = R"(#version 300 es
layout(location = 0) in vec3 a_position;
uniform mat4 u_view_projection;
out vec3 v_world;
void main() {
  v_world = a_position;
  gl_Position = u_view_projection * vec4(a_position, 1.0);
}
)";

// Flat shading: the face normal from screen-space derivatives of the world position.
constexpr const char* kShadedFragment = R"(#version 300 es
precision highp float;
in vec3 v_world;
uniform vec3 u_eye;
uniform vec4 u_color;
out vec4 o_color;
void main() {
  vec3 n = normalize(cross(dFdx(v_world), dFdy(v_world)));
  vec3 to_eye = normalize(u_eye - v_world);
  const vec3 sun = vec3(0.3713907, 0.5570860, 0.7427814);  // normalize(2, 3, 4)
  float head_light = abs(dot(n, to_eye));
  float sun_light = abs(dot(n, sun));
  float shade = 0.25 + 0.5 * head_light + 0.25 * sun_light;
  o_color = vec4(u_color.rgb * shade, u_color.a);
}
)";

constexpr const char* kFlatVertex = R"(#version 300 es
layout(location = 0) in vec3 a_position;
uniform mat4 u_view_projection;
uniform float u_point_size;
void main() {
  gl_Position = u_view_projection * vec4(a_position, 1.0);
  gl_PointSize = u_point_size;
}
)";

constexpr const char* kFlatFragment = R"(#version 300 es
precision mediump float;
uniform vec4 u_color;
uniform bool u_round;  // round points: drop the corners of the point sprite
out vec4 o_color;
void main() {
  if (u_round) {
    vec2 d = gl_PointCoord - vec2(0.5);
    if (dot(d, d) > 0.25) discard;
  }
  o_color = u_color;
}
)";

void SetupPositionArray(GLuint vertex_array, GLuint positions, GLuint indices) {
  glBindVertexArray(vertex_array);
  glBindBuffer(GL_ARRAY_BUFFER, positions);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
  if (indices != 0) glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, indices);
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
}

bool FiniteColor(const Eigen::Vector4f& c) {
  return c.allFinite() && c.minCoeff() >= 0.f && c.maxCoeff() <= 1.f;
}

}  // namespace

Status MapRendererOptions::Check() const {
  for (const Eigen::Vector4f* c :
       {&background, &mesh_color, &wireframe_color, &point_color, &keyframe_color,
        &other_keyframe_color, &estimate_color, &ground_truth_color}) {
    if (!FiniteColor(*c)) return Status::Error("renderer colours must be RGBA in [0, 1]");
  }
  if (!(point_size_px > 0.f) || !std::isfinite(point_size_px))
    return Status::Error("point_size_px must be finite and > 0");
  if (!(line_width_px > 0.f) || !std::isfinite(line_width_px))
    return Status::Error("line_width_px must be finite and > 0");
  if (!(frustum_depth_m > 0.0) || !std::isfinite(frustum_depth_m))
    return Status::Error("frustum_depth_m must be finite and > 0");
  return Status::Ok();
}

Expected<std::unique_ptr<MapRenderer>> MapRenderer::Create(const MapRendererOptions& options) {
  if (Status s = options.Check(); !s) return s.Prefixed("MapRenderer: ");
  std::unique_ptr<MapRenderer> renderer(new MapRenderer(options));
  if (Status s = renderer->Init(); !s) return Status::Error("MapRenderer: " + s.message());
  return renderer;
}

MapRenderer::~MapRenderer() = default;

Status MapRenderer::Init() {
  Expected<GlProgram> shaded =
      CompileProgram({{GL_VERTEX_SHADER, kShadedVertex}, {GL_FRAGMENT_SHADER, kShadedFragment}});
  if (!shaded) return shaded.status();
  Expected<GlProgram> flat =
      CompileProgram({{GL_VERTEX_SHADER, kFlatVertex}, {GL_FRAGMENT_SHADER, kFlatFragment}});
  if (!flat) return flat.status();
  shaded_program_ = std::move(*shaded);
  flat_program_ = std::move(*flat);
  shaded_view_projection_ = glGetUniformLocation(shaded_program_.id(), "u_view_projection");
  shaded_eye_ = glGetUniformLocation(shaded_program_.id(), "u_eye");
  shaded_color_ = glGetUniformLocation(shaded_program_.id(), "u_color");
  flat_view_projection_ = glGetUniformLocation(flat_program_.id(), "u_view_projection");
  flat_color_ = glGetUniformLocation(flat_program_.id(), "u_color");
  flat_point_size_ = glGetUniformLocation(flat_program_.id(), "u_point_size");
  flat_round_ = glGetUniformLocation(flat_program_.id(), "u_round");

  mesh_positions_ = MakeGlBuffer();
  mesh_indices_ = MakeGlBuffer();
  wire_indices_ = MakeGlBuffer();
  points_ = MakeGlBuffer();
  lines_ = MakeGlBuffer();
  mesh_vertex_array_ = MakeGlVertexArray();
  wire_vertex_array_ = MakeGlVertexArray();
  point_vertex_array_ = MakeGlVertexArray();
  line_vertex_array_ = MakeGlVertexArray();
  SetupPositionArray(mesh_vertex_array_.id(), mesh_positions_.id(), mesh_indices_.id());
  SetupPositionArray(wire_vertex_array_.id(), mesh_positions_.id(), wire_indices_.id());
  SetupPositionArray(point_vertex_array_.id(), points_.id(), 0);
  SetupPositionArray(line_vertex_array_.id(), lines_.id(), 0);
  return CheckGlError("MapRenderer setup");
}

Eigen::Matrix4f MapRenderer::ViewMatrix(const Pose3& world_from_camera) {
  return (Camera::GlFromCv() * world_from_camera.Inverse().Matrix()).cast<float>();
}

Status MapRenderer::SetMesh(const std::vector<Eigen::Vector3f>& positions,
                            const std::vector<uint32_t>& triangles) {
  if (triangles.size() % 3 != 0) {
    return Status::Error("MapRenderer::SetMesh: triangle index count is not a multiple of 3");
  }
  for (uint32_t index : triangles) {
    if (index >= positions.size()) {
      return Status::Error("MapRenderer::SetMesh: triangle index " + std::to_string(index) +
                           " out of range (" + std::to_string(positions.size()) + " vertices)");
    }
  }
  // Unique undirected edges for the wireframe.
  std::vector<std::pair<uint32_t, uint32_t>> edges;
  edges.reserve(triangles.size());
  for (size_t t = 0; t < triangles.size(); t += 3) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = triangles[t + k], b = triangles[t + (k + 1) % 3];
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<uint32_t> wire;
  wire.reserve(2 * edges.size());
  for (const auto& [a, b] : edges) wire.insert(wire.end(), {a, b});

  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "positions must be packed");
  glBindBuffer(GL_ARRAY_BUFFER, mesh_positions_.id());
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(positions.size() * sizeof(Eigen::Vector3f)),
               positions.empty() ? nullptr : positions.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  glBindVertexArray(0);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mesh_indices_.id());
  glBufferData(GL_ELEMENT_ARRAY_BUFFER,
               static_cast<GLsizeiptr>(triangles.size() * sizeof(uint32_t)),
               triangles.empty() ? nullptr : triangles.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, wire_indices_.id());
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(wire.size() * sizeof(uint32_t)),
               wire.empty() ? nullptr : wire.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, 0);
  num_mesh_indices_ = static_cast<GLsizei>(triangles.size());
  num_wire_indices_ = static_cast<GLsizei>(wire.size());
  return CheckGlError("MapRenderer::SetMesh");
}

void MapRenderer::Upload(GLenum target, GLuint buffer, const void* data, size_t bytes,
                         size_t* capacity) {
  glBindBuffer(target, buffer);
  if (bytes > *capacity) {
    *capacity = std::max<size_t>(bytes, 2 * *capacity);
    glBufferData(target, static_cast<GLsizeiptr>(*capacity), nullptr, GL_DYNAMIC_DRAW);
  }
  if (bytes > 0) glBufferSubData(target, 0, static_cast<GLsizeiptr>(bytes), data);
  glBindBuffer(target, 0);
}

void MapRenderer::SetMapPoints(const std::vector<Eigen::Vector3f>& points) {
  Upload(GL_ARRAY_BUFFER, points_.id(), points.data(), points.size() * sizeof(Eigen::Vector3f),
         &points_capacity_);
  num_points_ = static_cast<GLsizei>(points.size());
}

void MapRenderer::SetKeyframes(const std::vector<Pose3>& world_from_keyframes) {
  keyframes_ = world_from_keyframes;
}
void MapRenderer::SetOtherKeyframes(const std::vector<Pose3>& world_from_keyframes) {
  other_keyframes_ = world_from_keyframes;
}
void MapRenderer::SetEstimatedPose(std::optional<Pose3> world_from_camera) {
  estimate_ = world_from_camera;
}
void MapRenderer::SetGroundTruthPose(std::optional<Pose3> world_from_camera) {
  ground_truth_ = world_from_camera;
}
void MapRenderer::SetFrustumCamera(const Camera& camera) { frustum_camera_ = camera; }

void MapRenderer::AppendFrustum(const Pose3& world_from_camera,
                                std::vector<Eigen::Vector3f>* lines) const {
  const Camera& c = frustum_camera_;
  const double d = options_.frustum_depth_m;
  const Eigen::Vector3f apex = world_from_camera.translation().cast<float>();
  const Eigen::Vector2d image_corners[4] = {
      {0, 0}, {double(c.width), 0}, {double(c.width), double(c.height)}, {0, double(c.height)}};
  Eigen::Vector3f corners[4];
  for (int i = 0; i < 4; ++i) {
    corners[i] = (world_from_camera * c.Unproject(image_corners[i], d)).cast<float>();
  }
  for (int i = 0; i < 4; ++i) {
    lines->push_back(apex);
    lines->push_back(corners[i]);
    lines->push_back(corners[i]);
    lines->push_back(corners[(i + 1) % 4]);
  }
}

void MapRenderer::DrawLines(size_t first_vertex, size_t count, const Eigen::Vector4f& color) {
  if (count == 0) return;
  glUniform4fv(flat_color_, 1, color.data());
  glDrawArrays(GL_LINES, static_cast<GLint>(first_vertex), static_cast<GLsizei>(count));
}

Status MapRenderer::Draw(const Eigen::Matrix4f& view, const Eigen::Matrix4f& projection) {
  if (!view.allFinite() || !projection.allFinite()) {
    return Status::Error("MapRenderer::Draw: view or projection matrix is not finite");
  }
  const Eigen::Matrix4f view_projection = projection * view;
  const Eigen::Vector3f eye = -view.topLeftCorner<3, 3>().transpose() * view.topRightCorner<3, 1>();
  if (options_.clear) {
    const Eigen::Vector4f& bg = options_.background;
    glClearColor(bg[0], bg[1], bg[2], bg[3]);
    glClearDepthf(1.f);
    glDepthMask(GL_TRUE);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  }
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);

  if (options_.mesh_style == MapRendererOptions::MeshStyle::kShaded && num_mesh_indices_ > 0) {
    glUseProgram(shaded_program_.id());
    glUniformMatrix4fv(shaded_view_projection_, 1, GL_FALSE, view_projection.data());
    glUniform3fv(shaded_eye_, 1, eye.data());
    glUniform4fv(shaded_color_, 1, options_.mesh_color.data());
    glEnable(GL_POLYGON_OFFSET_FILL);  // keep points and lines on the surface visible
    glPolygonOffset(1.f, 2.f);
    glBindVertexArray(mesh_vertex_array_.id());
    glDrawElements(GL_TRIANGLES, num_mesh_indices_, GL_UNSIGNED_INT, nullptr);
    glDisable(GL_POLYGON_OFFSET_FILL);
  }

  glUseProgram(flat_program_.id());
  glUniformMatrix4fv(flat_view_projection_, 1, GL_FALSE, view_projection.data());
  glUniform1f(flat_point_size_, 1.f);
  glUniform1i(flat_round_, 0);
  if (options_.mesh_style == MapRendererOptions::MeshStyle::kWireframe && num_wire_indices_ > 0) {
    glUniform4fv(flat_color_, 1, options_.wireframe_color.data());
    glBindVertexArray(wire_vertex_array_.id());
    glDrawElements(GL_LINES, num_wire_indices_, GL_UNSIGNED_INT, nullptr);
  }

  line_scratch_.clear();
  for (const Pose3& keyframe : keyframes_) AppendFrustum(keyframe, &line_scratch_);
  const size_t keyframe_lines = line_scratch_.size();
  for (const Pose3& keyframe : other_keyframes_) AppendFrustum(keyframe, &line_scratch_);
  const size_t other_lines = line_scratch_.size() - keyframe_lines;
  if (ground_truth_) AppendFrustum(*ground_truth_, &line_scratch_);
  const size_t ground_truth_first = keyframe_lines + other_lines;
  const size_t ground_truth_lines = line_scratch_.size() - ground_truth_first;
  if (estimate_) AppendFrustum(*estimate_, &line_scratch_);
  const size_t estimate_lines = line_scratch_.size() - ground_truth_first - ground_truth_lines;
  if (!line_scratch_.empty()) {
    Upload(GL_ARRAY_BUFFER, lines_.id(), line_scratch_.data(),
           line_scratch_.size() * sizeof(Eigen::Vector3f), &lines_capacity_);
    glLineWidth(options_.line_width_px);
    glBindVertexArray(line_vertex_array_.id());
    DrawLines(0, keyframe_lines, options_.keyframe_color);
    DrawLines(keyframe_lines, other_lines, options_.other_keyframe_color);
    DrawLines(ground_truth_first, ground_truth_lines, options_.ground_truth_color);
    // The estimate last: where it coincides with the ground truth, it shows.
    DrawLines(ground_truth_first + ground_truth_lines, estimate_lines, options_.estimate_color);
  }

  if (num_points_ > 0) {
    glUniform1f(flat_point_size_, options_.point_size_px);
    glUniform1i(flat_round_, options_.point_size_px > 2.f ? 1 : 0);
    glUniform4fv(flat_color_, 1, options_.point_color.data());
    glBindVertexArray(point_vertex_array_.id());
    glDrawArrays(GL_POINTS, 0, num_points_);
  }
  glBindVertexArray(0);
  glUseProgram(0);
  return CheckGlError("MapRenderer::Draw");
}

}  // namespace m2s
