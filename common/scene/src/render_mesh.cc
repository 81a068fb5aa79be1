// RenderMesh loading with assimp; see render_mesh.h. The transform of every position is the
// one LoadScene() applies (scene.cc), evaluated with the same float / double steps.
#include "m2s/common/render_mesh.h"

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/Importer.hpp>

namespace m2s {
namespace {

RenderTexture TextureOf(const aiScene& ai, const aiMaterial& material,
                        const std::filesystem::path& folder) {
  RenderTexture texture;
  aiString name;
  const bool found = material.GetTexture(aiTextureType_DIFFUSE, 0, &name) == AI_SUCCESS ||
                     material.GetTexture(aiTextureType_BASE_COLOR, 0, &name) == AI_SUCCESS;
  if (!found || name.length == 0) return texture;
  texture.name = name.C_Str();
  if (const aiTexture* embedded = ai.GetEmbeddedTexture(name.C_Str())) {
    if (embedded->mHeight == 0) {  // compressed: mWidth bytes
      const auto* bytes = reinterpret_cast<const uint8_t*>(embedded->pcData);
      texture.encoded.assign(bytes, bytes + embedded->mWidth);
    } else {  // raw aiTexel (b, g, r, a), top row first
      texture.width = static_cast<int>(embedded->mWidth);
      texture.height = static_cast<int>(embedded->mHeight);
      const size_t n = static_cast<size_t>(texture.width) * texture.height;
      texture.rgba.resize(n * 4);
      for (size_t i = 0; i < n; ++i) {
        const aiTexel& t = embedded->pcData[i];
        texture.rgba[4 * i + 0] = t.r;
        texture.rgba[4 * i + 1] = t.g;
        texture.rgba[4 * i + 2] = t.b;
        texture.rgba[4 * i + 3] = t.a;
      }
    }
    return texture;
  }
  std::string file = texture.name;
  for (char& c : file) {
    if (c == '\\') c = '/';  // models written on Windows
  }
  const std::filesystem::path p(file);
  texture.path = (p.is_absolute() ? p : folder / p).lexically_normal().string();
  return texture;
}

RenderBatch BatchOf(const aiScene& ai, unsigned int material_index,
                    const std::filesystem::path& folder) {
  RenderBatch batch;
  if (material_index >= ai.mNumMaterials || ai.mMaterials == nullptr) return batch;
  const aiMaterial& material = *ai.mMaterials[material_index];
  aiString name;
  if (material.Get(AI_MATKEY_NAME, name) == AI_SUCCESS) batch.material = name.C_Str();
  aiColor4D color;
  if (material.Get(AI_MATKEY_BASE_COLOR, color) == AI_SUCCESS ||
      material.Get(AI_MATKEY_COLOR_DIFFUSE, color) == AI_SUCCESS) {
    batch.diffuse = Eigen::Vector3f(color.r, color.g, color.b).cwiseMax(0.f).cwiseMin(1.f);
  }
  batch.texture = TextureOf(ai, material, folder);
  return batch;
}

struct Loader {
  const aiScene& ai;
  Eigen::Matrix3d linear;  // scale * rotation
  Eigen::Matrix3d normal_linear;
  Eigen::Vector3d translation;
  std::filesystem::path folder;
  std::map<unsigned int, RenderBatch> batches;  // by material index

