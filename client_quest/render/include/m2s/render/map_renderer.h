// MapRenderer: draws the scene mesh, the SLAM map points, the keyframe frusta and the
// estimated / ground-truth camera frusta with GLES 3 into whatever framebuffer is bound.
//
// Inputs are plain data (positions, triangles, points, poses, a Camera for the frustum shape),
// so the renderer knows nothing of the server: the headless client renders a chosen viewpoint
// into an OffscreenTarget (offscreen_target.h), the XR app renders each eye into its swapchain
// image with that eye's view and projection.
//
// Matrices are OpenGL's: `view` maps world to GL eye coordinates (x right, y up, looking down
// -z), `projection` eye to clip. For a camera of this project (OpenCV axes), use
// ViewMatrix(world_from_camera) and Camera::GlProjection(); a pixel (u, v) of that camera then
// lands on window pixel (u, height - v), i.e. on image row v once OffscreenTarget flips rows.
//
// Drawing: the mesh is flat-shaded from screen-space derivatives of its world position (no
// normals needed; a head light plus a fixed sun keep faces apart) and pushed back with a
// polygon offset so points and lines on its surface stay visible; or drawn as its unique
// edges (wireframe); or not at all. Map points are round GL_POINTS of a given pixel size,
// frusta are GL_LINES: apex to the four image corners and the image rectangle at
// `frustum_depth_m`.
//
// Needs a current GLES 3.0+ context on the calling thread for Create(), the setters and
// Draw(); GL objects are released in the destructor, which must run with that context
// current. Not thread-safe. Buffers grow geometrically and are reused: no allocation per
// Draw() in steady state. Draw() changes the program, vertex array, depth, blend and polygon
// offset state and leaves them changed (the caller owns the frame's GL state).
//
//   auto renderer = MapRenderer::Create(MapRendererOptions{});
//   (*renderer)->SetMesh(scene.positions, scene.triangles);
//   (*renderer)->SetMapPoints(points);
//   (*renderer)->Draw(MapRenderer::ViewMatrix(viewpoint), camera.GlProjection().cast<float>());
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/status.h"
#include "m2s/gpu/gl_util.h"

namespace m2s {

struct MapRendererOptions {
  enum class MeshStyle { kShaded, kWireframe, kHidden };
  MeshStyle mesh_style = MeshStyle::kShaded;
  // RGBA colours in [0, 1].
  Eigen::Vector4f background = {0.08f, 0.08f, 0.10f, 1.f};
  Eigen::Vector4f mesh_color = {0.78f, 0.78f, 0.74f, 1.f};
  Eigen::Vector4f wireframe_color = {0.55f, 0.55f, 0.60f, 1.f};
  Eigen::Vector4f point_color = {1.f, 0.15f, 0.15f, 1.f};          // map points: red
  Eigen::Vector4f keyframe_color = {0.2f, 0.45f, 1.f, 1.f};        // keyframes: blue
  Eigen::Vector4f other_keyframe_color = {0.9f, 0.2f, 0.9f, 1.f};  // other agents': magenta
  Eigen::Vector4f estimate_color = {0.1f, 0.95f, 0.2f, 1.f};       // estimated pose: green
  Eigen::Vector4f ground_truth_color = {1.f, 0.65f, 0.f, 1.f};     // ground truth: orange
  float point_size_px = 3.f;     // diameter of a map point, in pixels (> 0)
  float line_width_px = 1.f;     // requested frustum line width (drivers may cap it at 1)
  double frustum_depth_m = 0.1;  // distance from the apex to the drawn image rectangle (> 0)
  bool clear = true;             // clear colour and depth before drawing

  Status Check() const;
};

class MapRenderer {
 public:
  static Expected<std::unique_ptr<MapRenderer>> Create(const MapRendererOptions& options);
  ~MapRenderer();
  MapRenderer(const MapRenderer&) = delete;
  MapRenderer& operator=(const MapRenderer&) = delete;

  // GL view matrix (world -> GL eye) of a camera with OpenCV axes: GlFromCv() * camera_from_world.
  static Eigen::Matrix4f ViewMatrix(const Pose3& world_from_camera);

  // Uploads the mesh (done once per scene). Error on indices out of range or a count that is
  // not a multiple of 3.
  Status SetMesh(const std::vector<Eigen::Vector3f>& positions,
                 const std::vector<uint32_t>& triangles);
  void SetMapPoints(const std::vector<Eigen::Vector3f>& points);
  void SetKeyframes(const std::vector<Pose3>& world_from_keyframes);
  // Keyframes of other agents sharing the map, drawn in other_keyframe_color.
  void SetOtherKeyframes(const std::vector<Pose3>& world_from_keyframes);
  void SetEstimatedPose(std::optional<Pose3> world_from_camera);
  void SetGroundTruthPose(std::optional<Pose3> world_from_camera);
  // The camera whose image rectangle the frusta show (default: Camera{}).
  void SetFrustumCamera(const Camera& camera);

  // Draws everything into the bound framebuffer with the current viewport.
  Status Draw(const Eigen::Matrix4f& view, const Eigen::Matrix4f& projection);

  const MapRendererOptions& options() const { return options_; }

 private:
  explicit MapRenderer(const MapRendererOptions& options) : options_(options) {}
  Status Init();
  // Appends the 8 line segments of one frustum to `lines` (pairs of endpoints).
  void AppendFrustum(const Pose3& world_from_camera, std::vector<Eigen::Vector3f>* lines) const;
  // Uploads `data` into `buffer` (growing its storage geometrically) bound to `target`.
  static void Upload(GLenum target, GLuint buffer, const void* data, size_t bytes,
                     size_t* capacity);
  void DrawLines(size_t first_vertex, size_t count, const Eigen::Vector4f& color);

  MapRendererOptions options_;
  Camera frustum_camera_;
  std::vector<Pose3> keyframes_, other_keyframes_;
  std::optional<Pose3> estimate_, ground_truth_;
  std::vector<Eigen::Vector3f> line_scratch_;

  GlProgram shaded_program_, flat_program_;
  GlVertexArray mesh_vertex_array_, wire_vertex_array_, point_vertex_array_, line_vertex_array_;
  GlBuffer mesh_positions_, mesh_indices_, wire_indices_, points_, lines_;
  size_t points_capacity_ = 0, lines_capacity_ = 0;
  GLsizei num_mesh_indices_ = 0, num_wire_indices_ = 0, num_points_ = 0;
  GLint shaded_view_projection_ = -1, shaded_eye_ = -1, shaded_color_ = -1;
  GLint flat_view_projection_ = -1, flat_color_ = -1, flat_point_size_ = -1, flat_round_ = -1;
};

}  // namespace m2s
