// The wire codec: round-trip precision, the 8-bytes-per-feature budget and malformed input.
#include "m2s/common/wire_format.h"

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <utility>

#include <gtest/gtest.h>

namespace m2s::wire {
namespace {

FeatureFrame RandomFrame(int width, int height, int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.f, static_cast<float>(width));
  std::uniform_real_distribution<float> v(0.f, static_cast<float>(height));
  FeatureFrame frame;
  frame.session_id = 42;
  frame.seq = 7;
  frame.capture_time_us = 123456;
  frame.send_wall_us = 987654321;
  frame.camera = Camera::FromHorizontalFov(width, height, 90.0);
  for (int i = 0; i < n; ++i) {
    VertexFeature f;
    f.id = static_cast<VertexId>(i * 3 + 1);
    f.uv = {u(rng), v(rng)};
    // Keep clear of the clamped last code at the right/bottom edge.
    f.uv = f.uv.cwiseMin(Eigen::Vector2f(width - 0.01f, height - 0.01f));
    frame.features.push_back(f);
  }
  frame.ground_truth_world_from_camera =
      Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
            Eigen::Vector3d(1, -2, 3));
  return frame;
}

TEST(WireFormatTest, UvShiftMatchesTheDocumentedResolution) {
  EXPECT_EQ(UvShiftFor(640, 480), 6);
  EXPECT_EQ(UvShiftFor(1024, 1024), 6);
  EXPECT_EQ(UvShiftFor(1832, 1920), 5);
  EXPECT_EQ(UvShiftFor(4096, 2048), 4);
  EXPECT_EQ(UvShiftFor(100, 100), 8);
  EXPECT_EQ(UvShiftFor(65536, 10), 0);
  EXPECT_EQ(UvShiftFor(65537, 10), -1);
  EXPECT_EQ(UvShiftFor(0, 10), -1);
}

TEST(WireFormatTest, RoundTripErrorWithinHalfAQuantum) {
  const int sizes[][2] = {{640, 480}, {1024, 1024}, {1832, 1920}, {4096, 3000}, {120, 90}};
  for (const auto& size : sizes) {
    const FeatureFrame frame = RandomFrame(size[0], size[1], 3000, size[0]);
    const std::vector<uint8_t> bytes = EncodeFeatureFrame(frame);
    const auto decoded = DecodeFeatureFrame(bytes.data(), bytes.size(), {});
    ASSERT_TRUE(decoded.ok()) << decoded.error();
    const int shift = UvShiftFor(size[0], size[1]);
    const double bound = std::ldexp(1.0, -(shift + 1));
    ASSERT_EQ(decoded->features.size(), frame.features.size());
    double worst = 0;
    for (size_t i = 0; i < frame.features.size(); ++i) {
      EXPECT_EQ(decoded->features[i].id, frame.features[i].id);
      worst = std::max<double>(
          worst, (decoded->features[i].uv - frame.features[i].uv).cwiseAbs().maxCoeff());
    }
    EXPECT_LE(worst, bound * (1 + 1e-6)) << size[0] << "x" << size[1];
    EXPECT_EQ(decoded->session_id, 42);
    EXPECT_EQ(decoded->seq, 7);
    EXPECT_EQ(decoded->capture_time_us, 123456);
    EXPECT_EQ(decoded->send_wall_us, 987654321);
    EXPECT_EQ(decoded->camera.width, size[0]);
    EXPECT_DOUBLE_EQ(decoded->camera.fx, frame.camera.fx);
    ASSERT_TRUE(decoded->ground_truth_world_from_camera.has_value());
    EXPECT_LT((decoded->ground_truth_world_from_camera->translation() -
               frame.ground_truth_world_from_camera->translation())
                  .norm(),
              1e-12);
  }
}

TEST(WireFormatTest, EightBytesPerFeature) {
  const auto small = EncodeFeatureFrame(RandomFrame(640, 480, 100, 1));
  const auto large = EncodeFeatureFrame(RandomFrame(640, 480, 1100, 1));
  EXPECT_EQ(large.size() - small.size(), 1000u * 8u);
  EXPECT_EQ(small.size(), FeatureFrameEncodedSize(100));
}

