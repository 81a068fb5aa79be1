// Closed-form alignment of matched 3-D point sets (Umeyama 1991, via Eigen::umeyama).
//
//   std::optional<Sim3> target_from_source = AlignPoints(source, target, /*with_scale=*/true);
//   // target[i] ~= (*target_from_source) * source[i]
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/geometry.h"

namespace m2s {

// Least-squares similarity (with_scale) or rigid transform mapping source onto target.
// Returns nullopt with fewer than 3 pairs, mismatched sizes, non-finite input or a degenerate
// (collinear) configuration.
std::optional<Sim3> AlignPoints(const std::vector<Eigen::Vector3d>& source,
                                const std::vector<Eigen::Vector3d>& target, bool with_scale);

}  // namespace m2s
