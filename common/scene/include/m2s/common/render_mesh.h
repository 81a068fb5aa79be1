// RenderMesh: a scene's triangles with what a renderer needs to colour them (normals, texture
// coordinates, per-vertex colours, the material's diffuse colour and texture), grouped into one
// batch per material.
//
// Positions are in the same world frame and rounded exactly as LoadScene() computes them (the
// node transform in float as assimp stores it, then the SceneLoadOptions transform in double,
// rounded to float), so a depth image rendered from a RenderMesh agrees with the Scene's
// vertices to float precision. Normals get the same linear transform (inverse transpose),
// normalised. Texture coordinates are assimp's (channel 0; v = 0 at the image's bottom row).
//
// A RenderMesh is a plain value; it reads no file after LoadRenderMesh() returns (textures are
// named by path and decoded by the renderer). Safe to share read-only between threads.
//
//   Expected<RenderMesh> mesh = LoadRenderMesh("room.glb");
//   if (!mesh) return mesh.status();
//   auto renderer = SceneRenderer::Create(*mesh, camera);  // client_quest/render
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/scene.h"
#include "m2s/common/status.h"

namespace m2s {

// A material's diffuse texture: a file (absolute, or resolved against the model's folder), or
// an image embedded in the model: either compressed bytes (PNG, JPEG... as in a GLB file) or
// raw RGBA8 pixels (top row first).
struct RenderTexture {
  std::string path;              // file to decode; empty for an embedded texture
  std::vector<uint8_t> encoded;  // embedded compressed image (when non-empty)
  int width = 0, height = 0;     // embedded raw pixels (when width > 0)
  std::vector<uint8_t> rgba;     // width * height * 4
  std::string name;              // for messages: the path as the model names it

  bool empty() const { return path.empty() && encoded.empty() && rgba.empty(); }
};

// The triangles of one material. Optional attributes are either empty or one per position.
struct RenderBatch {
  std::string material;                          // the material's name (may be empty)
  Eigen::Vector3f diffuse{0.78f, 0.78f, 0.74f};  // RGB in [0, 1], used without a texture
  RenderTexture texture;                         // empty: no texture
  std::vector<Eigen::Vector3f> positions;        // world (metres)
  std::vector<Eigen::Vector3f> normals;          // world, unit; empty: faces are shaded flat
  std::vector<Eigen::Vector2f> uvs;              // empty without texture coordinates
  std::vector<Eigen::Vector4f> colors;           // per-vertex RGBA in [0, 1]; empty: none
  std::vector<uint32_t> triangles;               // 3 indices per triangle into positions
};

struct RenderMesh {
  std::string name;
  std::vector<RenderBatch> batches;

  size_t num_triangles() const;
  size_t num_positions() const;
};

// Loads `path` as LoadScene() does (same checks and error messages, same transform) and keeps
// materials: the diffuse colour (AI_MATKEY_COLOR_DIFFUSE, or the PBR base colour), the first
// aiTextureType_DIFFUSE (else BASE_COLOR) texture of each material, vertex colours of channel
// 0 and texture coordinates of channel 0. Meshes with the same material share a batch. Point
// and line primitives are not drawn. A texture file that is missing is reported by the
// renderer, not here.
Expected<RenderMesh> LoadRenderMesh(const std::string& path, const SceneLoadOptions& options = {});

// One untextured batch of the scene's triangles (flat shaded, the default diffuse colour):
// what the default scene renders as.
RenderMesh MakeRenderMesh(const Scene& scene);

}  // namespace m2s
