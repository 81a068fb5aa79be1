// The SLAM feature budget: a frame's validated features cut to the `budget` whose vertex ids
// rank lowest (m2s/common/feature_rank.h explains the ranking: id-stable between views, spread
// over the image). A client that sent only that subset loses nothing.
//
//   SortedFeatures features = ...;          // validated, sorted by id
//   ApplyFeatureBudget(2000, &features);    // still sorted by id, at most 2000 left
#pragma once

#include "tracking/frame_validation.h"

namespace m2s::slam {

// Keeps the `budget` lowest-ranked features (all of them when budget <= 0 or when there are
// not more than `budget`); the order by id is preserved. Returns the number removed.
size_t ApplyFeatureBudget(int budget, SortedFeatures* features);

}  // namespace m2s::slam
