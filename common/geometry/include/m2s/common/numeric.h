// Small numeric helpers used across the tree: evenly spaced subsamples, medians and
// percentiles, the chi-square bounds of the outlier tests, degrees and radians, and a look-at
// camera pose.
//
// Pure functions of their arguments; thread-safe.
//
//   for (size_t i : EvenlySpacedIndices(ids.size(), 600)) used.push_back(ids[i]);
//   double p95 = Percentile(latencies_ms, 0.95);
//   double depth = MedianDepth(camera_from_world, points_world);
#pragma once

#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/geometry.h"

namespace m2s {

// Chi-square quantiles: the outlier bounds on a squared residual in units of sigma^2.
inline constexpr double kChi2OneDof95 = 3.841;    // 95 %, 1 dof (distance to an epipolar line)
inline constexpr double kChi2TwoDof95 = 5.991;    // 95 %, 2 dof (reprojection, transfer error)
inline constexpr double kChi2ThreeDof95 = 7.815;  // 95 %, 3 dof (a 3-D position)
inline constexpr double kChi2FiveDof999 = 20.52;  // 99.9 %, 5 dof (a two-view motion)
inline constexpr double kChi2SixDof999 = 22.46;   // 99.9 %, 6 dof (a pose)

// Angles: degrees to radians and back.
inline constexpr double DegToRad(double deg) { return deg * (3.14159265358979323846 / 180.0); }
inline constexpr double RadToDeg(double rad) { return rad * (180.0 / 3.14159265358979323846); }

// How EvenlySpacedIndices turns a spaced position into an index.
enum class IndexRounding { kDown, kUp };

// An evenly spaced subsample of [0, n), ascending: every index when max_count is 0 or n <=
// max_count; otherwise the positions 0, s, 2s, ... (s = n / max_count, accumulated by repeated
// addition) below n, rounded down or up. Accumulation can stop just short of n, so the result
// may hold max_count + 1 indices.
std::vector<size_t> EvenlySpacedIndices(size_t n, size_t max_count,
                                        IndexRounding rounding = IndexRounding::kDown);

// The element of rank n / 2 (for an even count, the upper of the two middle values); 0 when
// empty.
double Median(std::vector<double> values);

// Median of the points' depths (z in the camera frame); 0 when there are none.
double MedianDepth(const Pose3& camera_from_world,
                   const std::vector<Eigen::Vector3d>& points_world);

// Which value Percentile reports for q in [0, 1], over the n values sorted ascending (v).
enum class PercentileMethod {
  kInterpolated,  // numpy's default: v[floor(p)] + (v[ceil(p)] - v[floor(p)]) * frac(p), p = q
                  // (n-1)
  kRoundedRank,   // v[round(q (n - 1))], halves rounded up
  kFlooredRank,   // v[min(n - 1, floor(q n))]
};

// The q-quantile of `values` (0 when empty).
double Percentile(std::vector<double> values, double q,
                  PercentileMethod method = PercentileMethod::kInterpolated);
float Percentile(std::vector<float> values, double q,
                 PercentileMethod method = PercentileMethod::kInterpolated);

// world_from_camera of a camera at `eye` looking at `target` (OpenCV axes: x right, y down,
// z forward), with `up` pointing up in the image (any perpendicular when it is parallel to
// the viewing direction).
Pose3 LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
             const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

}  // namespace m2s
