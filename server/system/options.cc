#include "m2s/slam/system.h"

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
  if (input_queue_capacity <= 0) return fail("input_queue_capacity must be positive");
  if (num_ba_threads <= 0) return fail("num_ba_threads must be positive");
  if (max_keyframes < 2) return fail("max_keyframes must be at least 2");
  return true;
}

}  // namespace m2s::slam
