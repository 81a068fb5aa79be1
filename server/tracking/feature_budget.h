// The SLAM feature budget: a frame's validated features cut to `budget` by the balanced
// selection (m2s/common/feature_rank.h): spread over an image grid so that dense objects do
// not starve sparse walls, id-stable between views, and nested, so a client that sent the
// balanced selection of at least `budget` features loses nothing.
//
//   const FeatureGrid grid = FeatureGrid::ForImage(camera.width, camera.height);
//   SortedFeatures features = ...;                // validated, sorted by id
//   ApplyFeatureBudget(2000, grid, &features);    // still sorted by id, at most 2000 left
#pragma once

#include "m2s/common/feature_rank.h"
#include "tracking/frame_validation.h"

namespace m2s::slam {

// Keeps the balanced selection of `budget` features (all of them when budget <= 0 or when
// there are not more than `budget`); the order by id is preserved. Returns the number removed.
size_t ApplyFeatureBudget(int budget, const FeatureGrid& grid, SortedFeatures* features);

}  // namespace m2s::slam
