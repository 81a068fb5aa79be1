// The wire codec: LCM messages (proto/*.lcm) <-> the project's value types, with full
// validation of everything that arrives from the network.
//
// Feature frames carry 8 bytes per feature: a 32-bit vertex id and u, v as 16-bit unsigned
// fixed point with `uv_shift` fractional bits (proto/feature_frame_t.lcm). UvShiftFor() picks
// the finest resolution the image allows: 1/64 px up to 1024 px, 1/32 px up to 2048 px, ...
// Round-trip error is at most 2^-(uv_shift+1) px, except that a coordinate within
// 2^-(uv_shift+1) px of the right/bottom image edge is clamped to the last code inside the
// image (error < 2^-uv_shift px), so every encoded feature decodes inside the image.
//
// Decoding never trusts the bytes: sizes and counts are checked before anything is allocated,
// and every failure is reported with a DropReason (the server's drop counters are keyed by
// its name) and a one-line message.
//
//   std::vector<uint8_t> bytes = EncodeFeatureFrame(frame);
//   Expected<FeatureFrame> decoded = DecodeFeatureFrame(bytes.data(), bytes.size(), limits);
//   if (!decoded) counters[decoded.reason()]++;
//
// Thread-safety: free functions on values, safe from any thread.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

// The generated headers compare a function pointer with void* (-Wpedantic).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpedantic"
#include <m2s/camera_t.hpp>
#include <m2s/feature_frame_t.hpp>
#include <m2s/map_delta_t.hpp>
#include <m2s/pose_estimate_t.hpp>
#include <m2s/pose_t.hpp>
#include <m2s/server_stats_t.hpp>
#include <m2s/session_control_t.hpp>
#pragma GCC diagnostic pop

#include "m2s/common/camera.h"
#include "m2s/common/drop_reason.h"
#include "m2s/common/geometry.h"
#include "m2s/common/status.h"
#include "m2s/common/types.h"

namespace m2s::wire {

// LCM channel names, the one place they are spelled.
inline constexpr const char* kFrameChannel = "M2S_FRAME";      // client -> server
inline constexpr const char* kPoseChannel = "M2S_POSE";        // server -> client
inline constexpr const char* kMapChannel = "M2S_MAP";          // server -> client
inline constexpr const char* kSessionChannel = "M2S_SESSION";  // both directions
inline constexpr const char* kStatsChannel = "M2S_STATS";      // server -> anyone
inline constexpr const char* kDefaultLcmUrl = "udpm://239.255.76.67:7667?ttl=0";

// Every decoder failure carries its DropReason (m2s/common/drop_reason.h, shared with the
// frame validator); the server's drop counters are keyed by its name.
using m2s::DropReason;
using m2s::kNumDropReasons;
using m2s::ToString;

// A feature frame as the project handles it (the decoded feature_frame_t).
struct FeatureFrame {
  SessionId session_id = 0;
  int64_t seq = 0;
  int64_t capture_time_us = 0;
  int64_t send_wall_us = 0;
  Camera camera;
  std::vector<VertexFeature> features;
  std::optional<Pose3> ground_truth_world_from_camera;
};

// Limits applied while decoding a frame.
struct FrameLimits {
  int max_features = 200000;
};

// The largest shift (<= 8) with max(width, height) * 2^shift <= 65536; -1 when the image is
// larger than 65536 px or not positive.
int UvShiftFor(int width, int height);
// Fixed-point code of a coordinate in [0, size) pixels, clamped to the codes inside the image
// (a value within half a quantum of `size` gets the last code, so it still decodes inside).
uint16_t QuantizeCoordinate(float value, int size, int uv_shift);
float DequantizeCoordinate(uint16_t code, int uv_shift);

// Value <-> message conversions.
pose_t ToMessage(const Pose3& pose);
camera_t ToMessage(const Camera& camera);
Expected<Pose3> FromMessage(const pose_t& message);     // kNonFinite / kBadBytes (|q| ~ 0)
Expected<Camera> FromMessage(const camera_t& message);  // kNonFinite / kBadCamera
// The message for a frame (the camera must be valid; features must lie in the image).
feature_frame_t ToMessage(const FeatureFrame& frame);
// Validates a decoded message (everything but the byte layout).
Expected<FeatureFrame> FromMessage(const feature_frame_t& message, const FrameLimits& limits);

// Map group names (session_control_t::map_group): at most kMaxMapGroupName characters of
// [A-Za-z0-9_.-]; empty means no group. Fails with DropReason::kBadGroupName.
inline constexpr size_t kMaxMapGroupName = 64;
Status CheckMapGroupName(std::string_view name);

// Byte-level encode / decode with validation.
template <typename Message>
std::vector<uint8_t> Encode(const Message& message) {
  std::vector<uint8_t> bytes(static_cast<size_t>(message.getEncodedSize()));
  message.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  return bytes;
}
std::vector<uint8_t> EncodeFeatureFrame(const FeatureFrame& frame);
// Encoded size of a frame with n features (160 + 8 n bytes).
size_t FeatureFrameEncodedSize(size_t num_features);

Expected<FeatureFrame> DecodeFeatureFrame(const void* data, size_t size, const FrameLimits& limits);
// The other messages: byte layout, fingerprint and version checked; finite poses checked for
// poses and keyframes; session_control_t's camera is checked only for HELLO, its map_group
// (CheckMapGroupName) for every type.
Expected<session_control_t> DecodeSessionControl(const void* data, size_t size);
Expected<pose_estimate_t> DecodePoseEstimate(const void* data, size_t size);
Expected<map_delta_t> DecodeMapDelta(const void* data, size_t size);
Expected<server_stats_t> DecodeServerStats(const void* data, size_t size);

// Microseconds of CLOCK_REALTIME (the *_wall_us fields).
int64_t WallClockMicros();

}  // namespace m2s::wire