  void AddMesh(const aiMatrix4x4& transform, const aiMesh& mesh) {
    if (mesh.mNumVertices == 0 || mesh.mNumFaces == 0) return;
    auto [it, inserted] = batches.try_emplace(mesh.mMaterialIndex);
    if (inserted) it->second = BatchOf(ai, mesh.mMaterialIndex, folder);
    RenderBatch& batch = it->second;
    const bool normals = mesh.HasNormals() && (inserted || !batch.normals.empty());
    const bool uvs = mesh.HasTextureCoords(0) && (inserted || !batch.uvs.empty());
    const bool colors = mesh.HasVertexColors(0) && (inserted || !batch.colors.empty());
    // An attribute kept only when every mesh of the batch has it.
    if (!mesh.HasNormals()) batch.normals.clear();
    if (!mesh.HasTextureCoords(0)) batch.uvs.clear();
    if (!mesh.HasVertexColors(0)) batch.colors.clear();
    const auto first = static_cast<uint32_t>(batch.positions.size());
    aiMatrix3x3 node_normal(transform);
    node_normal.Inverse().Transpose();
    for (unsigned int v = 0; v < mesh.mNumVertices; ++v) {
      const aiVector3D q = transform * mesh.mVertices[v];
      const Eigen::Vector3d world = linear * Eigen::Vector3d(q.x, q.y, q.z) + translation;
      batch.positions.push_back(world.cast<float>());
      if (normals) {
        const aiVector3D n = node_normal * mesh.mNormals[v];
        Eigen::Vector3d w = normal_linear * Eigen::Vector3d(n.x, n.y, n.z);
        if (!(w.norm() > 0) || !w.allFinite()) w = Eigen::Vector3d::UnitZ();
        batch.normals.push_back(w.normalized().cast<float>());
      }
      if (uvs) {
        const aiVector3D& t = mesh.mTextureCoords[0][v];
        batch.uvs.emplace_back(t.x, t.y);
      }
      if (colors) {
        const aiColor4D& c = mesh.mColors[0][v];
        batch.colors.emplace_back(c.r, c.g, c.b, c.a);
      }
    }
    for (unsigned int f = 0; f < mesh.mNumFaces; ++f) {
      const aiFace& face = mesh.mFaces[f];
      for (unsigned int c = 2; c < face.mNumIndices; ++c) {  // a fan, as LoadScene
        batch.triangles.insert(
            batch.triangles.end(),
            {first + face.mIndices[0], first + face.mIndices[c - 1], first + face.mIndices[c]});
      }
    }
  }

  // Depth-first from the root, as LoadScene (the hierarchy was validated by it).
  void AddNodes(const aiNode& root) {
    struct Item {
      const aiNode* node;
      aiMatrix4x4 parent;
    };
    std::vector<Item> stack = {{&root, aiMatrix4x4()}};
    while (!stack.empty()) {
      const Item item = stack.back();
      stack.pop_back();
      const aiMatrix4x4 transform = item.parent * item.node->mTransformation;
      for (unsigned int m = 0; m < item.node->mNumMeshes; ++m) {
        AddMesh(transform, *ai.mMeshes[item.node->mMeshes[m]]);
      }
      for (unsigned int c = item.node->mNumChildren; c-- > 0;) {
        stack.push_back({item.node->mChildren[c], transform});
      }
    }
  }
};

}  // namespace

size_t RenderMesh::num_triangles() const {
  size_t n = 0;
  for (const RenderBatch& b : batches) n += b.triangles.size() / 3;
  return n;
}

size_t RenderMesh::num_positions() const {
  size_t n = 0;
  for (const RenderBatch& b : batches) n += b.positions.size();
  return n;
}

Expected<RenderMesh> LoadRenderMesh(const std::string& path, const SceneLoadOptions& options) {
  // LoadScene's checks (file, format, structure, finiteness) and its messages.
  Expected<Scene> scene = LoadScene(path, options);
  if (!scene) return scene.status();
  Assimp::Importer importer;
  const aiScene* ai = importer.ReadFile(path, aiProcess_Triangulate);
  if (ai == nullptr || ai->mRootNode == nullptr) {
    return Expected<RenderMesh>::Error("scene '" + path +
                                       "': cannot be parsed: " + importer.GetErrorString());
  }
  const Eigen::Matrix3d linear = options.scale * options.rotation.normalized().toRotationMatrix();
  Loader loader{*ai,
                linear,
                linear.inverse().transpose(),
                options.translation,
                std::filesystem::path(path).parent_path(),
                {}};
  loader.AddNodes(*ai->mRootNode);
  RenderMesh mesh;
  mesh.name = scene->name;
  for (auto& [index, batch] : loader.batches) mesh.batches.push_back(std::move(batch));
  return mesh;
}

RenderMesh MakeRenderMesh(const Scene& scene) {
  RenderMesh mesh;
  mesh.name = scene.name;
  RenderBatch batch;
  batch.positions = scene.positions;
  batch.triangles = scene.triangles;
  mesh.batches.push_back(std::move(batch));
  return mesh;
}

}  // namespace m2s
