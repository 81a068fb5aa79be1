#include "m2s/common/wire_format.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <sstream>
#include <string_view>

namespace m2s::wire {
namespace {

constexpr int kMaxUvShift = 8;
constexpr int kHashBytes = 8;
constexpr int kPoseBytes = 7 * 8;
constexpr int kCameraBytes = 2 * 4 + 6 * 8;
constexpr int kKeyframeBytes = 4 + 8 + kPoseBytes + 1;
// An encoded string: int32 length (counting the NUL), at least the NUL.
constexpr int kMinStringBytes = 4 + 1;

// Walks the byte layout of a message over untrusted bytes, big-endian. Every step is checked
// against the bytes that remain; the first failure is kept as a one-line message.
class Reader {
 public:
  Reader(const void* data, size_t size) : data_(static_cast<const uint8_t*>(data)), size_(size) {}

  bool Skip(size_t n) {
    if (n > remaining()) {
      return Fail("needs " + std::to_string(n) + " bytes, " + std::to_string(remaining()) +
                  " left");
    }
    pos_ += n;
    return true;
  }
  bool ReadI32(int32_t* value) {
    uint64_t v = 0;
    if (!ReadBigEndian(4, &v)) return false;
    *value = static_cast<int32_t>(static_cast<uint32_t>(v));
    return true;
  }
  bool ReadI64(int64_t* value) {
    uint64_t v = 0;
    if (!ReadBigEndian(8, &v)) return false;
    *value = static_cast<int64_t>(v);
    return true;
  }
  // Reads an array count; fails unless 0 <= count and count * min_element_bytes bytes remain.
  bool ReadCount(size_t min_element_bytes, int32_t* count) {
    const size_t at = pos_;
    if (!ReadI32(count)) return false;
    if (*count < 0 || static_cast<uint64_t>(*count) * min_element_bytes > remaining()) {
      return FailAt(at, "count " + std::to_string(*count) + " with " + std::to_string(remaining()) +
                            " bytes left");
    }
    return true;
  }
  // Reads a count and skips count * element_bytes.
  bool SkipArray(size_t element_bytes, int32_t* count) {
    return ReadCount(element_bytes, count) && Skip(static_cast<size_t>(*count) * element_bytes);
  }
  // Skips a string: int32 length counting the terminating NUL (1 <= length <= what remains),
  // the characters (none of them NUL), the NUL.
  bool SkipString() {
    const size_t at = pos_;
    int32_t length = 0;
    if (!ReadI32(&length)) return false;
    if (length < 1 || static_cast<uint64_t>(length) > remaining()) {
      return FailAt(at, "string length " + std::to_string(length) + " with " +
                            std::to_string(remaining()) + " bytes left");
    }
    // The NUL ends the string and nothing before it is one (lcm's encoder writes C strings).
    const void* nul = std::memchr(data_ + pos_, 0, static_cast<size_t>(length));
    if (nul != data_ + pos_ + length - 1) return FailAt(at, "string not NUL-terminated");
    pos_ += static_cast<size_t>(length);
    return true;
  }
  bool AtEnd() { return remaining() == 0 || Fail(std::to_string(remaining()) + " trailing bytes"); }
  // Records a failure other than the layout's.
  bool Fail(DropReason reason, std::string message) {
    reason_ = reason;
    error_ = std::move(message);
    return false;
  }

  size_t remaining() const { return size_ - pos_; }
  DropReason reason() const { return reason_; }
  const std::string& error() const { return error_; }

