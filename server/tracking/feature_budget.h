// A bounded, id-stable subset of a frame's features for SLAM.
//
// A 640x480 view of a dense mesh sees ~10^4 vertices; tracking and mapping need ~10^3 points
// (exact association, no outliers to outvote). Each vertex id gets a fixed pseudo-random rank
// (a 64-bit mix of the id, so ranks do not follow the mesh's vertex order); a frame keeps the
// `budget` features of lowest rank. The selection is therefore consistent between frames and
// keyframes (a vertex kept in one view is kept in every view where at most `budget` visible
// vertices outrank it), spread uniformly over the image, and independent of feature order.
//
//   SortedFeatures features = ...;          // validated, sorted by id
//   ApplyFeatureBudget(2000, &features);    // still sorted by id, at most 2000 left
#pragma once

#include <cstdint>

#include "tracking/frame_validation.h"

namespace m2s::slam {

// The rank of a vertex id (lower is kept first): a bijective 64-bit mix of the id.
uint64_t FeatureRank(VertexId id);

// Keeps the `budget` lowest-ranked features (all of them when budget <= 0 or when there are
// not more than `budget`); the order by id is preserved. Returns the number removed.
size_t ApplyFeatureBudget(int budget, SortedFeatures* features);

}  // namespace m2s::slam