TEST(WireFormatTest, EdgeCoordinatesClampToTheLastCode) {
  EXPECT_EQ(QuantizeCoordinate(1023.999f, 1024, 6), 65535);
  EXPECT_EQ(QuantizeCoordinate(639.999f, 640, 6), 640 * 64 - 1);
  EXPECT_EQ(QuantizeCoordinate(-0.3f, 640, 6), 0);
  EXPECT_EQ(QuantizeCoordinate(std::nanf(""), 640, 6), 0);
  // A feature at the very edge still decodes inside the image.
  FeatureFrame edge = RandomFrame(640, 480, 1, 9);
  edge.features[0].uv = {639.9999f, 479.9999f};
  const auto bytes = EncodeFeatureFrame(edge);
  EXPECT_TRUE(DecodeFeatureFrame(bytes.data(), bytes.size(), {}).ok());
  EXPECT_FLOAT_EQ(DequantizeCoordinate(65535, 6), 1023.984375f);
}

TEST(WireFormatTest, PoseAndCameraConversions) {
  const Pose3 pose(Eigen::Quaterniond(0.5, 0.5, -0.5, 0.5), Eigen::Vector3d(0.1, 0.2, 0.3));
  const auto back = FromMessage(ToMessage(pose));
  ASSERT_TRUE(back.ok());
  EXPECT_LT((back->Matrix() - pose.Matrix()).norm(), 1e-15);
  pose_t nan_pose = ToMessage(pose);
  nan_pose.q[2] = std::nan("");
  EXPECT_EQ(FromMessage(nan_pose).reason(), DropReason::kNonFinite);
  const Camera camera = Camera::FromHorizontalFov(800, 600, 70.0);
  const auto camera_back = FromMessage(ToMessage(camera));
  ASSERT_TRUE(camera_back.ok());
  EXPECT_EQ(camera_back->height, 600);
  EXPECT_DOUBLE_EQ(camera_back->cy, camera.cy);
  camera_t bad = ToMessage(camera);
  bad.fx = -1;
  EXPECT_EQ(FromMessage(bad).reason(), DropReason::kBadCamera);
  bad.fx = std::numeric_limits<double>::infinity();
  EXPECT_EQ(FromMessage(bad).reason(), DropReason::kNonFinite);
}

// Decodes a message built by hand and returns the reason (kCount when it decoded).
DropReason ReasonFor(const feature_frame_t& m, int max_features = 200000) {
  const std::vector<uint8_t> bytes = Encode(m);
  const auto decoded = DecodeFeatureFrame(bytes.data(), bytes.size(), {max_features});
  return decoded.ok() ? DropReason::kCount : decoded.reason();
}

TEST(WireFormatTest, MalformedFramesAreRejectedWithTheirReason) {
  const feature_frame_t good = ToMessage(RandomFrame(640, 480, 50, 3));
  EXPECT_EQ(ReasonFor(good), DropReason::kCount);

  feature_frame_t m = good;
  m.version = 2;
  EXPECT_EQ(ReasonFor(m), DropReason::kBadVersion);
  m = good;
  m.ids[3] = -5;
  EXPECT_EQ(ReasonFor(m), DropReason::kNegativeId);
  m = good;
  m.ids[4] = m.ids[9];
  EXPECT_EQ(ReasonFor(m), DropReason::kDuplicateId);
  m = good;
  m.u_q[1] = static_cast<int16_t>(640 << 6);  // u == width
  EXPECT_EQ(ReasonFor(m), DropReason::kOutOfImage);
  m = good;
  m.v_q[1] = -1;  // 65535 / 64 px > height
  EXPECT_EQ(ReasonFor(m), DropReason::kOutOfImage);
  m = good;
  m.uv_shift = 7;
  EXPECT_EQ(ReasonFor(m), DropReason::kBadUvShift);
  m = good;
  m.camera.cx = std::nan("");
  EXPECT_EQ(ReasonFor(m), DropReason::kNonFinite);
  m = good;
  m.camera.width = -640;
  EXPECT_EQ(ReasonFor(m), DropReason::kBadCamera);
  m = good;
  m.ground_truth_world_from_camera.t[0] = std::nan("");
  EXPECT_EQ(ReasonFor(m), DropReason::kNonFinite);
  m.has_ground_truth = false;  // ignored when absent
  EXPECT_EQ(ReasonFor(m), DropReason::kCount);
  EXPECT_EQ(ReasonFor(good, 49), DropReason::kTooManyFeatures);
}

