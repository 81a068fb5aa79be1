// How well views determine camera motion, from the points' geometry alone (independent of
// residuals, so exact and noisy data are judged alike): the standard deviations of two views'
// relative rotation and translation direction (the initialiser refuses motions that are not
// determined, docs/design/two_view_initialisation.md), and of a camera centre solved from
// known points (the tracker loses a frame whose centre its points leave undetermined).
#pragma once

#include <optional>
#include <string>
#include <utility>
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
// "rotation sigma R deg, direction sigma D deg", for the logs and refusal messages.
std::string Describe(const MotionUncertainty& u);

std::optional<MotionUncertainty> TwoViewMotionUncertainty(
    const Camera& camera, double pixel_sigma, const Pose3& camera1_from_camera0,
    const std::vector<Eigen::Vector3d>& points_camera0);

// The same standard deviations for the motion of view 1 relative to view 0 when more views
// see the points: `views_from_camera0[0]` (fixed) and `[1]` are the two views, the others'
// poses unknown too (nuisance, like the points); `observations` lists which view sees which
// point, (view index, point index). Points seen by fewer than two views add nothing. nullopt
// without translation in view 1; infinities where the views leave the motion unconstrained.
std::optional<MotionUncertainty> MultiViewMotionUncertainty(
    const Camera& camera, double pixel_sigma, const std::vector<Pose3>& views_from_camera0,
    const std::vector<Eigen::Vector3d>& points_camera0,
    const std::vector<std::pair<int, int>>& observations);

// Covariance (world units squared) of a camera's centre solved from known points, its rotation
// unknown too, for image noise `pixel_sigma` on their projections: the position block of the
// inverse of the pose's Fisher information. nullopt when the points leave the pose undetermined
// (fewer than 3 in front of the camera, or all on one ray). With `point_sigmas` (world units,
// one per point, or empty), each point's own position is that uncertain in every direction: its
// projection's noise grows by the deviation that projects to (a map point triangulated over a
// small baseline fixes a pose less than an exact one).
std::optional<Eigen::Matrix3d> PoseCentreCovariance(
    const Camera& camera, double pixel_sigma, const Pose3& camera_from_world,
    const std::vector<Eigen::Vector3d>& points_world, const std::vector<double>& point_sigmas = {});

// A view's centre uncertainty from the points `use` indexes in `points_world`, on an even
// subset of at most `max_points` of them (dense views), its information scaled up to the whole
// (as if its noise were that much smaller): the covariance, its largest standard deviation,
// and the subset's median depth. nullopt when the points leave the pose undetermined.
struct ViewCentreUncertainty {
  Eigen::Matrix3d covariance;
  double sigma = 0.0;
  double median_depth = 0.0;
};
std::optional<ViewCentreUncertainty> CentreUncertaintyOfView(
    const Camera& camera, double pixel_sigma, const Pose3& camera_from_world,
    const std::vector<Eigen::Vector3d>& points_world, const std::vector<size_t>& use,
    int max_points);

// Largest standard deviation (world units) of that centre (the square root of the covariance's
// largest eigenvalue); infinity where the covariance is nullopt.
double PoseCentreSigma(const Camera& camera, double pixel_sigma, const Pose3& camera_from_world,
                       const std::vector<Eigen::Vector3d>& points_world,
                       const std::vector<double>& point_sigmas = {});

}  // namespace m2s::slam
