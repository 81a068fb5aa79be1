// How well two views determine their relative motion: the standard deviations of the rotation
// and of the translation's direction for a given image noise, from the points' geometry alone
// (independent of residuals, so exact and noisy data are judged alike). The initialiser refuses
// motions that are not determined (docs/design/two_view_initialisation.md).
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"

namespace m2s::slam {

// Standard deviations (radians) of the relative motion of two views: the rotation, and the
// direction of the translation (its length is the monocular scale), for image noise
// `pixel_sigma` on the points' projections. The inverse of the motion's Fisher information with
// the points marginalised (Schur complement); a motion the views leave unconstrained gives
// infinities. nullopt without translation or with fewer than 3 points.
struct MotionUncertainty {
  double rotation_rad = 0.0;
  double direction_rad = 0.0;
};
std::optional<MotionUncertainty> TwoViewMotionUncertainty(
    const Camera& camera, double pixel_sigma, const Pose3& camera1_from_camera0,
    const std::vector<Eigen::Vector3d>& points_camera0);

}  // namespace m2s::slam