TEST(WireFormatTest, BadBytesNeverCrashOrAllocate) {
  const std::vector<uint8_t> good = EncodeFeatureFrame(RandomFrame(640, 480, 20, 4));
  // Truncated at every length.
  for (size_t n = 0; n < good.size(); ++n) {
    const auto d = DecodeFeatureFrame(good.data(), n, {});
    ASSERT_FALSE(d.ok());
    EXPECT_EQ(d.reason(), DropReason::kBadBytes) << n;
  }
  // Trailing byte.
  std::vector<uint8_t> longer = good;
  longer.push_back(0);
  EXPECT_EQ(DecodeFeatureFrame(longer.data(), longer.size(), {}).reason(), DropReason::kBadBytes);
  // A huge or negative count in a short message.
  for (int32_t count : {-1, 0x7fffffff, 1 << 28}) {
    std::vector<uint8_t> bad = good;
    for (int i = 0; i < 4; ++i) bad[99 + i] = static_cast<uint8_t>(count >> (24 - 8 * i));
    EXPECT_EQ(DecodeFeatureFrame(bad.data(), bad.size(), {}).reason(), DropReason::kBadBytes);
  }
  // Another type's fingerprint.
  pose_estimate_t pose{};
  pose.version = pose_estimate_t::VERSION;
  pose.world_from_camera = ToMessage(Pose3());
  const auto pose_bytes = Encode(pose);
  EXPECT_EQ(DecodeFeatureFrame(pose_bytes.data(), pose_bytes.size(), {}).reason(),
            DropReason::kWrongFingerprint);
  EXPECT_TRUE(DecodePoseEstimate(pose_bytes.data(), pose_bytes.size()).ok());
  // Random bytes on every decoder.
  std::mt19937 rng(5);
  for (int trial = 0; trial < 2000; ++trial) {
    std::vector<uint8_t> junk(rng() % 300);
    for (auto& b : junk) b = static_cast<uint8_t>(rng());
    if (trial % 2 == 0 && junk.size() >= 8) {  // with a valid fingerprint half of the time
      const int64_t hashes[] = {feature_frame_t::getHash(), session_control_t::getHash(),
                                map_delta_t::getHash(), server_stats_t::getHash()};
      const uint64_t h = static_cast<uint64_t>(hashes[trial / 2 % 4]);
      for (int i = 0; i < 8; ++i) junk[i] = static_cast<uint8_t>(h >> (56 - 8 * i));
    }
    EXPECT_FALSE(DecodeFeatureFrame(junk.data(), junk.size(), {}).ok() &&
                 DecodeSessionControl(junk.data(), junk.size()).ok() &&
                 DecodeMapDelta(junk.data(), junk.size()).ok() &&
                 DecodeServerStats(junk.data(), junk.size()).ok());
  }
}

TEST(WireFormatTest, MapDeltaWithHugeCountsIsRejected) {
  map_delta_t delta{};
  delta.version = map_delta_t::VERSION;
  delta.num_keyframes = delta.num_removed_keyframes = delta.num_removed_points = 0;
  delta.num_points = 2;
  delta.point_ids = {1, 2};
  delta.point_xyz = {{0, 1, 2}, {3, 4, 5}};
  std::vector<uint8_t> bytes = Encode(delta);
  ASSERT_TRUE(DecodeMapDelta(bytes.data(), bytes.size()).ok());
  // num_points sits after the 8-byte hash, the header (43 bytes in all) and two empty arrays.
  const size_t offset = 43 + 4 + 4;
  for (int i = 0; i < 4; ++i) bytes[offset + i] = i == 0 ? 0x40 : 0;
  EXPECT_EQ(DecodeMapDelta(bytes.data(), bytes.size()).reason(), DropReason::kBadBytes);
}

TEST(WireFormatTest, SessionControlValidation) {
  session_control_t m{};
  m.version = session_control_t::VERSION;
  m.type = session_control_t::HELLO;
  m.camera = ToMessage(Camera());
  auto bytes = Encode(m);
  EXPECT_TRUE(DecodeSessionControl(bytes.data(), bytes.size()).ok());
  m.camera.height = 0;
  bytes = Encode(m);
  EXPECT_EQ(DecodeSessionControl(bytes.data(), bytes.size()).reason(), DropReason::kBadCamera);
  m.type = 99;
  bytes = Encode(m);
  EXPECT_EQ(DecodeSessionControl(bytes.data(), bytes.size()).reason(),
            DropReason::kBadSessionMessage);
}