 private:
  bool ReadBigEndian(int bytes, uint64_t* value) {
    if (!Skip(static_cast<size_t>(bytes))) return false;
    uint64_t v = 0;
    for (size_t i = pos_ - static_cast<size_t>(bytes); i < pos_; ++i) v = (v << 8) | data_[i];
    *value = v;
    return true;
  }
  bool Fail(const std::string& what) { return FailAt(pos_, what); }
  bool FailAt(size_t at, const std::string& what) {
    return Fail(DropReason::kBadBytes, "at byte " + std::to_string(at) + ": " + what);
  }

  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  DropReason reason_ = DropReason::kBadBytes;
  std::string error_;
};

// Checks the type hash, then walks the byte layout with `layout(Reader*)` (the bytes after the
// fingerprint; true when every length and count fits and nothing is left over), and only then
// decodes with the generated code: lcm-gen's decoders trust lengths (a string length of
// INT32_MIN reads out of bounds) and size arrays by counts before reading them.
template <typename Message, typename Layout>
Expected<Message> DecodeChecked(const void* data, size_t size, Layout&& layout) {
  const std::string_view name = Message::getTypeName();  // strings built on failure only
  Reader reader(data, size);
  int64_t hash = 0;
  if (!reader.ReadI64(&hash)) {
    return Expected<Message>::Error(DropReason::kBadBytes,
                                    std::string(name) + ": message shorter than its fingerprint");
  }
  if (hash != Message::getHash()) {
    return Expected<Message>::Error(DropReason::kWrongFingerprint,
                                    "fingerprint is not that of " + std::string(name));
  }
  if (size > static_cast<size_t>(INT32_MAX)) {
    return Expected<Message>::Error(DropReason::kBadBytes,
                                    std::string(name) + ": message larger than 2 GiB");
  }
  if (!layout(&reader) || !reader.AtEnd()) {
    return Expected<Message>::Error(reader.reason(), std::string(name) + ": " + reader.error());
  }
  Message message;
  int consumed = -1;
  try {
    consumed = message.decode(data, 0, static_cast<int>(size));
  } catch (const std::exception&) {
    consumed = -1;
  }
  if (consumed < 0 || static_cast<size_t>(consumed) != size) {
    return Expected<Message>::Error(DropReason::kBadBytes, std::string(name) + ": malformed bytes");
  }
  if (message.version != Message::VERSION) {
    return Expected<Message>::Error(DropReason::kBadVersion, std::string(name) + ": version " +
                                                                 std::to_string(message.version));
  }
  return message;
}

bool AllFinite(const double* values, int n) {
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(values[i])) return false;
  }
  return true;
}

}  // namespace

int UvShiftFor(int width, int height) {
  const int64_t size = std::max(width, height);
  if (width <= 0 || height <= 0 || size > 65536) return -1;
  int shift = 0;
  while (shift < kMaxUvShift && (size << (shift + 1)) <= 65536) ++shift;
  return shift;
}

uint16_t QuantizeCoordinate(float value, int size, int uv_shift) {
  const double scaled = std::ldexp(static_cast<double>(value), uv_shift);
  if (!(scaled > 0.0)) return 0;  // also NaN
  const long long last = std::min((static_cast<long long>(size) << uv_shift) - 1, 65535LL);
  return static_cast<uint16_t>(std::clamp(std::llround(scaled), 0LL, std::max(last, 0LL)));
}

float DequantizeCoordinate(uint16_t code, int uv_shift) {
  return static_cast<float>(std::ldexp(static_cast<double>(code), -uv_shift));
}

pose_t ToMessage(const Pose3& pose) {
  pose_t m;
  for (int i = 0; i < 3; ++i) m.t[i] = pose.translation()[i];
  const Eigen::Quaterniond& q = pose.rotation();
  m.q[0] = q.w();
  m.q[1] = q.x();
  m.q[2] = q.y();
  m.q[3] = q.z();
  return m;
}

camera_t ToMessage(const Camera& camera) {
  camera_t m;
  m.width = camera.width;
  m.height = camera.height;
  m.fx = camera.fx;
  m.fy = camera.fy;
  m.cx = camera.cx;
  m.cy = camera.cy;
  m.near_m = camera.near;
  m.far_m = camera.far;
  return m;
}

