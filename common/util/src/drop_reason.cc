#include "m2s/common/drop_reason.h"

namespace m2s {

const char* ToString(DropReason reason) {
  switch (reason) {
    case DropReason::kBadBytes:
      return "bad_bytes";
    case DropReason::kWrongFingerprint:
      return "wrong_fingerprint";
    case DropReason::kBadVersion:
      return "bad_version";
    case DropReason::kBadCamera:
      return "bad_camera";
    case DropReason::kNonFinite:
      return "non_finite";
    case DropReason::kBadUvShift:
      return "bad_uv_shift";
    case DropReason::kNegativeId:
      return "negative_id";
    case DropReason::kOutOfImage:
      return "out_of_image";
    case DropReason::kDuplicateId:
      return "duplicate_id";
    case DropReason::kTooManyFeatures:
      return "too_many_features";
    case DropReason::kSeqNotIncreasing:
      return "seq_not_increasing";
    case DropReason::kUnknownSession:
      return "unknown_session";
    case DropReason::kEndedSession:
      return "ended_session";
    case DropReason::kMaxSessions:
      return "max_sessions";
    case DropReason::kCameraChanged:
      return "camera_changed";
    case DropReason::kBadSessionMessage:
      return "bad_session_message";
    case DropReason::kNotAuthenticated:
      return "not_authenticated";
    case DropReason::kReplayed:
      return "replayed";
    case DropReason::kStale:
      return "stale";
    case DropReason::kTooManySenders:
      return "too_many_senders";
    case DropReason::kSeqJump:
      return "seq_jump";
    case DropReason::kSpoofedSession:
      return "spoofed_session";
    case DropReason::kEmptyFrame:
      return "empty";
    case DropReason::kNonFiniteTimestamp:
      return "non_finite_timestamp";
    case DropReason::kTimestampGoingBack:
      return "timestamp_going_back";
    case DropReason::kNonFiniteUv:
      return "non_finite_uv";
    case DropReason::kBadGroupName:
      return "bad_group_name";
    case DropReason::kGroupCamera:
      return "group_camera_mismatch";
    case DropReason::kMaxGroups:
      return "max_groups";
    case DropReason::kCount:
      break;
  }
  return "unknown";
}

}  // namespace m2s