// Big-endian int32 at `offset`, as lcm encodes lengths and counts.
void PutI32(std::vector<uint8_t>* bytes, size_t offset, uint32_t value) {
  for (int i = 0; i < 4; ++i) (*bytes)[offset + i] = static_cast<uint8_t>(value >> (24 - 8 * i));
}

std::vector<uint8_t> EncodedSessionControl(const std::string& client_name,
                                           const std::string& reason) {
  session_control_t m{};
  m.version = session_control_t::VERSION;
  m.type = session_control_t::HELLO;
  m.client_name = client_name;
  m.reason = reason;
  m.camera = ToMessage(Camera());
  return Encode(m);
}

// client_name's length field: after the hash, version, type and four int64.
constexpr size_t kClientNameLengthOffset = 8 + 2 + 1 + 4 * 8;

TEST(WireFormatTest, SessionControlWithStringLengthInt32MinIsBadBytes) {
  // The message of the security review (115 bytes then, 120 with the empty map group): a
  // two-character client name whose length field says 0x80000000 (lcm-gen's decoder computes
  // len - 1 on it and reads 2 GiB).
  std::vector<uint8_t> bytes = EncodedSessionControl("m2", "");
  ASSERT_EQ(bytes.size(), 120u);
  ASSERT_TRUE(DecodeSessionControl(bytes.data(), bytes.size()).ok());
  PutI32(&bytes, kClientNameLengthOffset, 0x80000000u);
  const auto decoded = DecodeSessionControl(bytes.data(), bytes.size());
  ASSERT_FALSE(decoded.ok());
  EXPECT_EQ(decoded.reason(), DropReason::kBadBytes);
  EXPECT_NE(decoded.error().find("string length -2147483648"), std::string::npos)
      << decoded.error();
}

TEST(WireFormatTest, SessionControlStringLengthsAreCheckedAgainstTheBytesLeft) {
  const std::vector<uint8_t> good = EncodedSessionControl("quest", "why");
  ASSERT_TRUE(DecodeSessionControl(good.data(), good.size()).ok());
  const size_t name_at = kClientNameLengthOffset;  // length 6: "quest" and its NUL
  const size_t reason_at = name_at + 4 + 6;        // length 4: "why" and its NUL
  const std::pair<size_t, int32_t> fields[] = {{name_at, 6}, {reason_at, 4}};
  for (const auto& [offset, length] : fields) {
    const int32_t left = static_cast<int32_t>(good.size() - offset - 4);
    for (int32_t tampered : {0, -1, INT32_MIN, INT32_MAX, length - 1, length + 1, left, left + 1}) {
      std::vector<uint8_t> bytes = good;
      PutI32(&bytes, offset, static_cast<uint32_t>(tampered));
      const auto decoded = DecodeSessionControl(bytes.data(), bytes.size());
      ASSERT_FALSE(decoded.ok()) << offset << " " << tampered;
      EXPECT_EQ(decoded.reason(), DropReason::kBadBytes) << offset << " " << tampered;
    }
    // The byte the length points at is not the NUL.
    std::vector<uint8_t> bytes = good;
    bytes[offset + 4 + static_cast<size_t>(length) - 1] = 'x';
    const auto decoded = DecodeSessionControl(bytes.data(), bytes.size());
    EXPECT_EQ(decoded.reason(), DropReason::kBadBytes);
    EXPECT_NE(decoded.error().find("NUL"), std::string::npos) << decoded.error();
  }
  std::vector<uint8_t> longer = good;
  longer.push_back(0);
  EXPECT_EQ(DecodeSessionControl(longer.data(), longer.size()).reason(), DropReason::kBadBytes);
  for (size_t n = 0; n < good.size(); ++n) {
    EXPECT_EQ(DecodeSessionControl(good.data(), n).reason(), DropReason::kBadBytes) << n;
  }
}

