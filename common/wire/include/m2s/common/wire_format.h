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
//   DecodeResult<FeatureFrame> decoded = DecodeFeatureFrame(bytes.data(), bytes.size(), limits);
//   if (!decoded) counters[decoded.reason()]++;
//
// Thread-safety: free functions on values, safe from any thread.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <variant>
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

// Why a message was not used. The names (ToString) are the server's drop-counter keys.
enum class DropReason : int {
  kBadBytes = 0,       // not decodable: too short, inconsistent counts, trailing bytes
  kWrongFingerprint,   // LCM type hash of another message type
  kBadVersion,         // version field other than the one we speak
  kBadCamera,          // camera out of range (size, focal length, depth range)
  kNonFinite,          // NaN / infinity in a pose or the camera
  kBadUvShift,         // uv_shift not the one UvShiftFor() gives for the camera
  kNegativeId,         // vertex id < 0
  kOutOfImage,         // (u, v) outside [0, width) x [0, height)
  kDuplicateId,        // the same vertex id twice in a frame
  kTooManyFeatures,    // more features than the configured maximum
  kSeqNotIncreasing,   // sequence number going back or repeating
  kUnknownSession,     // a request for a session the server does not hold
  kEndedSession,       // a frame for a session that ended (bye, timeout)
  kMaxSessions,        // a new session while the server is full
  kCameraChanged,      // a frame whose camera differs from its session's camera
  kBadSessionMessage,  // unknown session_control_t type or invalid field
  kNotAuthenticated,   // keyed bus: no envelope, a tag that does not verify, another key
  kReplayed,           // keyed bus: an authentic message seen before
  kStale,              // keyed bus: sender clock further off than the allowed message age
  kTooManySenders,     // keyed bus: the table of senders is full of fresh entries
  kSeqJump,            // a frame whose sequence number jumps further than allowed
  kSpoofedSession,     // a message for a session from another sender than its owner
  kCount,
};
inline constexpr int kNumDropReasons = static_cast<int>(DropReason::kCount);
const char* ToString(DropReason reason);

// An error with its reason code.
struct WireError {
  DropReason reason = DropReason::kBadBytes;
  std::string message;
};

// Expected<T> with a reason code on failure.
template <typename T>
class DecodeResult {
 public:
  DecodeResult(T value) : data_(std::move(value)) {}          // NOLINT: implicit by design
  DecodeResult(WireError error) : data_(std::move(error)) {}  // NOLINT
  static DecodeResult Error(DropReason reason, std::string message) {
    return DecodeResult(WireError{reason, std::move(message)});
  }

  bool ok() const { return std::holds_alternative<T>(data_); }
  explicit operator bool() const { return ok(); }
  T& value() & { return std::get<T>(data_); }
  const T& value() const& { return std::get<T>(data_); }
  T&& value() && { return std::get<T>(std::move(data_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  DropReason reason() const { return std::get<WireError>(data_).reason; }
  const std::string& error() const { return std::get<WireError>(data_).message; }
  Status status() const { return ok() ? Status::Ok() : Status::Error(error()); }

 private:
  std::variant<T, WireError> data_;
};

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
DecodeResult<Pose3> FromMessage(const pose_t& message);     // kNonFinite / kBadBytes (|q| ~ 0)
DecodeResult<Camera> FromMessage(const camera_t& message);  // kNonFinite / kBadCamera
// The message for a frame (the camera must be valid; features must lie in the image).
feature_frame_t ToMessage(const FeatureFrame& frame);
// Validates a decoded message (everything but the byte layout).
DecodeResult<FeatureFrame> FromMessage(const feature_frame_t& message, const FrameLimits& limits);

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

DecodeResult<FeatureFrame> DecodeFeatureFrame(const void* data, size_t size,
                                              const FrameLimits& limits);
// The other messages: byte layout, fingerprint and version checked; finite poses checked for
// poses and keyframes; session_control_t's camera is checked only for HELLO.
DecodeResult<session_control_t> DecodeSessionControl(const void* data, size_t size);
DecodeResult<pose_estimate_t> DecodePoseEstimate(const void* data, size_t size);
DecodeResult<map_delta_t> DecodeMapDelta(const void* data, size_t size);
DecodeResult<server_stats_t> DecodeServerStats(const void* data, size_t size);

// Microseconds of CLOCK_REALTIME (the *_wall_us fields).
int64_t WallClockMicros();

}  // namespace m2s::wire
