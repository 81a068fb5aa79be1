// Two-view and multi-view triangulation with the checks every new map point must pass.
//
// Poses are camera_from_world (the form projection wants). All functions are pure.
//
//   auto p = TriangulateChecked(camera, checks, {cfw_a, cfw_b}, {uv_a, uv_b});
//   if (p) map.AddPoint(id, *p, ...);
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/slam/options.h"

namespace m2s::slam {

struct TriangulationChecks {
  double min_parallax_deg = 1.0;      // angle between the two most separated rays
  double max_reprojection_px = 2.45;  // sqrt(5.991) at sigma 1 px
  double min_depth = 1e-6;            // cheirality (in front of every camera)
};

// The checks of a new map point under `model`: its parallax bound, and the 2-dof chi-square
// 95 % bound on the reprojection error.
TriangulationChecks PointChecks(const MeasurementModel& model);

// Linear (DLT) triangulation in the world frame from >= 2 views; nullopt if degenerate.
std::optional<Eigen::Vector3d> TriangulateDlt(const Camera& camera,
                                              const std::vector<Pose3>& camera_from_world,
                                              const std::vector<Eigen::Vector2d>& uv);

// DLT followed by the checks: depth > min_depth in every view, reprojection error under the
// bound in every view, and parallax (largest angle between rays) >= min_parallax_deg.
std::optional<Eigen::Vector3d> TriangulateChecked(const Camera& camera,
                                                  const TriangulationChecks& checks,
                                                  const std::vector<Pose3>& camera_from_world,
                                                  const std::vector<Eigen::Vector2d>& uv);

// Angle in degrees at `point` between the rays to two camera centres.
double ParallaxDeg(const Eigen::Vector3d& point, const Eigen::Vector3d& center_a,
                   const Eigen::Vector3d& center_b);

// Largest parallax in degrees at `point` over every pair of camera centres (0 for < 2).
// O(n^2): for a point's many observers use HasParallax.
double MaxParallaxDeg(const Eigen::Vector3d& point, const std::vector<Eigen::Vector3d>& centers);

// Whether some pair of centres sees `point` with at least `min_deg` of parallax, in O(n): the
// largest angle from the first ray to any other is within a factor 2 of the largest pairwise
// one (triangle inequality on the sphere); when it is between min/2 and min, the exact O(n^2)
// answer decides.
bool HasParallax(const Eigen::Vector3d& point, const std::vector<Eigen::Vector3d>& centers,
                 double min_deg);

// Squared reprojection error in pixels; +inf when the point is behind the camera.
double ReprojectionErrorSq(const Camera& camera, const Pose3& camera_from_world,
                           const Eigen::Vector3d& point_world, const Eigen::Vector2d& uv);

}  // namespace m2s::slam
