// Tracker internals shared by tracker.cc and tracker_recovery.cc.
#pragma once

#include <cmath>
#include <optional>
#include <vector>

#include "m2s/common/numeric.h"
#include "m2s/slam/options.h"
#include "optimization/problems.h"

namespace m2s::slam::tracker_internal {

// A view with fewer associated points than TrackerOptions::min_inliers gets a pose when this
// fraction of them are inliers and there are at least:
//  - kMinTrackedInliers for a pose tracked from the motion prior or relocalised by PnP (so a
//    view that empties for a moment, a hand-held camera turned to a bare wall, keeps its track
//    instead of starting a new map);
//  - kMinRotationOnlyInliers for a rotation-only pose (bearings to the reference keyframe);
//    as many map points in view must agree with it, when there are that many to judge;
//  - kMinOverrulingPoints recent points for them alone to overrule dormant ones.
constexpr double kSparseViewInlierFraction = 0.75;
constexpr int kMinTrackedInliers = 8;
constexpr int kMinRotationOnlyInliers = 12;
constexpr int kMinOverrulingPoints = 12;
// A pose's centre must be known to this standard deviation (fraction of the median depth of its
// inliers), or the frame is lost: a few points bunched at the edge of a view fit poses
// decimetres apart within the noise.
constexpr double kMaxCentreSigmaFraction = 0.05;

// camera_from_world from world points and their pixels by PnP + RANSAC (OpenCV's AP3P on at
// most 500 of them, evenly spread; tracker_recovery.cc), no start needed. nullopt when RANSAC
// finds no pose or OpenCV rejects the input (logged).
std::optional<Pose3> PnpRansac(const Camera& camera, double threshold_px,
                               const std::vector<Eigen::Vector3d>& points,
                               const std::vector<Eigen::Vector2d>& uvs, std::vector<int>* inliers);

// Pose-only refinement options for the measurement model: Huber at the inlier bound.
inline PoseOnlyOptions MakePoseOptions(const MeasurementModel& model) {
  PoseOnlyOptions p;
  p.pixel_sigma = model.pixel_sigma;
  p.huber_delta_px = std::sqrt(kChi2TwoDof95) * model.pixel_sigma;
  return p;
}

}  // namespace m2s::slam::tracker_internal
