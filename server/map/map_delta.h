// Coalescing map deltas: several consecutive deltas as one, for a receiver that takes them less
// often than they are made (each agent of a map group takes the group map's deltas at its own
// pace).
#pragma once

#include "m2s/slam/system.h"

namespace m2s::slam {

// Appends `next` (whose base_revision is at most accumulated->revision, or a full delta) to
// `accumulated`, so that applying the result equals applying both in order: a later upsert
// replaces an earlier one, a removal cancels an earlier upsert (a full delta simply loses the
// item), an upsert cancels an earlier removal. Items stay sorted by id.
void AppendDelta(MapDelta* accumulated, const MapDelta& next);

}  // namespace m2s::slam
