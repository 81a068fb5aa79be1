// What a bundle adjustment of the map optimises, chosen from the map's contents alone: the
// local window (the newest keyframe and its covisible neighbours, the points they observe, the
// other observers of those points held fixed) or the whole map; and the BaProblem built from a
// window. Pure functions of read-only MapData, so they are tested on small maps with known
// covisibility.
//
// Thread-safety: call under Map::Read (they only read the MapData they are given).
//
//   map.Read([&](const MapData& m) {
//     window = SelectLocalBaWindow(m, newest_keyframe, options);
//     problem = MakeBaProblem(m, window);
//   });
#pragma once

#include <vector>

#include "m2s/common/types.h"
#include "m2s/slam/options.h"
#include "map/map_data.h"
#include "optimization/problems.h"

namespace m2s::slam {

// Covisibility needed to count as a neighbour (local window, culling, culling links).
inline constexpr int kMinCovisiblePoints = 15;
// Fixed keyframes in a local BA: at most this multiple of the window (most shared first).
inline constexpr int kFixedKeyframesPerWindow = 2;
// Maps with at most this many keyframes are young: refined by a global BA per keyframe instead
// of a local one, and never culled (their scale still settles).
inline constexpr int kYoungMapKeyframes = 10;
inline bool IsYoungMap(const MapData& m) {
  return m.keyframes().size() <= static_cast<size_t>(kYoungMapKeyframes);
}

// A bundle adjustment's selection, in the order of the problem it makes.
struct BaWindow {
  struct Member {
    KeyframeId id = 0;
    bool fixed = false;
  };
  std::vector<Member> keyframes;
  std::vector<VertexId> points;  // optimised, ascending
  // Points of the window left out by the point cap (re-triangulated after the BA), ascending.
  std::vector<VertexId> rest;
};

// The first `max_count` keyframes sharing at least kMinCovisiblePoints points with `id`, most
// shared first (MapData::Covisible's order).
std::vector<KeyframeId> CovisibleNeighbours(const MapData& m, KeyframeId id, int max_count);

// The local window of `newest`: it and its local_ba_window - 1 best covisible neighbours,
// optimised (ascending ids); then the other observers of their points, at most
// kFixedKeyframesPerWindow * local_ba_window of them (most shared points first), fixed
// (ascending ids). Without a fixed keyframe the oldest optimised one is fixed (the gauge).
// The points: every map point a window keyframe observes, at most local_ba_max_points of them
// (evenly spaced over the ascending ids; 0: all), the others in `rest`.
BaWindow SelectLocalBaWindow(const MapData& m, KeyframeId newest, const MapperOptions& options);

// Every keyframe (ascending; the first one fixed) and every point, at most `max_points` of
// them (evenly spaced over the ascending ids; 0: all), the others in `rest`.
BaWindow SelectGlobalBaWindow(const MapData& m, int max_points);

// The problem of a window: its keyframes (camera_from_world) in order, its points, and every
// observation of a point by a keyframe of the window.
BaProblem MakeBaProblem(const MapData& m, const BaWindow& window);

}  // namespace m2s::slam
