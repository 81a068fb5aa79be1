#include "m2s/slam/options.h"

#include <cmath>

#include "m2s/slam/system.h"

namespace m2s::slam {
namespace {

// An error whose message names the struct.
Status Fail(const char* prefix, const char* message) {
  return Status::Error(std::string(prefix) + message);
}

// NaN is not positive.
bool Positive(double value) { return value > 0.0; }

}  // namespace

const char* ToString(TrackingState state) {
  switch (state) {
    case TrackingState::kNotInitialized:
      return "not_initialized";
    case TrackingState::kOk:
      return "ok";
    case TrackingState::kLost:
      return "lost";
    case TrackingState::kRelocalized:
      return "relocalized";
    case TrackingState::kRejected:
      return "rejected";
  }
  return "unknown";
}

Status InitializerOptions::Check() const {
  constexpr char kName[] = "InitializerOptions: ";
  if (min_points < 8) return Fail(kName, "min_points must be at least 8");
  if (!Positive(min_parallax_deg)) return Fail(kName, "min_parallax_deg must be positive");
  if (max_reference_age < 2) return Fail(kName, "max_reference_age must be at least 2");
  if (!Positive(max_rotation_sigma_deg)) {
    return Fail(kName, "max_rotation_sigma_deg must be positive");
  }
  if (!Positive(max_direction_sigma_deg)) {
    return Fail(kName, "max_direction_sigma_deg must be positive");
  }
  if (!std::isfinite(more_views_after_s)) {
    return Fail(kName, "more_views_after_s must be finite");
  }
  return Status::Ok();
}

Status TrackerOptions::Check() const {
  constexpr char kName[] = "TrackerOptions: ";
  if (max_points < 0) return Fail(kName, "max_points must be >= 0 (0: all)");
  if (min_inliers < 6) return Fail(kName, "min_inliers must be at least 6");
  if (!(keyframe_tracked_ratio > 0.0 && keyframe_tracked_ratio <= 1.0)) {
    return Fail(kName, "keyframe_tracked_ratio must be in (0, 1]");
  }
  if (keyframe_min_new_points < 1) {
    return Fail(kName, "keyframe_min_new_points must be positive");
  }
  if (!Positive(keyframe_baseline_ratio)) {
    return Fail(kName, "keyframe_baseline_ratio must be positive");
  }
  if (!Positive(keyframe_max_interval_s)) {
    return Fail(kName, "keyframe_max_interval_s must be positive");
  }
  if (min_constrained_points < 0) return Fail(kName, "min_constrained_points must be >= 0");
  return Status::Ok();
}

Status MapperOptions::Check() const {
  constexpr char kName[] = "MapperOptions: ";
  if (local_ba_window < 2) return Fail(kName, "local_ba_window must be at least 2");
  if (local_ba_max_points < 0) return Fail(kName, "local_ba_max_points must be >= 0");
  if (num_ba_threads <= 0) return Fail(kName, "num_ba_threads must be positive");
  if (!(keyframe_redundancy > 0.0 && keyframe_redundancy <= 1.0)) {
    return Fail(kName, "keyframe_redundancy must be in (0, 1]");
  }
  if (keyframe_redundancy_observers < 1) {
    return Fail(kName, "keyframe_redundancy_observers must be at least 1");
  }
  if (max_keyframes < 2) return Fail(kName, "max_keyframes must be at least 2");
  // +inf shows every point; NaN would hide them all.
  if (!Positive(max_point_uncertainty)) {
    return Fail(kName, "max_point_uncertainty must be positive");
  }
  return Status::Ok();
}

Status DriftOptions::Check() const {
  constexpr char kName[] = "DriftOptions: ";
  if (min_points < 6) return Fail(kName, "min_points must be at least 6");
  if (min_keyframe_gap < 2) return Fail(kName, "min_keyframe_gap must be at least 2");
  if (!Positive(min_error)) return Fail(kName, "min_error must be positive");
  return Status::Ok();
}

Status MultiMapOptions::Check() const {
  constexpr char kName[] = "MultiMapOptions: ";
  if (!(new_map_after_lost_s >= 0.0) || !std::isfinite(new_map_after_lost_s)) {
    return Fail(kName, "new_map_after_lost_s must be finite and >= 0");
  }
  if (min_features < 0) return Fail(kName, "min_features must be >= 0");
  if (merge_min_shared_points < 3) return Fail(kName, "merge_min_shared_points must be >= 3");
  if (!(merge_min_inlier_fraction > 0.0 && merge_min_inlier_fraction <= 1.0)) {
    return Fail(kName, "merge_min_inlier_fraction must be in (0, 1]");
  }
  return Status::Ok();
}

Status Options::Check() const {
  constexpr char kName[] = "Options: ";
  if (Status s = camera.Check(); !s) return s;
  if (!Positive(pixel_sigma) || !std::isfinite(pixel_sigma)) {
    return Fail(kName, "pixel_sigma must be positive and finite");
  }
  if (!Positive(min_triangulation_parallax_deg)) {
    return Fail(kName, "min_triangulation_parallax_deg must be positive");
  }
  if (max_features_per_frame <= 0) {
    return Fail(kName, "max_features_per_frame must be positive");
  }
  if (!(image_margin_px >= 0.0)) return Fail(kName, "image_margin_px must be >= 0");
  if (feature_budget < 0) return Fail(kName, "feature_budget must be >= 0 (0: all features)");
  if (feature_budget > 0 && feature_budget < initializer.min_points) {
    return Fail(kName, "feature_budget must be at least initializer.min_points");
  }
  if (frame_observations_kept < 0) return Fail(kName, "frame_observations_kept must be >= 0");
  if (!(refine_acceleration_sigma >= 0.0) || !std::isfinite(refine_acceleration_sigma))
    return Fail(kName, "refine_acceleration_sigma must be finite and >= 0");
  if (input_queue_capacity <= 0) return Fail(kName, "input_queue_capacity must be positive");
  if (mapping_queue_capacity < 1) {
    return Fail(kName, "mapping_queue_capacity must be positive");
  }
  if (mapping_nice < 0 || mapping_nice > 19) {
    return Fail(kName, "mapping_nice must be in [0, 19]");
  }
  for (const Status& stage :
       {initializer.Check(), tracker.Check(), mapper.Check(), drift.Check(), multi_map.Check()}) {
    if (!stage) return stage;
  }
  return Status::Ok();
}

}  // namespace m2s::slam
