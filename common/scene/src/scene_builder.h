// Internal: builds a Scene from positions, merging exactly equal positions into one id.
// Used by LoadScene (assimp meshes) and MakeDefaultScene (procedural meshes).
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/scene.h"
#include "m2s/common/types.h"

namespace m2s::internal {

class SceneBuilder {
 public:
  // The id of p: the id of an earlier identical position, else the next id. -0 equals +0.
  VertexId Add(const Eigen::Vector3f& p) {
    const Key key{Bits(p.x()), Bits(p.y()), Bits(p.z())};
    const auto [it, inserted] = ids_.try_emplace(key, static_cast<VertexId>(positions_.size()));
    if (inserted) positions_.push_back(Eigen::Vector3f(Clean(p.x()), Clean(p.y()), Clean(p.z())));
    return it->second;
  }
  // Keeps the triangle unless two corners are the same vertex.
  void AddTriangle(VertexId a, VertexId b, VertexId c) {
    if (a == b || b == c || a == c) return;
    triangles_.insert(triangles_.end(), {a, b, c});
  }
  size_t num_vertices() const { return positions_.size(); }
  size_t num_triangles() const { return triangles_.size() / 3; }

  // Renumbers ids into LoadScene order: first use in triangle order, then unused vertices.
  void Canonicalize() {
    constexpr VertexId kUnset = ~VertexId{0};
    std::vector<VertexId> new_id(positions_.size(), kUnset);
    VertexId next = 0;
    for (uint32_t& index : triangles_) {
      if (new_id[index] == kUnset) new_id[index] = next++;
      index = new_id[index];
    }
    for (VertexId& id : new_id) {
      if (id == kUnset) id = next++;
    }
    std::vector<Eigen::Vector3f> positions(positions_.size());
    for (size_t i = 0; i < positions_.size(); ++i) positions[new_id[i]] = positions_[i];
    positions_ = std::move(positions);
    ids_.clear();
  }

  Scene Build(std::string name) && {
    Scene scene;
    scene.name = std::move(name);
    scene.positions = std::move(positions_);
    scene.triangles = std::move(triangles_);
    return scene;
  }

 private:
  struct Key {
    uint32_t x, y, z;
    bool operator==(const Key& o) const { return x == o.x && y == o.y && z == o.z; }
  };
  struct KeyHash {
    size_t operator()(const Key& k) const {
      uint64_t h = 1469598103934665603ull;
      for (uint32_t v : {k.x, k.y, k.z}) h = (h ^ v) * 1099511628211ull;
      return static_cast<size_t>(h ^ (h >> 29));
    }
  };
  static float Clean(float v) { return v == 0.f ? 0.f : v; }
  static uint32_t Bits(float v) {
    const float c = Clean(v);
    uint32_t b;
    std::memcpy(&b, &c, sizeof(b));
    return b;
  }

  std::unordered_map<Key, VertexId, KeyHash> ids_;
  std::vector<Eigen::Vector3f> positions_;
  std::vector<uint32_t> triangles_;
};

}  // namespace m2s::internal
