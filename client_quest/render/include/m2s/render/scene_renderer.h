// SceneRenderer: colour and metric depth images of a RenderMesh (common/render_mesh.h) seen by
// a project camera, for image-based methods (m2s_export) and front ends that need pixels.
//
// Geometry: the projection of the occlusion pass and the projectors (camera.h): a world point
// with camera coordinates (X, Y, Z) lands at u = fx X/Z + cx, v = fy Y/Z + cy, and pixel
// (i, j) of the image is sampled at its centre (i + 0.5, j + 0.5); a vertex at (u, v) lies in
// pixel (floor(u), floor(v)). Triangles are clipped at near and far, drawn two-sided, and
// the nearest one at each pixel centre wins (32-bit float depth test).
//
// Outputs (RenderedFrame, top row first):
//  * depth: the camera Z (metres) of the surface at the pixel centre, written from a
//    perspective-correct varying into a 32-bit float colour attachment (not reconstructed from
//    the depth buffer); 0 where no triangle covers the pixel centre.
//  * rgb: albedo * shade, 8 bits. Albedo is the batch's texture at the fragment's texture
//    coordinates (assimp's v flipped: v = 0 is the image's bottom row; repeat wrapping,
//    trilinear mip-mapping) when the batch has a texture and texture coordinates, otherwise
//    its diffuse colour; either is multiplied by the per-vertex colour when present.
//    shade = kAmbient + (1 - kAmbient) |n_z|, n the unit normal in camera coordinates (the
//    interpolated vertex normal, or the face normal without normals): a directional light
//    along the camera's viewing axis, so faces of different orientation differ. Background 0.
//
// Needs a current GLES 3.1+ context (GlContext, client_quest/gpu) with renderable R32F
// (GLES 3.2, or EXT_color_buffer_float) on the calling thread for Create() and Render();
// GL objects are released in the destructor, which must run with that context current. Not
// thread-safe. Render() restores the framebuffer binding and the viewport; it leaves the
// program, vertex array, texture unit 0, depth test and face culling state changed.
//
//   auto context = GlContext::CreateHeadless();
//   auto renderer = SceneRenderer::Create(LoadRenderMesh("room.obj").value(), camera);
//   RenderedFrame frame;
//   Status s = (*renderer)->Render(world_from_camera, &frame);
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/render_mesh.h"
#include "m2s/common/status.h"

namespace m2s {

struct RenderedFrame {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // width * height * 3, top row first
  std::vector<float> depth;  // width * height, metres along the camera z axis, 0 = nothing
};

class SceneRenderer {
 public:
  // Ambient part of the shading (see the header comment).
  static constexpr float kAmbient = 0.25f;

  // Needs a current GLES 3.1+ context; decodes textures (OpenCV imgcodecs) and uploads the
  // mesh. Errors: bad camera, no current context or no renderable R32F, a texture that cannot
  // be read or decoded (naming it), an image larger than the GL limits.
  static Expected<std::unique_ptr<SceneRenderer>> Create(const RenderMesh& mesh,
                                                         const Camera& camera);
  ~SceneRenderer();
  SceneRenderer(const SceneRenderer&) = delete;
  SceneRenderer& operator=(const SceneRenderer&) = delete;

  // Renders the mesh from `world_from_camera` (OpenCV camera axes) into `frame` (resized to
  // the camera's image; its storage is reused). Error on a non-finite pose or a GL error.
  Status Render(const Pose3& world_from_camera, RenderedFrame* frame);

  const Camera& camera() const { return camera_; }

  struct Impl;

 private:
  SceneRenderer(std::unique_ptr<Impl> impl, const Camera& camera);
  std::unique_ptr<Impl> impl_;
  Camera camera_;
};

}  // namespace m2s
