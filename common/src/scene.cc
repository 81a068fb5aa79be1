// Scene loading with assimp; see scene.h for the id order.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/Importer.hpp>

#include "m2s/common/scene.h"
#include "scene_builder.h"

namespace m2s {
namespace {

struct Loader {
  const aiScene& ai;
  Eigen::Matrix3d linear;  // scale * rotation
  Eigen::Vector3d translation;
  internal::SceneBuilder builder;
  bool non_finite = false;

  VertexId Add(const aiMatrix4x4& node_transform, const aiVector3D& p) {
    const aiVector3D q = node_transform * p;
    const Eigen::Vector3d world = linear * Eigen::Vector3d(q.x, q.y, q.z) + translation;
    const Eigen::Vector3f f = world.cast<float>();
    if (!f.allFinite()) non_finite = true;
    return builder.Add(f);
  }

  void AddMesh(const aiMatrix4x4& transform, const aiMesh& mesh) {
    std::vector<VertexId> ids(mesh.mNumVertices);
    std::vector<bool> seen(mesh.mNumVertices, false);
    auto id_of = [&](unsigned int index) {
      if (!seen[index]) {
        ids[index] = Add(transform, mesh.mVertices[index]);
        seen[index] = true;
      }
      return ids[index];
    };
    for (unsigned int f = 0; f < mesh.mNumFaces; ++f) {
      const aiFace& face = mesh.mFaces[f];
      for (unsigned int c = 0; c < face.mNumIndices; ++c) id_of(face.mIndices[c]);
      if (face.mNumIndices == 3) {
        builder.AddTriangle(ids[face.mIndices[0]], ids[face.mIndices[1]], ids[face.mIndices[2]]);
      }
    }
    for (unsigned int v = 0; v < mesh.mNumVertices; ++v) id_of(v);
  }

  void AddNode(const aiNode& node, const aiMatrix4x4& parent) {
    const aiMatrix4x4 transform = parent * node.mTransformation;
    for (unsigned int m = 0; m < node.mNumMeshes; ++m) {
      AddMesh(transform, *ai.mMeshes[node.mMeshes[m]]);
    }
    for (unsigned int c = 0; c < node.mNumChildren; ++c) AddNode(*node.mChildren[c], transform);
  }
};

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace

bool SceneLoadOptions::Check(std::string* why) const {
  auto fail = [why](const char* message) {
    if (why) *why = message;
    return false;
  };
  if (!std::isfinite(scale) || scale <= 0.0) return fail("scale must be positive and finite");
  if (!rotation.coeffs().allFinite() || std::abs(rotation.norm() - 1.0) > 1e-6) {
    return fail("rotation must be a finite unit quaternion");
  }
  if (!translation.allFinite()) return fail("translation must be finite");
  return true;
}

Expected<Scene> LoadScene(const std::string& path, const SceneLoadOptions& options) {
  const std::string where = "scene '" + path + "': ";
  std::string why;
  if (!options.Check(&why)) return Expected<Scene>::Error(where + "invalid load options: " + why);
  std::error_code ec;
  const std::filesystem::path fs_path(path);
  if (!std::filesystem::exists(fs_path, ec)) return Expected<Scene>::Error(where + "no such file");
  if (!std::filesystem::is_regular_file(fs_path, ec)) {
    return Expected<Scene>::Error(where + "not a regular file");
  }
  if (!std::ifstream(path, std::ios::binary).good()) {
    return Expected<Scene>::Error(where + "cannot be opened for reading");
  }
  if (std::filesystem::file_size(fs_path, ec) == 0)
    return Expected<Scene>::Error(where + "empty file");

  Assimp::Importer importer;
  const std::string extension = Lower(fs_path.extension().string());
  // Only triangulation and validation: neither reorders faces nor joins vertices.
  const aiScene* ai =
      importer.ReadFile(path, aiProcess_Triangulate | aiProcess_ValidateDataStructure);
  if (ai == nullptr) {
    if (extension.empty() || !importer.IsExtensionSupported(extension)) {
      return Expected<Scene>::Error(where + "unsupported format '" + extension +
                                    "' (assimp: " + importer.GetErrorString() + ")");
    }
    return Expected<Scene>::Error(where + "cannot be parsed: " + importer.GetErrorString());
  }
  if (ai->mRootNode == nullptr || ai->mNumMeshes == 0) {
    return Expected<Scene>::Error(where + "no vertices (the file has no meshes)");
  }

  Loader loader{*ai,
                options.scale * options.rotation.normalized().toRotationMatrix(),
                options.translation,
                {}};
  loader.AddNode(*ai->mRootNode, aiMatrix4x4());
  if (loader.non_finite) return Expected<Scene>::Error(where + "non-finite vertex positions");
  if (loader.builder.num_vertices() == 0) {
    return Expected<Scene>::Error(where + "no vertices (meshes are empty or not used by any node)");
  }
  return std::move(loader.builder).Build(fs_path.stem().string());
}

}  // namespace m2s
