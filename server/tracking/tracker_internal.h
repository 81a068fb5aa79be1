// Tracker internals shared by tracker.cc and tracker_recovery.cc.
#pragma once

#include <cmath>

#include "m2s/common/numeric.h"
#include "m2s/slam/options.h"
#include "optimization/problems.h"

namespace m2s::slam::tracker_internal {

// A view with fewer associated points than TrackerOptions::min_inliers gets a pose when this
// fraction of them are inliers, and at least kMinTrackedInliers for a pose tracked from the
// motion prior or relocalised by PnP (so a view that empties for a moment, a hand-held camera
// turned to a bare wall, keeps its track instead of starting a new map), at least
// kMinPoseInliers for a rotation-only pose and for the recent points alone to overrule
// dormant ones.
constexpr double kSparseViewInlierFraction = 0.75;
constexpr int kMinPoseInliers = 12;
constexpr int kMinTrackedInliers = 8;

// Pose-only refinement options for the measurement model: Huber at the inlier bound.
inline PoseOnlyOptions MakePoseOptions(const MeasurementModel& model) {
  PoseOnlyOptions p;
  p.pixel_sigma = model.pixel_sigma;
  p.huber_delta_px = std::sqrt(kChi2TwoDof95) * model.pixel_sigma;
  return p;
}

}  // namespace m2s::slam::tracker_internal
