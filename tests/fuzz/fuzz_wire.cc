// Fuzz targets of the wire decoders (common/src/wire_format.cc).
#include <cmath>
#include <cstring>
#include <vector>

#include "fuzz_targets.h"
#include "m2s/common/check.h"
#include "m2s/common/wire_format.h"

namespace m2s::fuzz {
namespace {

// A decoded message encodes back to exactly the bytes it came from: every field the decoder
// accepts is kept as it was (strings hold no NUL but their last byte).
template <typename Message>
int DecodeAndReencode(const uint8_t* data, size_t size,
                      Expected<Message> (*decode)(const void*, size_t)) {
  const Expected<Message> decoded = decode(data, size);
  if (!decoded) {
    M2S_CHECK(!decoded.error().empty());
    return 0;
  }
  const std::vector<uint8_t> bytes = wire::Encode(*decoded);
  M2S_CHECK(bytes.size() == size) << bytes.size() << " bytes re-encoded from " << size;
  M2S_CHECK(std::memcmp(bytes.data(), data, size) == 0) << "re-encoded bytes differ";
  return 0;
}

bool UnitAndFinite(const Pose3& pose) {
  return pose.AllFinite() && std::abs(pose.rotation().norm() - 1.0) < 1e-9;
}

}  // namespace

int FuzzFeatureFrame(const uint8_t* data, size_t size) {
  const wire::FrameLimits limits;  // the server's default (ServerOptions::max_features)
  const auto decoded = wire::DecodeFeatureFrame(data, size, limits);
  if (!decoded) {
    M2S_CHECK(!decoded.error().empty());
    return 0;
  }
  const wire::FeatureFrame& frame = *decoded;
  M2S_CHECK(size == wire::FeatureFrameEncodedSize(frame.features.size()));
  for (const VertexFeature& f : frame.features) {
    M2S_CHECK(frame.camera.InImage(f.uv.x(), f.uv.y())) << "feature " << f.id << " outside";
  }
  if (frame.ground_truth_world_from_camera) {
    M2S_CHECK(UnitAndFinite(*frame.ground_truth_world_from_camera));
  }
  // Encoding the decoded frame and decoding it again gives the same frame.
  const std::vector<uint8_t> bytes = wire::EncodeFeatureFrame(frame);
  M2S_CHECK(bytes.size() == size);
  const auto again = wire::DecodeFeatureFrame(bytes.data(), bytes.size(), limits);
  M2S_CHECK(again.ok()) << again.error();
  M2S_CHECK(again->session_id == frame.session_id && again->seq == frame.seq &&
            again->capture_time_us == frame.capture_time_us &&
            again->send_wall_us == frame.send_wall_us);
  M2S_CHECK(again->camera.width == frame.camera.width && again->camera.fx == frame.camera.fx &&
            again->camera.far == frame.camera.far);
  M2S_CHECK(again->features.size() == frame.features.size());
  for (size_t i = 0; i < frame.features.size(); ++i) {
    M2S_CHECK(again->features[i].id == frame.features[i].id &&
              again->features[i].uv == frame.features[i].uv);
  }
  M2S_CHECK(again->ground_truth_world_from_camera.has_value() ==
            frame.ground_truth_world_from_camera.has_value());
  return 0;
}

int FuzzSessionControl(const uint8_t* data, size_t size) {
  return DecodeAndReencode<session_control_t>(data, size, wire::DecodeSessionControl);
}

int FuzzPoseEstimate(const uint8_t* data, size_t size) {
  return DecodeAndReencode<pose_estimate_t>(data, size, wire::DecodePoseEstimate);
}

int FuzzMapDelta(const uint8_t* data, size_t size) {
  return DecodeAndReencode<map_delta_t>(data, size, wire::DecodeMapDelta);
}

int FuzzServerStats(const uint8_t* data, size_t size) {
  return DecodeAndReencode<server_stats_t>(data, size, wire::DecodeServerStats);
}

}  // namespace m2s::fuzz
