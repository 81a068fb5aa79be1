// Writes the seed corpus of the fuzz targets (tests/fuzz/corpus/<target>/) and the
// regression inputs of the bugs the targets were written for (tests/fuzz/regressions/):
//   fuzz_make_corpus tests/fuzz
// The output is committed; rerun after a wire or file format change.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz_targets.h"
#include "m2s/common/bus_auth.h"
#include "m2s/common/lcm_log.h"
#include "m2s/common/wire_format.h"
#include "map/map.h"

namespace m2s::fuzz {
namespace {

namespace fs = std::filesystem;

void Write(const fs::path& path, const std::vector<uint8_t>& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  std::printf("%6zu  %s\n", bytes.size(), path.string().c_str());
}

void PutI32(std::vector<uint8_t>* bytes, size_t offset, uint32_t value) {
  for (int i = 0; i < 4; ++i) (*bytes)[offset + i] = static_cast<uint8_t>(value >> (24 - 8 * i));
}

wire::FeatureFrame Frame(int width, int height, int n, bool ground_truth) {
  wire::FeatureFrame frame;
  frame.session_id = 0x1234;
  frame.seq = 3;
  frame.capture_time_us = 100000;
  frame.send_wall_us = 1700000000000000;
  frame.camera = Camera::FromHorizontalFov(width, height, 90.0);
  for (int i = 0; i < n; ++i) {
    frame.features.push_back({static_cast<VertexId>(7 * i + 2),
                              Eigen::Vector2f((i * 37) % width + 0.25f, (i * 53) % height + 0.5f)});
  }
  if (ground_truth) {
    frame.ground_truth_world_from_camera =
        Pose3(Eigen::Quaterniond(0.9, 0.1, -0.3, 0.2), Eigen::Vector3d(0.5, -1, 2));
  }
  return frame;
}

session_control_t Session(int8_t type, const std::string& name, const std::string& reason,
                          const std::string& map_group = "") {
  session_control_t m{};
  m.version = session_control_t::VERSION;
  m.type = type;
  m.session_id = 0x1234;
  m.wall_us = 1700000000000000;
  m.client_name = name;
  m.reason = reason;
  m.camera = wire::ToMessage(Camera());
  m.map_group = map_group;
  return m;
}

pose_estimate_t PoseEstimate(int8_t state) {
  pose_estimate_t m{};
  m.version = pose_estimate_t::VERSION;
  m.session_id = 0x1234;
  m.seq = 3;
  m.state = state;
  m.world_from_camera = wire::ToMessage(Pose3(Eigen::Quaterniond(1, 0, 0, 0), {1, 2, 3}));
  m.num_features = 200;
  m.num_inliers = 150;
  m.tracking_ms = 2.5f;
  m.map_revision = 9;
  return m;
}

map_delta_t MapDelta(bool empty) {
  map_delta_t m{};
  m.version = map_delta_t::VERSION;
  m.session_id = 0x1234;
  m.revision = 2;
  m.base_revision = 1;
  if (empty) return m;
  m.num_keyframes = 2;
  m.keyframes.resize(2);
  for (int i = 0; i < 2; ++i) {
    m.keyframes[i].id = i;
    m.keyframes[i].world_from_camera = wire::ToMessage(Pose3());
    m.keyframes[i].own = i == 0;
  }
  m.num_removed_keyframes = 1;
  m.removed_keyframes = {5};
  m.num_points = 3;
  m.point_ids = {1, 2, 3};
  m.point_xyz = {{0, 1, 2}, {1, 1, 1}, {-1, 0, 4}};
  m.num_removed_points = 1;
  m.removed_points = {9};
  return m;
}

server_stats_t ServerStats(bool empty) {
  server_stats_t m{};
  m.version = server_stats_t::VERSION;
  m.frames_in = 100;
  m.frames_processed = 98;
  if (empty) return m;
  m.num_drop_reasons = 2;
  m.drop_reasons = {"bad_bytes", "stale"};
  m.drop_counts = {1, 1};
  return m;
}

// A small map for the default camera: keyframes 0..2 (keyframe 1 removed, linked to 0),
// points observed by both survivors.
std::vector<uint8_t> MapFile(bool empty) {
  slam::Map map;
  if (!empty) {
    map.Write([](slam::MapData& m) {
      for (KeyframeId k = 0; k < 3; ++k) {
        slam::Keyframe kf;
        kf.id = k;
        kf.seq = k;
        kf.timestamp = 0.1 * k;
        kf.world_from_camera =
            Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * k, 0, 0));
        for (VertexId v = 0; v < 5; ++v) {
          kf.ids.push_back(v);
          kf.uvs.emplace_back(100.0 + 10 * v, 200.0 + k);
        }
        m.AddKeyframe(std::move(kf));
      }
      for (VertexId v = 0; v < 4; ++v) {
        m.AddPoint(v, Eigen::Vector3d(v, 0.5, 3), 0);
        m.AddObservation(v, 0);
        m.AddObservation(v, 2);
      }
      m.RemoveKeyframe(1, slam::KeyframeLink{0, Pose3()});
    });
  }
  const fs::path path = fs::temp_directory_path() / "m2s_fuzz_seed.m2smap";
  if (!map.Save(path.string(), Camera()).ok()) std::abort();
  std::ifstream in(path, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
  fs::remove(path);
  return bytes;
}

// The map file of the security review: 2^28 keyframes announced, the first one announcing
// 2^28 features, 148 bytes in all.
std::vector<uint8_t> HugeCountMapFile() {
  std::vector<uint8_t> bytes = MapFile(/*empty=*/true);
  bytes.resize(56);  // magic, version, camera, next keyframe id
  auto append = [&bytes](const auto& value) {
    const auto* p = reinterpret_cast<const uint8_t*>(&value);
    bytes.insert(bytes.end(), p, p + sizeof(value));
  };
  append(uint64_t{1} << 28);  // keyframes
  append(uint32_t{0});
  append(int64_t{0});
  append(0.0);
  for (double v : {0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0}) append(v);
  append(uint64_t{1} << 28);  // features of the first keyframe
  return bytes;
}

// Three events; with `garbage`, bytes before the first one (skipped by the reader).
std::vector<uint8_t> Log(bool garbage) {
  std::vector<uint8_t> log;
  const std::vector<std::pair<std::string, std::vector<uint8_t>>> events = {
      {wire::kSessionChannel, wire::Encode(Session(session_control_t::HELLO, "fuzz", ""))},
      {wire::kFrameChannel, wire::EncodeFeatureFrame(Frame(120, 90, 3, false))},
      {wire::kPoseChannel, wire::Encode(PoseEstimate(pose_estimate_t::STATE_OK))}};
  for (size_t i = 0; i < events.size(); ++i) {
    if (garbage && i == 0) log.insert(log.end(), {0x5a, 0xED, 0xA1, 0xDA});
    wire::LcmLogEvent event;
    event.event_number = static_cast<int64_t>(i);
    event.timestamp_us = 1700000000000000 + 100000 * static_cast<int64_t>(i);
    event.channel = events[i].first;
    event.data = events[i].second;
    wire::AppendLcmLogEvent(event, &log);
  }
  return log;
}

std::vector<uint8_t> Sealed(bool encrypt, const std::vector<uint8_t>& payload) {
  const wire::BusKey key = *wire::BusKeyFromBytes(kFuzzBusKeyBytes, sizeof(kFuzzBusKeyBytes));
  const wire::BusSealer sealer(key, encrypt, /*sender_id=*/0x5eed);
  return sealer.Seal(kFuzzBusChannel, payload.data(), payload.size(), kFuzzBusNowUs);
}

int Main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_make_corpus TESTS_FUZZ_DIR\n");
    return 2;
  }
  const fs::path corpus = fs::path(argv[1]) / "corpus";
  const fs::path regressions = fs::path(argv[1]) / "regressions";
  Write(corpus / "feature_frame" / "640x480_5_ground_truth.bin",
        wire::EncodeFeatureFrame(Frame(640, 480, 5, true)));
  Write(corpus / "feature_frame" / "120x90_20.bin",
        wire::EncodeFeatureFrame(Frame(120, 90, 20, false)));
  Write(corpus / "feature_frame" / "empty.bin", wire::EncodeFeatureFrame(Frame(64, 48, 0, false)));
  Write(corpus / "session_control" / "hello.bin",
        wire::Encode(Session(session_control_t::HELLO, "quest", "")));
  Write(corpus / "session_control" / "hello_map_group.bin",
        wire::Encode(Session(session_control_t::HELLO, "quest", "", "room-a_2.b")));
  Write(corpus / "session_control" / "bye.bin",
        wire::Encode(Session(session_control_t::BYE, "", "")));
  Write(corpus / "session_control" / "rejected.bin",
        wire::Encode(Session(session_control_t::REJECTED, "server", "max sessions")));
  Write(corpus / "pose_estimate" / "ok.bin", wire::Encode(PoseEstimate(pose_estimate_t::STATE_OK)));
  Write(corpus / "pose_estimate" / "lost.bin",
        wire::Encode(PoseEstimate(pose_estimate_t::STATE_LOST)));
  Write(corpus / "map_delta" / "empty.bin", wire::Encode(MapDelta(true)));
  Write(corpus / "map_delta" / "small.bin", wire::Encode(MapDelta(false)));
  Write(corpus / "server_stats" / "empty.bin", wire::Encode(ServerStats(true)));
  Write(corpus / "server_stats" / "two_reasons.bin", wire::Encode(ServerStats(false)));
  Write(corpus / "map_file" / "empty.m2smap", MapFile(true));
  Write(corpus / "map_file" / "small.m2smap", MapFile(false));
  Write(corpus / "lcm_log" / "three_events.lcmlog", Log(false));
  Write(corpus / "lcm_log" / "leading_garbage.lcmlog", Log(true));
  Write(corpus / "bus_envelope" / "plain_frame.bin",
        Sealed(false, wire::EncodeFeatureFrame(Frame(120, 90, 3, false))));
  Write(corpus / "bus_envelope" / "encrypted_session.bin",
        Sealed(true, wire::Encode(Session(session_control_t::HELLO, "quest", ""))));
  Write(corpus / "bus_envelope" / "empty_payload.bin", Sealed(false, {}));

  std::vector<uint8_t> crash = wire::Encode(Session(session_control_t::HELLO, "m2", ""));
  PutI32(&crash, 8 + 2 + 1 + 4 * 8, 0x80000000u);  // client_name's length
  Write(regressions / "session_control_len_int32_min.bin", crash);
  Write(regressions / "map_file_count_2pow28.bin", HugeCountMapFile());
  std::vector<uint8_t> log = Log(false);
  PutI32(&log, 24, 0x7fffffffu);  // the first event's data length
  Write(regressions / "lcm_log_data_len_int32_max.bin", log);
  return 0;
}

}  // namespace
}  // namespace m2s::fuzz

int main(int argc, char** argv) { return m2s::fuzz::Main(argc, argv); }
