// Scene loading with assimp; see scene.h for the id order.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <system_error>
#include <unordered_map>
#include <vector>

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/Importer.hpp>

#include "m2s/common/scene.h"
#include "scene_builder.h"
#include "scene_cache.h"

namespace m2s {
namespace {

struct Loader {
  const aiScene& ai;
  Eigen::Matrix3d linear;  // scale * rotation
  Eigen::Vector3d translation;
  internal::SceneBuilder builder;
  bool non_finite = false;
  std::vector<ScenePart> parts;
  std::unordered_map<std::string, int> name_uses;

  VertexId Add(const aiMatrix4x4& node_transform, const aiVector3D& p) {
    const aiVector3D q = node_transform * p;
    const Eigen::Vector3d world = linear * Eigen::Vector3d(q.x, q.y, q.z) + translation;
    const Eigen::Vector3f f = world.cast<float>();
    if (!f.allFinite()) non_finite = true;
    return builder.Add(f);
  }

  // A part per (node, mesh) visit: the new ids and triangles of the visit, and the earlier
  // ids its corners merged into.
  void AddPart(const std::string& name, const aiMatrix4x4& transform, const aiMesh& mesh) {
    ScenePart part;
    const int uses = ++name_uses[name];
    part.name = uses == 1 ? name : name + "~" + std::to_string(uses);
    part.first_triangle = static_cast<uint32_t>(builder.num_triangles());
    part.first_vertex = static_cast<VertexId>(builder.num_vertices());
    AddMesh(transform, mesh, &part.extra_ids);
    part.num_triangles = static_cast<uint32_t>(builder.num_triangles()) - part.first_triangle;
    part.end_vertex = static_cast<VertexId>(builder.num_vertices());
    std::sort(part.extra_ids.begin(), part.extra_ids.end());
    part.extra_ids.erase(std::unique(part.extra_ids.begin(), part.extra_ids.end()),
                         part.extra_ids.end());
    part.extra_ids.shrink_to_fit();
    parts.push_back(std::move(part));
  }

  void AddMesh(const aiMatrix4x4& transform, const aiMesh& mesh, std::vector<VertexId>* earlier) {
    const auto first_new = static_cast<VertexId>(builder.num_vertices());
    std::vector<VertexId> ids(mesh.mNumVertices);
    std::vector<bool> seen(mesh.mNumVertices, false);
    auto id_of = [&](unsigned int index) {
      if (!seen[index]) {
        ids[index] = Add(transform, mesh.mVertices[index]);
        if (ids[index] < first_new) earlier->push_back(ids[index]);
        seen[index] = true;
      }
      return ids[index];
    };
    for (unsigned int f = 0; f < mesh.mNumFaces; ++f) {
      const aiFace& face = mesh.mFaces[f];
      for (unsigned int c = 0; c < face.mNumIndices; ++c) id_of(face.mIndices[c]);
      // Polygons left by the triangulation (a mesh whose primitive flags hide them): a fan.
      for (unsigned int c = 2; c < face.mNumIndices; ++c) {
        builder.AddTriangle(ids[face.mIndices[0]], ids[face.mIndices[c - 1]],
                            ids[face.mIndices[c]]);
      }
    }
    for (unsigned int v = 0; v < mesh.mNumVertices; ++v) id_of(v);
  }

