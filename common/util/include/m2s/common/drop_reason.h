// Why a message or a frame was not used: one reason code for the wire decoders, the bus
// envelope, the server's session table and the SLAM frame validator. The names (ToString) are
// the keys of every drop counter (server stats, SystemStats::rejected_by_reason, metrics.json).
#pragma once

namespace m2s {

enum class DropReason : int {
  kBadBytes = 0,        // not decodable: too short, inconsistent counts, trailing bytes
  kWrongFingerprint,    // LCM type hash of another message type
  kBadVersion,          // version field other than the one we speak
  kBadCamera,           // camera out of range (size, focal length, depth range)
  kNonFinite,           // NaN / infinity in a pose or the camera
  kBadUvShift,          // uv_shift not the one UvShiftFor() gives for the camera
  kNegativeId,          // vertex id < 0
  kOutOfImage,          // (u, v) outside the image (the validator allows a margin)
  kDuplicateId,         // the same vertex id twice in a frame
  kTooManyFeatures,     // more features than the configured maximum
  kSeqNotIncreasing,    // sequence number going back or repeating
  kUnknownSession,      // a request for a session the server does not hold
  kEndedSession,        // a frame for a session that ended (bye, timeout)
  kMaxSessions,         // a new session while the server is full
  kCameraChanged,       // a frame whose camera differs from its session's camera
  kBadSessionMessage,   // unknown session_control_t type or invalid field
  kNotAuthenticated,    // keyed bus: no envelope, a tag that does not verify, another key
  kReplayed,            // keyed bus: an authentic message seen before
  kStale,               // keyed bus: sender clock further off than the allowed message age
  kTooManySenders,      // keyed bus: the table of senders is full of fresh entries
  kSeqJump,             // a frame whose sequence number jumps further than allowed
  kSpoofedSession,      // a message for a session from another sender than its owner
  kEmptyFrame,          // a frame without features
  kNonFiniteTimestamp,  // a frame whose timestamp is NaN / infinite
  kTimestampGoingBack,  // a frame older than the last accepted one
  kNonFiniteUv,         // a feature at NaN / infinite image coordinates
  kBadGroupName,        // a map group name too long or with characters outside [A-Za-z0-9_.-]
  kGroupCamera,         // a session whose camera differs from its map group's camera
  kMaxGroups,           // a new map group while the server holds its maximum of groups
  kCount,
};
inline constexpr int kNumDropReasons = static_cast<int>(DropReason::kCount);

// The reason's stable snake_case name ("bad_bytes", "out_of_image", ...).
const char* ToString(DropReason reason);

}  // namespace m2s
