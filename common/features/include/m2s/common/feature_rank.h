// A fixed ranking of vertex ids, for bounded, id-stable subsets of a frame's features.
//
// A 640x480 view of a dense mesh sees ~10^4 vertices; SLAM needs ~10^3 (exact association, no
// outliers to outvote). Each vertex id gets a fixed pseudo-random rank (a bijective 64-bit mix
// of the id, so ranks do not follow the mesh's vertex order); a frame keeps the `budget`
// features of lowest rank. The subset is therefore the same in every view (a vertex kept in
// one view is kept in every view where fewer than `budget` visible vertices outrank it), spread
// uniformly over the image, and independent of the features' order. The client may send only
// that subset and the server selects the same one (slam::Options::feature_budget).
//
//   const uint64_t threshold = FeatureRankThreshold(ids, 2000);
//   keep feature i  <=>  FeatureRank(ids[i]) <= threshold
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "m2s/common/types.h"

namespace m2s {

// The rank of a vertex id (lower is kept first). Distinct ids have distinct ranks.
uint64_t FeatureRank(VertexId id);

// The highest rank kept when the `budget` lowest-ranked of `ids` (distinct) are kept:
// exactly min(budget, ids.size()) ids have FeatureRank(id) <= the result. UINT64_MAX (keep
// everything) when budget <= 0 or ids.size() <= budget.
uint64_t FeatureRankThreshold(std::span<const VertexId> ids, int budget);

// Keeps the `budget` lowest-ranked features, in their order (all when budget <= 0); the ids
// must be distinct. Returns the number removed.
size_t KeepLowestRanked(int budget, std::vector<VertexFeature>* features);

}  // namespace m2s