Expected<Pose3> FromMessage(const pose_t& m) {
  if (!AllFinite(m.t, 3) || !AllFinite(m.q, 4)) {
    return Expected<Pose3>::Error(DropReason::kNonFinite, "pose has a non-finite value");
  }
  const Eigen::Quaterniond q(m.q[0], m.q[1], m.q[2], m.q[3]);
  const double norm = q.norm();
  if (!(norm > 1e-6))
    return Expected<Pose3>::Error(DropReason::kBadBytes, "pose quaternion is zero");
  // A norm that overflows would normalise to a zero quaternion.
  if (!std::isfinite(norm)) {
    return Expected<Pose3>::Error(DropReason::kNonFinite, "pose quaternion norm is not finite");
  }
  return Pose3(q, Eigen::Vector3d(m.t[0], m.t[1], m.t[2]));
}

Expected<Camera> FromMessage(const camera_t& m) {
  const double values[] = {m.fx, m.fy, m.cx, m.cy, m.near_m, m.far_m};
  if (!AllFinite(values, 6)) {
    return Expected<Camera>::Error(DropReason::kNonFinite, "camera has a non-finite value");
  }
  Camera camera;
  camera.width = m.width;
  camera.height = m.height;
  camera.fx = m.fx;
  camera.fy = m.fy;
  camera.cx = m.cx;
  camera.cy = m.cy;
  camera.near = m.near_m;
  camera.far = m.far_m;
  if (Status valid = camera.Check(); !valid) {
    return Expected<Camera>::Error(DropReason::kBadCamera, "camera: " + valid.message());
  }
  if (UvShiftFor(camera.width, camera.height) < 0) {
    return Expected<Camera>::Error(DropReason::kBadCamera, "camera: image larger than 65536 px");
  }
  return camera;
}

feature_frame_t ToMessage(const FeatureFrame& frame) {
  feature_frame_t m;
  m.version = feature_frame_t::VERSION;
  m.session_id = frame.session_id;
  m.seq = frame.seq;
  m.capture_time_us = frame.capture_time_us;
  m.send_wall_us = frame.send_wall_us;
  m.camera = ToMessage(frame.camera);
  const int shift = std::max(0, UvShiftFor(frame.camera.width, frame.camera.height));
  m.uv_shift = static_cast<int8_t>(shift);
  const size_t n = frame.features.size();
  m.num_features = static_cast<int32_t>(n);
  m.ids.resize(n);
  m.u_q.resize(n);
  m.v_q.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const VertexFeature& f = frame.features[i];
    m.ids[i] = static_cast<int32_t>(f.id);
    m.u_q[i] = static_cast<int16_t>(QuantizeCoordinate(f.uv.x(), frame.camera.width, shift));
    m.v_q[i] = static_cast<int16_t>(QuantizeCoordinate(f.uv.y(), frame.camera.height, shift));
  }
  m.has_ground_truth = frame.ground_truth_world_from_camera.has_value();
  m.ground_truth_world_from_camera =
      m.has_ground_truth ? ToMessage(*frame.ground_truth_world_from_camera) : ToMessage(Pose3());
  return m;
}

