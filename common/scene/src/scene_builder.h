// Internal: builds a Scene from positions, merging exactly equal positions into one id.
// Used by LoadScene (assimp meshes) and MakeDefaultScene (procedural meshes).
// The position -> id index is an open-addressing table of ids (4 bytes a slot, at most half
// full) that compares against the stored positions: a 10M-vertex scan takes about a second,
// where a node-based hash map spends tens of seconds in allocation and rehashing.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
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
    const Eigen::Vector3f clean(Clean(p.x()), Clean(p.y()), Clean(p.z()));
    if (2 * (positions_.size() + 1) > slots_.size()) Grow();
    const size_t mask = slots_.size() - 1;
    for (size_t slot = Hash(clean) & mask;; slot = (slot + 1) & mask) {
      const VertexId id = slots_[slot];
      if (id == kEmpty) {
        slots_[slot] = static_cast<VertexId>(positions_.size());
        positions_.push_back(clean);
        return slots_[slot];
      }
      if (std::memcmp(positions_[id].data(), clean.data(), sizeof(clean)) == 0) return id;
    }
  }
  // Room for `n` distinct positions without regrowing (a hint; Add grows as needed).
  void Reserve(size_t n) {
    positions_.reserve(n);
    while (slots_.size() < 2 * n) Grow();
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
    slots_.clear();
    slots_.shrink_to_fit();
  }

  Scene Build(std::string name) && {
    Scene scene;
    scene.name = std::move(name);
    scene.positions = std::move(positions_);
    scene.triangles = std::move(triangles_);
    return scene;
  }

 private:
  static constexpr VertexId kEmpty = ~VertexId{0};

  static float Clean(float v) { return v == 0.f ? 0.f : v; }  // -0 -> +0
  static size_t Hash(const Eigen::Vector3f& p) {
    uint32_t b[3];
    std::memcpy(b, p.data(), sizeof(b));
    uint64_t h = (uint64_t{b[0]} << 32 | b[1]) * 0x9E3779B97F4A7C15ull;
    h = (h ^ (h >> 31) ^ b[2]) * 0xBF58476D1CE4E5B9ull;
    return static_cast<size_t>(h ^ (h >> 29));
  }
  // Doubles the table (at least 1024 slots) and re-inserts every stored position.
  void Grow() {
    std::vector<VertexId> slots(std::max<size_t>(1024, 2 * slots_.size()), kEmpty);
    const size_t mask = slots.size() - 1;
    for (size_t id = 0; id < positions_.size(); ++id) {
      size_t slot = Hash(positions_[id]) & mask;
      while (slots[slot] != kEmpty) slot = (slot + 1) & mask;
      slots[slot] = static_cast<VertexId>(id);
    }
    slots_ = std::move(slots);
  }

  std::vector<VertexId> slots_;  // power-of-two size, kEmpty or an index into positions_
  std::vector<Eigen::Vector3f> positions_;
  std::vector<uint32_t> triangles_;
};

}  // namespace m2s::internal
