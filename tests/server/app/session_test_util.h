// What the session manager tests share: the messages a manager publishes, decoded, and the
// frames and session messages a client sends.
#pragma once

#include <chrono>
#include <mutex>
#include <string>
#include <vector>

#include "m2s/common/wire_format.h"
#include "m2s/server_app/session_manager.h"

namespace m2s::server_app {

struct Published {
  std::mutex mutex;
  std::vector<pose_estimate_t> poses;
  std::vector<map_delta_t> maps;
  std::vector<session_control_t> control;
  void Add(const std::string& channel, const std::vector<uint8_t>& b) {
    std::lock_guard<std::mutex> lock(mutex);
    if (channel == wire::kPoseChannel)
      poses.push_back(*wire::DecodePoseEstimate(b.data(), b.size()));
    if (channel == wire::kMapChannel) maps.push_back(*wire::DecodeMapDelta(b.data(), b.size()));
    if (channel == wire::kSessionChannel) {
      control.push_back(*wire::DecodeSessionControl(b.data(), b.size()));
    }
  }
};

inline ServerOptions SyncOptions() {
  ServerOptions options;
  options.synchronous = true;
  options.max_sessions = 2;
  options.drop_log_period_s = 100;
  return options;
}

inline wire::FeatureFrame Frame(int64_t session, int64_t seq) {
  wire::FeatureFrame f;
  f.session_id = session;
  f.seq = seq;
  f.capture_time_us = seq % (int64_t{1} << 40) * 100000;  // no overflow at the largest seqs
  f.camera = Camera();
  f.features = {{1, {10.f, 20.f}}, {2, {30.f, 40.f}}};
  f.ground_truth_world_from_camera =
      Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(seq, 0, 0));
  return f;
}

inline std::vector<uint8_t> Control(int8_t type, int64_t session) {
  session_control_t m{};
  m.version = session_control_t::VERSION;
  m.type = type;
  m.session_id = session;
  m.camera = wire::ToMessage(Camera());
  return wire::Encode(m);
}

// The session manager's clock in tests (ServerOptions::clock): moves only when told.
struct ManualClock {
  std::chrono::steady_clock::time_point now{};
  void Advance(double seconds) {
    now += std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(seconds));
  }
};

}  // namespace m2s::server_app