Expected<FeatureFrame> FromMessage(const feature_frame_t& m, const FrameLimits& limits) {
  using R = Expected<FeatureFrame>;
  if (m.version != feature_frame_t::VERSION) {
    return R::Error(DropReason::kBadVersion, "frame version " + std::to_string(m.version));
  }
  if (m.num_features < 0 || m.ids.size() != static_cast<size_t>(m.num_features) ||
      m.u_q.size() != m.ids.size() || m.v_q.size() != m.ids.size()) {
    return R::Error(DropReason::kBadBytes, "frame feature arrays inconsistent with num_features");
  }
  auto camera = FromMessage(m.camera);
  if (!camera) return R::Error(camera.reason(), camera.error());
  const int shift = UvShiftFor(camera->width, camera->height);
  if (m.uv_shift != shift) {
    return R::Error(DropReason::kBadUvShift, "uv_shift " + std::to_string(m.uv_shift) + " for a " +
                                                 std::to_string(camera->width) + "x" +
                                                 std::to_string(camera->height) +
                                                 " image (expected " + std::to_string(shift) + ")");
  }
  if (m.num_features > limits.max_features) {
    return R::Error(
        DropReason::kTooManyFeatures,
        std::to_string(m.num_features) + " features > max " + std::to_string(limits.max_features));
  }
  FeatureFrame frame;
  if (m.has_ground_truth) {
    auto gt = FromMessage(m.ground_truth_world_from_camera);
    if (!gt) return R::Error(gt.reason(), "ground truth " + gt.error());
    frame.ground_truth_world_from_camera = *gt;
  }
  const uint32_t u_limit = static_cast<uint32_t>(camera->width) << shift;
  const uint32_t v_limit = static_cast<uint32_t>(camera->height) << shift;
  const size_t n = m.ids.size();
  frame.features.resize(n);
  for (size_t i = 0; i < n; ++i) {
    if (m.ids[i] < 0) {
      return R::Error(DropReason::kNegativeId, "negative vertex id " + std::to_string(m.ids[i]));
    }
    const uint16_t u = static_cast<uint16_t>(m.u_q[i]);
    const uint16_t v = static_cast<uint16_t>(m.v_q[i]);
    if (u >= u_limit || v >= v_limit) {
      return R::Error(DropReason::kOutOfImage,
                      "feature " + std::to_string(m.ids[i]) + " outside the image");
    }
    frame.features[i].id = static_cast<VertexId>(m.ids[i]);
    frame.features[i].uv = {DequantizeCoordinate(u, shift), DequantizeCoordinate(v, shift)};
  }
  std::vector<int32_t> sorted(m.ids);
  std::sort(sorted.begin(), sorted.end());
  const auto dup = std::adjacent_find(sorted.begin(), sorted.end());
  if (dup != sorted.end()) {
    return R::Error(DropReason::kDuplicateId, "vertex id " + std::to_string(*dup) + " twice");
  }
  frame.session_id = m.session_id;
  frame.seq = m.seq;
  frame.capture_time_us = m.capture_time_us;
  frame.send_wall_us = m.send_wall_us;
  frame.camera = *camera;
  return frame;
}

std::vector<uint8_t> EncodeFeatureFrame(const FeatureFrame& frame) {
  return Encode(ToMessage(frame));
}

size_t FeatureFrameEncodedSize(size_t num_features) {
  // hash, version, 4 int64, camera, uv_shift, count, 8 bytes per feature, flag, pose.
  return kHashBytes + 2 + 4 * 8 + kCameraBytes + 1 + 4 + 8 * num_features + 1 + kPoseBytes;
}

Expected<FeatureFrame> DecodeFeatureFrame(const void* data, size_t size,
                                          const FrameLimits& limits) {
  using R = Expected<FeatureFrame>;
  auto message = DecodeChecked<feature_frame_t>(data, size, [&limits](Reader* r) {
    int32_t count = 0;
    if (!r->Skip(2 + 4 * 8 + kCameraBytes + 1) || !r->SkipArray(4 + 2 + 2, &count) ||
        !r->Skip(1 + kPoseBytes) || !r->AtEnd()) {
      return false;
    }
    return count <= limits.max_features ||
           r->Fail(DropReason::kTooManyFeatures, std::to_string(count) + " features > max " +
                                                     std::to_string(limits.max_features));
  });
  if (!message) return R::Error(message.reason(), message.error());
  return FromMessage(*message, limits);
}