  // Depth-first from the root, children in order, with accumulated transforms. Iterative, so a
  // deep hierarchy cannot overflow the stack; bounded, so a malformed cyclic one cannot hang.
  bool AddNodes(const aiNode& root) {
    constexpr size_t kMaxNodeVisits = size_t{1} << 24;
    struct Item {
      const aiNode* node;
      aiMatrix4x4 parent;
      std::string parent_path;
    };
    std::vector<Item> stack = {{&root, aiMatrix4x4(), ""}};
    for (size_t visits = 0; !stack.empty(); ++visits) {
      if (visits >= kMaxNodeVisits) return false;
      const Item item = std::move(stack.back());
      stack.pop_back();
      const aiMatrix4x4 transform = item.parent * item.node->mTransformation;
      std::string path = item.parent_path;
      if (!path.empty()) path.push_back('/');
      path.append(item.node->mName.data, item.node->mName.length);
      for (unsigned int m = 0; m < item.node->mNumMeshes; ++m) {
        std::string name = path;
        if (item.node->mNumMeshes > 1) name.append("#").append(std::to_string(m));
        AddPart(name, transform, *ai.mMeshes[item.node->mMeshes[m]]);
      }
      for (unsigned int c = item.node->mNumChildren; c-- > 0;) {
        stack.push_back({item.node->mChildren[c], transform, path});
      }
    }
    return true;
  }
};

// What assimp's ValidateDataStructure checks and we rely on, without its rule that every mesh
// has faces (point clouds are valid scenes here).
Status Validate(const aiScene& ai) {
  if (ai.mNumMeshes > 0 && ai.mMeshes == nullptr) return Status::Error("mesh array missing");
  for (unsigned int m = 0; m < ai.mNumMeshes; ++m) {
    const aiMesh* mesh = ai.mMeshes[m];
    if (mesh == nullptr) return Status::Error("mesh " + std::to_string(m) + " missing");
    if (mesh->mNumVertices > 0 && mesh->mVertices == nullptr) {
      return Status::Error("mesh " + std::to_string(m) + " has no vertex array");
    }
    if (mesh->mNumFaces > 0 && mesh->mFaces == nullptr) {
      return Status::Error("mesh " + std::to_string(m) + " has no face array");
    }
    for (unsigned int f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices == 0 || face.mIndices == nullptr) {
        return Status::Error("mesh " + std::to_string(m) + " face " + std::to_string(f) +
                             " has no indices");
      }
      for (unsigned int c = 0; c < face.mNumIndices; ++c) {
        if (face.mIndices[c] >= mesh->mNumVertices) {
          return Status::Error("mesh " + std::to_string(m) + " face " + std::to_string(f) +
                               " indexes a vertex out of range");
        }
      }
    }
  }
  std::vector<const aiNode*> stack = {ai.mRootNode};
  for (size_t visits = 0; !stack.empty(); ++visits) {
    if (visits >= (size_t{1} << 24)) return Status::Error("node hierarchy too large or cyclic");
    const aiNode* node = stack.back();
    stack.pop_back();
    if (node == nullptr) return Status::Error("null node in the hierarchy");
    for (unsigned int k = 0; k < node->mNumMeshes; ++k) {
      if (node->mMeshes == nullptr || node->mMeshes[k] >= ai.mNumMeshes) {
        return Status::Error("node '" + std::string(node->mName.C_Str()) +
                             "' refers to a missing mesh");
      }
    }
    if (node->mNumChildren > 0 && node->mChildren == nullptr)
      return Status::Error("node children missing");
    for (unsigned int c = 0; c < node->mNumChildren; ++c) stack.push_back(node->mChildren[c]);
  }
  return Status::Ok();
}

Expected<Scene> ParseScene(const std::string& path, const SceneLoadOptions& options);

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace

Status SceneLoadOptions::Check() const {
  if (!std::isfinite(scale) || scale <= 0.0)
    return Status::Error("scale must be positive and finite");
  if (!rotation.coeffs().allFinite() || std::abs(rotation.norm() - 1.0) > 1e-6) {
    return Status::Error("rotation must be a finite unit quaternion");
  }
  if (!translation.allFinite()) return Status::Error("translation must be finite");
  return Status::Ok();
}

Expected<Scene> LoadScene(const std::string& path, const SceneLoadOptions& options) {
  const std::string where = "scene '" + path + "': ";
  if (Status s = options.Check(); !s) return s.Prefixed(where + "invalid load options: ");
  std::error_code ec;
  const std::filesystem::path fs_path(path);
  if (!std::filesystem::exists(fs_path, ec)) return Expected<Scene>::Error(where + "no such file");
  if (!std::filesystem::is_regular_file(fs_path, ec)) {
    return Expected<Scene>::Error(where + "not a regular file");
  }
  if (!std::ifstream(path, std::ios::binary).good()) {
    return Expected<Scene>::Error(where + "cannot be opened for reading");
  }
  const uint64_t file_size = std::filesystem::file_size(fs_path, ec);
  if (file_size == 0) return Expected<Scene>::Error(where + "empty file");

  // The cache: the key hashes the file's bytes, so an edited file never reads a stale entry.
  std::string cache_dir;
  std::optional<uint64_t> cache_key;
  uint64_t source_size = 0;
  if (options.use_cache && file_size >= options.cache_min_bytes) {
    cache_dir = internal::SceneCacheDir(options);
    if (!cache_dir.empty()) cache_key = internal::SceneCacheKey(path, options, &source_size);
    if (cache_key) {
      if (std::optional<Scene> cached =
              internal::ReadSceneCache(cache_dir, *cache_key, source_size, options)) {
        cached->name = fs_path.stem().string();
        return std::move(*cached);
      }
    }
  }
  Expected<Scene> parsed = ParseScene(path, options);
  if (parsed && cache_key) {
    internal::WriteSceneCache(cache_dir, *cache_key, source_size, options, *parsed);
  }
  return parsed;
}

namespace {

// LoadScene without the cache: assimp, then the id assignment of scene.h.
Expected<Scene> ParseScene(const std::string& path, const SceneLoadOptions& options) {
  const std::string where = "scene '" + path + "': ";
  const std::filesystem::path fs_path(path);

  Assimp::Importer importer;
  const std::string extension = Lower(fs_path.extension().string());
  // By extension only: assimp would otherwise sniff the content, slowly and by guesswork.
  if (extension.empty() || !importer.IsExtensionSupported(extension)) {
    return Expected<Scene>::Error(where + "unsupported format '" + extension + "'");
  }
  // Import without post-processing, validate, then triangulate only: no step that reorders
  // faces or joins vertices.
  const aiScene* ai = importer.ReadFile(path, 0);
  if (ai == nullptr) {
    return Expected<Scene>::Error(where + "cannot be parsed: " + importer.GetErrorString());
  }
  if (ai->mRootNode == nullptr || ai->mNumMeshes == 0) {
    return Expected<Scene>::Error(where + "no vertices (the file has no meshes)");
  }
  if (Status valid = Validate(*ai); !valid) return valid.Prefixed(where + "invalid data: ");
  ai = importer.ApplyPostProcessing(aiProcess_Triangulate);
  if (ai == nullptr) {
    return Expected<Scene>::Error(where + "triangulation failed: " + importer.GetErrorString());
  }

  Loader loader{*ai,
                options.scale * options.rotation.normalized().toRotationMatrix(),
                options.translation,
                {},
                false,
                {},
                {}};
  size_t vertices_in_meshes = 0;  // a hint: instanced meshes count once
  for (unsigned int m = 0; m < ai->mNumMeshes; ++m)
    vertices_in_meshes += ai->mMeshes[m]->mNumVertices;
  loader.builder.Reserve(vertices_in_meshes);
  if (!loader.AddNodes(*ai->mRootNode)) {
    return Expected<Scene>::Error(where + "node hierarchy too large or cyclic");
  }
  if (loader.non_finite) return Expected<Scene>::Error(where + "non-finite vertex positions");
  if (loader.builder.num_vertices() == 0) {
    return Expected<Scene>::Error(where + "no vertices (meshes are empty or not used by any node)");
  }
  Scene scene = std::move(loader.builder).Build(fs_path.stem().string());
  scene.parts = std::move(loader.parts);
  return scene;
}

}  // namespace

Expected<Scene> LoadSceneOrDefault(const std::string& path) {
  if (path.empty()) return MakeDefaultScene();
  return LoadScene(path);
}

}  // namespace m2s