TEST(WireFormatTest, PoseEstimateHasItsExactSize) {
  pose_estimate_t pose{};
  pose.version = pose_estimate_t::VERSION;
  pose.world_from_camera = ToMessage(Pose3());
  pose.map_id = 7;
  std::vector<uint8_t> bytes = Encode(pose);
  // 8 (type hash) + 2 + 5 * 8 + 1 + 7 * 8 (pose) + 2 * 4 + 1 + 4 + 8 + 4 (map_id).
  ASSERT_EQ(bytes.size(), 132u);
  const auto decoded = DecodePoseEstimate(bytes.data(), bytes.size());
  ASSERT_TRUE(decoded.ok()) << decoded.error();
  EXPECT_EQ(decoded->map_id, 7);
  for (size_t n = 0; n < bytes.size(); ++n) {
    EXPECT_EQ(DecodePoseEstimate(bytes.data(), n).reason(), DropReason::kBadBytes) << n;
  }
  bytes.push_back(0);
  const auto longer = DecodePoseEstimate(bytes.data(), bytes.size());
  EXPECT_EQ(longer.reason(), DropReason::kBadBytes);
  EXPECT_NE(longer.error().find("1 trailing bytes"), std::string::npos) << longer.error();
}

TEST(WireFormatTest, ServerStatsStringsAndCountsAreChecked) {
  server_stats_t stats{};
  stats.version = server_stats_t::VERSION;
  stats.num_drop_reasons = 2;
  stats.drop_reasons = {"bad_bytes", "stale"};
  stats.drop_counts = {3, 4};
  const std::vector<uint8_t> good = Encode(stats);
  const auto decoded = DecodeServerStats(good.data(), good.size());
  ASSERT_TRUE(decoded.ok()) << decoded.error();
  EXPECT_EQ(decoded->drop_reasons[1], "stale");
  const size_t count_at = 8 + 2 + 8 + 8 + 4 + 3 * 8;
  const size_t first_string_at = count_at + 4;  // length 10: "bad_bytes" and its NUL
  for (const auto& [offset, tampered] :
       std::vector<std::pair<size_t, uint32_t>>{{count_at, 0x80000000u},
                                                {count_at, 0xffffffffu},
                                                {count_at, 3},
                                                {first_string_at, 0x80000000u},
                                                {first_string_at, 0},
                                                {first_string_at, 9},
                                                {first_string_at, 0x7fffffffu}}) {
    std::vector<uint8_t> bytes = good;
    PutI32(&bytes, offset, tampered);
    EXPECT_EQ(DecodeServerStats(bytes.data(), bytes.size()).reason(), DropReason::kBadBytes)
        << offset << " " << tampered;
  }
}

TEST(WireFormatTest, AnyTamperedInt32NeverCrashesADecoder) {
  map_delta_t delta{};
  delta.version = map_delta_t::VERSION;
  delta.num_keyframes = 1;
  delta.keyframes.resize(1);
  delta.keyframes[0].world_from_camera = ToMessage(Pose3());
  delta.num_removed_keyframes = 1;
  delta.removed_keyframes = {3};
  delta.num_points = 1;
  delta.point_ids = {1};
  delta.point_xyz = {{0, 1, 2}};
  delta.num_removed_points = 1;
  delta.removed_points = {4};
  server_stats_t stats{};
  stats.version = server_stats_t::VERSION;
  stats.num_drop_reasons = 1;
  stats.drop_reasons = {"stale"};
  stats.drop_counts = {1};
  pose_estimate_t pose{};
  pose.version = pose_estimate_t::VERSION;
  pose.world_from_camera = ToMessage(Pose3());
  const std::vector<std::vector<uint8_t>> messages = {
      EncodeFeatureFrame(RandomFrame(640, 480, 3, 6)), EncodedSessionControl("quest", "why"),
      Encode(delta), Encode(stats), Encode(pose)};
  for (const std::vector<uint8_t>& good : messages) {
    for (size_t offset = 8; offset + 4 <= good.size(); ++offset) {
      for (uint32_t tampered : {0x80000000u, 0xffffffffu, 0x7fffffffu, 0u, 1u}) {
        std::vector<uint8_t> bytes = good;
        PutI32(&bytes, offset, tampered);
        // Decoding must fail cleanly or succeed; each decoder sees every message.
        (void)DecodeFeatureFrame(bytes.data(), bytes.size(), {});
        (void)DecodeSessionControl(bytes.data(), bytes.size());
        (void)DecodeMapDelta(bytes.data(), bytes.size());
        (void)DecodeServerStats(bytes.data(), bytes.size());
        (void)DecodePoseEstimate(bytes.data(), bytes.size());
      }
    }
  }
}

