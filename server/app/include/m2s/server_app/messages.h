// Conversions between the SLAM library's results and the wire messages the server publishes.
// Shared by the server, the on-device transport and the replay tool, so every path publishes
// identical bytes.
#pragma once

#include <cstdint>

#include "m2s/common/wire_format.h"
#include "m2s/slam/system.h"

namespace m2s::server_app {

// The SLAM frame for a decoded wire frame (timestamp in seconds from capture_time_us).
slam::Frame ToSlamFrame(const wire::FeatureFrame& frame);

// The pose estimate for one tracked frame.
pose_estimate_t ToPoseMessage(const slam::TrackResult& result, const wire::FeatureFrame& frame,
                              int64_t server_instance, int64_t map_revision);
int8_t ToWireState(slam::TrackingState state);

// A map delta message (keyframe ids and vertex ids as int32, times in microseconds).
map_delta_t ToMapMessage(const slam::MapDelta& delta, int64_t session_id, int64_t server_instance,
                         int64_t base_revision, int64_t revision);

// A session control message with the version and wall clock filled in.
session_control_t MakeSessionMessage(int8_t type, int64_t session_id, int64_t server_instance);

}  // namespace m2s::server_app
