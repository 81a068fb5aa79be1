// Keyframe culling: which keyframes around a newly mapped one are redundant (their points are
// seen well enough by others), which one a bounded map gives up, and the link that keeps a
// culled keyframe's trajectory entries resolvable. The selection is pure (read-only MapData in,
// plain values out); CullKeyframe applies one decision.
//
// Culling is sequential: each removal changes the observers the next decision counts, so the
// caller asks IsRedundant of one candidate at a time on the map as it is now.
//
// Thread-safety: call under Map::Read (selection) or Map::Write (CullKeyframe).
//
//   map.Write([&](MapData& m) {
//     if (IsYoungMap(m)) return;
//     for (KeyframeId id : CullingCandidates(m, newest, options))
//       if (IsRedundant(m, id, options)) CullKeyframe(&m, id);
//   });
#pragma once

#include <optional>
#include <vector>

#include "m2s/common/types.h"
#include "m2s/slam/options.h"
#include "map/map_data.h"

namespace m2s::slam {

// How many map points keyframe `id` observes, and how many of them at least
// `min_other_observers` other keyframes observe too.
struct Redundancy {
  int observed = 0;
  int redundant = 0;
};
Redundancy MeasureRedundancy(const MapData& m, KeyframeId id, int min_other_observers);

// Redundant: it observes points, and at least options.keyframe_redundancy of them are seen by
// options.keyframe_redundancy_observers other keyframes.
bool IsRedundant(const MapData& m, KeyframeId id, const MapperOptions& options);

// The keyframes culling examines after `newest` was mapped: its local_ba_window best covisible
// neighbours (CovisibleNeighbours), but neither the first keyframe nor `newest`. (A young map,
// IsYoungMap, is not culled at all.)
std::vector<KeyframeId> CullingCandidates(const MapData& m, KeyframeId newest,
                                          const MapperOptions& options);

// Beyond options.max_keyframes, the oldest keyframe but the first; nullopt within the bound or
// when that keyframe is `newest`.
std::optional<KeyframeId> OldestBeyondBound(const MapData& m, KeyframeId newest,
                                            const MapperOptions& options);

// Where a culled keyframe stays, relative to a survivor: the nearest keyframe sharing
// kMinCovisiblePoints points (the rigid link's lever arm, and so the error a later change of
// scale around it makes, is smallest); else the most covisible one; else the previous keyframe
// by id (the next one for the first).
KeyframeLink CullLink(const MapData& m, KeyframeId id);

// Removes keyframe `id` (linked by CullLink) and the points it leaves with fewer than two
// observers.
void CullKeyframe(MapData* m, KeyframeId id);

}  // namespace m2s::slam
