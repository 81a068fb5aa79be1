// Small value types shared by every layer.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace m2s {

using VertexId = uint32_t;    // dense from 0 in scene load order (see scene.h)
using KeyframeId = uint32_t;  // assigned by the map, never reused within a session
using SessionId = int64_t;

// What the client sends for each visible vertex: its id (the descriptor) and its sub-pixel
// image position.
struct VertexFeature {
  VertexId id = 0;
  Eigen::Vector2f uv = Eigen::Vector2f::Zero();
};

// A projected vertex as the projectors produce it: depth is the camera-frame Z in metres.
struct ProjectedVertex {
  VertexId id = 0;
  float u = 0.f;
  float v = 0.f;
  float depth = 0.f;
};

}  // namespace m2s