TEST(WireFormatTest, SessionControlCarriesTheMapGroup) {
  session_control_t m{};
  m.version = session_control_t::VERSION;
  m.type = session_control_t::HELLO;
  m.camera = ToMessage(Camera());
  const std::string longest(kMaxMapGroupName, 'g');
  for (const std::string& name : {std::string(), std::string("room-A_2.b"), longest}) {
    m.map_group = name;
    const std::vector<uint8_t> bytes = Encode(m);
    const auto decoded = DecodeSessionControl(bytes.data(), bytes.size());
    ASSERT_TRUE(decoded.ok()) << decoded.error();
    EXPECT_EQ(decoded->map_group, name);
  }
  // Too long, or a character outside [A-Za-z0-9_.-]: dropped as kBadGroupName, whatever the
  // message type, with a message that says what is wrong.
  const std::pair<std::string, std::string> bad[] = {{longest + "g", "65 characters"},
                                                     {"room a", "character code 32"},
                                                     {"room/a", "character code 47"},
                                                     {"caf\xc3\xa9", "character code 195"},
                                                     {"a\nb", "character code 10"}};
  for (const int8_t type : {session_control_t::HELLO, session_control_t::BYE}) {
    m.type = type;
    for (const auto& [name, says] : bad) {
      m.map_group = name;
      const std::vector<uint8_t> bytes = Encode(m);
      const auto decoded = DecodeSessionControl(bytes.data(), bytes.size());
      ASSERT_FALSE(decoded.ok()) << name;
      EXPECT_EQ(decoded.reason(), DropReason::kBadGroupName) << name;
      EXPECT_NE(decoded.error().find(says), std::string::npos) << decoded.error();
      EXPECT_NE(decoded.error().find("map group"), std::string::npos) << decoded.error();
    }
  }
  EXPECT_STREQ(ToString(DropReason::kBadGroupName), "bad_group_name");
}

TEST(WireFormatTest, MapDeltaKeyframesCarryOwnership) {
  map_delta_t delta{};
  delta.version = map_delta_t::VERSION;
  delta.num_keyframes = 2;
  delta.keyframes.resize(2);
  for (int i = 0; i < 2; ++i) {
    delta.keyframes[i].id = 10 + i;
    delta.keyframes[i].world_from_camera = ToMessage(Pose3());
    delta.keyframes[i].own = i == 0;
  }
  const std::vector<uint8_t> bytes = Encode(delta);
  const auto decoded = DecodeMapDelta(bytes.data(), bytes.size());
  ASSERT_TRUE(decoded.ok()) << decoded.error();
  ASSERT_EQ(decoded->keyframes.size(), 2u);
  EXPECT_TRUE(decoded->keyframes[0].own);
  EXPECT_FALSE(decoded->keyframes[1].own);
  // Each keyframe is 4 + 8 + 56 + 1 bytes: a delta cut inside the last one is bad bytes.
  EXPECT_EQ(DecodeMapDelta(bytes.data(), bytes.size() - 4 * 4 - 1).reason(), DropReason::kBadBytes);
}

TEST(WireFormatTest, MapDeltaCountsAreCheckedAgainstTheBytesLeft) {
  map_delta_t delta{};
  delta.version = map_delta_t::VERSION;
  delta.num_removed_keyframes = 1;
  delta.removed_keyframes = {3};
  const std::vector<uint8_t> good = Encode(delta);
  ASSERT_TRUE(DecodeMapDelta(good.data(), good.size()).ok());
  const size_t removed_at = 8 + 2 + 4 * 8 + 1 + 4;  // after the empty keyframe array
  for (uint32_t tampered : {0x80000000u, 0xffffffffu, 0u, 2u}) {
    std::vector<uint8_t> bytes = good;
    PutI32(&bytes, removed_at, tampered);
    EXPECT_EQ(DecodeMapDelta(bytes.data(), bytes.size()).reason(), DropReason::kBadBytes)
        << tampered;
  }
}

TEST(WireFormatTest, QuaternionWhoseNormOverflowsIsRejected) {
  // Found by fuzz_feature_frame: |q| overflows to infinity and q / |q| is a zero rotation.
  pose_t m = ToMessage(Pose3());
  m.q[1] = -1.16e257;
  EXPECT_EQ(FromMessage(m).reason(), DropReason::kNonFinite);
  feature_frame_t frame = ToMessage(RandomFrame(640, 480, 5, 8));
  frame.ground_truth_world_from_camera.q[2] = 1e200;
  EXPECT_EQ(ReasonFor(frame), DropReason::kNonFinite);
}

}  // namespace
}  // namespace m2s::wire
