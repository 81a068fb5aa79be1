#include "m2s/slam/system.h"

#include <cmath>

namespace m2s::slam {

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

bool Options::Check(std::string* why) const {
  auto fail = [why](const char* msg) {
    if (why) *why = msg;
    return false;
  };
  if (!camera.Check(why)) return false;
  if (max_features_per_frame <= 0) return fail("max_features_per_frame must be positive");
  if (feature_budget < 0) return fail("feature_budget must be >= 0 (0: all features)");
  if (feature_budget > 0 && feature_budget < init_min_points) {
    return fail("feature_budget must be at least init_min_points");
  }
  if (mapping_nice < 0 || mapping_nice > 19) return fail("mapping_nice must be in [0, 19]");
  if (input_queue_capacity <= 0) return fail("input_queue_capacity must be positive");
  if (num_ba_threads <= 0) return fail("num_ba_threads must be positive");
  if (max_keyframes < 2) return fail("max_keyframes must be at least 2");
  if (!(pixel_sigma > 0.0) || !std::isfinite(pixel_sigma))
    return fail("pixel_sigma must be positive");
  if (!(image_margin_px >= 0.0)) return fail("image_margin_px must be >= 0");
  if (init_min_points < 8) return fail("init_min_points must be at least 8");
  if (!(init_min_parallax_deg > 0.0)) return fail("init_min_parallax_deg must be positive");
  if (init_max_reference_age < 2) return fail("init_max_reference_age must be at least 2");
  if (min_tracked_points < 6) return fail("min_tracked_points must be at least 6");
  if (!(keyframe_tracked_ratio > 0.0 && keyframe_tracked_ratio <= 1.0)) {
    return fail("keyframe_tracked_ratio must be in (0, 1]");
  }
  if (keyframe_min_new_points < 1) return fail("keyframe_min_new_points must be positive");
  if (!(keyframe_baseline_ratio > 0.0)) return fail("keyframe_baseline_ratio must be positive");
  if (!(keyframe_max_interval_s > 0.0)) return fail("keyframe_max_interval_s must be positive");
  if (max_tracking_points < 0) return fail("max_tracking_points must be >= 0");
  if (local_ba_max_points < 0) return fail("local_ba_max_points must be >= 0");
  if (local_ba_window < 2) return fail("local_ba_window must be at least 2");
  if (mapping_queue_capacity < 1) return fail("mapping_queue_capacity must be positive");
  if (!(min_triangulation_parallax_deg > 0.0)) {
    return fail("min_triangulation_parallax_deg must be positive");
  }
  if (!(keyframe_redundancy > 0.0 && keyframe_redundancy <= 1.0)) {
    return fail("keyframe_redundancy must be in (0, 1]");
  }
  if (loop_min_points < 6) return fail("loop_min_points must be at least 6");
  if (loop_min_keyframe_gap < 2) return fail("loop_min_keyframe_gap must be at least 2");
  if (!(loop_min_error > 0.0)) return fail("loop_min_error must be positive");
  return true;
}

}  // namespace m2s::slam