Expected<session_control_t> DecodeSessionControl(const void* data, size_t size) {
  auto m = DecodeChecked<session_control_t>(data, size, [](Reader* r) {
    // version, type, 4 int64, client_name, reason, camera, flags, map_group.
    return r->Skip(2 + 1 + 4 * 8) && r->SkipString() && r->SkipString() &&
           r->Skip(kCameraBytes + 4) && r->SkipString();
  });
  if (!m) return m;
  if (Status name = CheckMapGroupName(m->map_group); !name) return name;
  if (m->type < session_control_t::HELLO || m->type > session_control_t::REJECTED) {
    return Expected<session_control_t>::Error(DropReason::kBadSessionMessage,
                                              "session message type " + std::to_string(m->type));
  }
  if (m->type == session_control_t::HELLO) {
    auto camera = FromMessage(m->camera);
    if (!camera)
      return Expected<session_control_t>::Error(camera.reason(), "HELLO " + camera.error());
  }
  return m;
}

Expected<pose_estimate_t> DecodePoseEstimate(const void* data, size_t size) {
  auto m = DecodeChecked<pose_estimate_t>(data, size, [](Reader* r) {
    // version, 5 int64, state, pose, 2 int32, keyframe_created, tracking_ms, map_revision,
    // map_id.
    return r->Skip(2 + 5 * 8 + 1 + kPoseBytes + 2 * 4 + 1 + 4 + 8 + 4);
  });
  if (!m) return m;
  if (!AllFinite(m->world_from_camera.t, 3) || !AllFinite(m->world_from_camera.q, 4)) {
    return Expected<pose_estimate_t>::Error(DropReason::kNonFinite, "pose estimate is not finite");
  }
  return m;
}

Expected<map_delta_t> DecodeMapDelta(const void* data, size_t size) {
  auto m = DecodeChecked<map_delta_t>(data, size, [](Reader* r) {
    // version, 4 int64, full; keyframes, removed keyframes, points (id + xyz), removed points.
    int32_t n = 0;
    return r->Skip(2 + 4 * 8 + 1) && r->SkipArray(kKeyframeBytes, &n) && r->SkipArray(4, &n) &&
           r->SkipArray(4 + 3 * 4, &n) && r->SkipArray(4, &n);
  });
  if (!m) return m;
  for (const keyframe_t& kf : m->keyframes) {
    if (!AllFinite(kf.world_from_camera.t, 3) || !AllFinite(kf.world_from_camera.q, 4)) {
      return Expected<map_delta_t>::Error(DropReason::kNonFinite,
                                          "map delta: keyframe pose not finite");
    }
  }
  for (const auto& p : m->point_xyz) {
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      return Expected<map_delta_t>::Error(DropReason::kNonFinite, "map delta: point not finite");
    }
  }
  return m;
}

Expected<server_stats_t> DecodeServerStats(const void* data, size_t size) {
  return DecodeChecked<server_stats_t>(data, size, [](Reader* r) {
    // version, 2 int64, int32, 3 int64; num_drop_reasons strings then as many int64; 2 floats.
    int32_t n = 0;
    if (!r->Skip(2 + 2 * 8 + 4 + 3 * 8) || !r->ReadCount(kMinStringBytes + 8, &n)) return false;
    for (int32_t i = 0; i < n; ++i) {
      if (!r->SkipString()) return false;
    }
    return r->Skip(static_cast<size_t>(n) * 8 + 2 * 4);
  });
}

Status CheckMapGroupName(std::string_view name) {
  if (name.size() > kMaxMapGroupName) {
    return Status::Error(DropReason::kBadGroupName,
                         "map group name of " + std::to_string(name.size()) + " characters (max " +
                             std::to_string(kMaxMapGroupName) + ")");
  }
  for (const char c : name) {
    const bool allowed = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                         (c >= '0' && c <= '9') || c == '_' || c == '.' || c == '-';
    if (!allowed) {
      return Status::Error(DropReason::kBadGroupName,
                           "map group name with character code " +
                               std::to_string(static_cast<int>(static_cast<uint8_t>(c))) +
                               " (allowed: A-Z a-z 0-9 _ . -)");
    }
  }
  return Status::Ok();
}

int64_t WallClockMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace m2s::wire
