// bus_attacker: a stray publisher on the LCM bus, for the system tests. It never has the bus
// key. It watches the bus until a victim sends frames, then, every round:
//   * the decoder crash message (a session_control_t whose string length is 0x80000000),
//   * RESET and BYE for the victim's session, a frame with seq INT64_MAX - 1 for it,
//   * a forged pose estimate and SESSION_ENDED to the victim client, eight HELLOs,
//   * replays of messages it captured from the victim and the server (authentic ones),
// and writes what it sent, per receiver, as JSON when it stops (--rounds or a victim BYE).
//
//   bus_attacker --lcm-url URL --report attack.json [--rounds N] [--period-ms MS]
//                [--crash-only]
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <thread>

#include <CLI/CLI.hpp>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "m2s/common/bus_auth.h"
#include "m2s/common/wire_format.h"
#include "m2s/server_app/messages.h"

namespace {

using namespace m2s;

struct Captured {
  std::string channel;
  std::vector<uint8_t> bytes;
};

// What the attacker learnt from the bus.
class Watcher {
 public:
  void OnRaw(const lcm::ReceiveBuffer* buffer, const std::string& channel) {
    const auto* data = static_cast<const uint8_t*>(buffer->data);
    std::vector<uint8_t> bytes(data, data + buffer->data_size);
    std::lock_guard<std::mutex> lock(mutex_);
    if (own_.count(bytes)) return;  // our own messages come back
    // An envelope's payload is in the clear unless encrypted: read the ids from it.
    const uint8_t* payload = data;
    size_t size = bytes.size();
    if (size > wire::kEnvelopeOverhead && std::memcmp(data, "M2SB", 4) == 0 && data[5] == 0) {
      payload += wire::kEnvelopeHeaderBytes;
      size -= wire::kEnvelopeOverhead;
    }
    if (channel == wire::kFrameChannel) {
      if (auto f = wire::DecodeFeatureFrame(payload, size, {})) {
        victim_session_ = f->session_id;
        victim_seq_ = f->seq;
        victim_seen_.notify_all();
      }
    } else if (channel == wire::kPoseChannel) {
      if (auto p = wire::DecodePoseEstimate(payload, size)) server_instance_ = p->server_instance;
    } else if (channel == wire::kSessionChannel) {
      auto m = wire::DecodeSessionControl(payload, size);
      if (m && m->type == session_control_t::BYE && victim_session_ &&
          m->session_id == *victim_session_) {
        victim_left_ = true;
      }
    }
    auto& per_channel = captured_[channel];
    if (per_channel.size() < kKeepPerChannel) per_channel.push_back({channel, bytes});
  }
  void MarkOwn(const std::vector<uint8_t>& bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    own_[bytes] = true;
  }
  // Up to `n` captured messages per channel, taken out of the capture.
  std::vector<Captured> TakeReplays(size_t n) {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<Captured> out;
    for (auto& [channel, list] : captured_) {
      for (size_t i = 0; i < n && !list.empty(); ++i) {
        out.push_back(std::move(list.back()));
        list.pop_back();
      }
    }
    return out;
  }
  // Waits until a victim's frame has been seen, at most `timeout`; its session, if any.
  std::optional<int64_t> WaitForVictim(std::chrono::seconds timeout) {
    std::unique_lock<std::mutex> lock(mutex_);
    victim_seen_.wait_for(lock, timeout, [&] { return victim_session_.has_value(); });
    return victim_session_;
  }
  int64_t server_instance() {
    std::lock_guard<std::mutex> lock(mutex_);
    return server_instance_;
  }
  bool victim_left() {
    std::lock_guard<std::mutex> lock(mutex_);
    return victim_left_;
  }

 private:
  static constexpr size_t kKeepPerChannel = 64;
  std::mutex mutex_;
  std::condition_variable victim_seen_;
  std::map<std::string, std::vector<Captured>> captured_;
  std::map<std::vector<uint8_t>, bool> own_;
  std::optional<int64_t> victim_session_;
  int64_t victim_seq_ = 0;
  int64_t server_instance_ = 0;
  bool victim_left_ = false;
};

// The 115-byte message that killed lcm-gen's decoder.
std::vector<uint8_t> CrashMessage() {
  session_control_t m{};
  m.version = session_control_t::VERSION;
  m.type = session_control_t::HELLO;
  m.camera = wire::ToMessage(Camera());
  std::vector<uint8_t> bytes = wire::Encode(m);
  const size_t name_length_at = 8 + 2 + 1 + 4 * 8;  // hash, version, type, 4 int64
  bytes[name_length_at] = 0x80;
  bytes[name_length_at + 1] = bytes[name_length_at + 2] = bytes[name_length_at + 3] = 0;
  return bytes;
}

session_control_t Control(int8_t type, int64_t session, int64_t instance) {
  session_control_t m = server_app::MakeSessionMessage(type, session, instance);
  m.camera = wire::ToMessage(Camera());
  return m;
}

struct Tally {
  int64_t to_server_forged = 0;    // on M2S_FRAME / M2S_SESSION, no valid tag
  int64_t to_server_replayed = 0;  // on M2S_FRAME / M2S_SESSION, authentic but seen before
  int64_t to_client_forged = 0;    // on M2S_POSE / M2S_MAP / M2S_SESSION / M2S_STATS
  int64_t to_client_replayed = 0;
  int64_t rounds = 0;
};

bool ToServer(const std::string& channel) {
  return channel == wire::kFrameChannel || channel == wire::kSessionChannel;
}
bool ToClient(const std::string& channel) { return channel != wire::kFrameChannel; }

}  // namespace

int main(int argc, char** argv) {
  std::string url = wire::kDefaultLcmUrl, report;
  int rounds = 40, period_ms = 150;
  bool crash_only = false;
  CLI::App app{"A stray publisher on the Mesh2SLAM bus (tests only)"};
  app.add_option("--lcm-url", url, "LCM URL");
  app.add_option("--report", report, "Write what was sent here (JSON)")->required();
  app.add_option("--rounds", rounds, "Rounds of attack at most");
  app.add_option("--period-ms", period_ms, "Milliseconds between rounds");
  app.add_flag("--crash-only", crash_only, "Send only the decoder crash message");
  CLI11_PARSE(app, argc, argv);

  lcm::LCM lcm(url);
  if (!lcm.good()) {
    std::cerr << "bus_attacker: cannot open " << url << "\n";
    return 2;
  }
  Watcher watcher;
  for (const char* channel : {wire::kFrameChannel, wire::kPoseChannel, wire::kMapChannel,
                              wire::kSessionChannel, wire::kStatsChannel}) {
    lcm.subscribe(channel, &Watcher::OnRaw, &watcher);
  }
  std::atomic<bool> stop{false};
  std::thread receiver([&] {
    while (!stop) lcm.handleTimeout(20);
  });

  Tally tally;
  auto send = [&](const std::string& channel, const std::vector<uint8_t>& bytes, bool replay) {
    if (!replay) watcher.MarkOwn(bytes);
    lcm.publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
    if (ToServer(channel)) ++(replay ? tally.to_server_replayed : tally.to_server_forged);
    if (ToClient(channel)) ++(replay ? tally.to_client_replayed : tally.to_client_forged);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));  // paces the publisher
  };
  // A fake envelope: the right shape with a made-up tag.
  std::mt19937_64 rng(7);
  auto fake_envelope = [&](const std::vector<uint8_t>& payload) {
    std::vector<uint8_t> out(wire::kEnvelopeOverhead + payload.size());
    for (auto& b : out) b = static_cast<uint8_t>(rng());
    std::memcpy(out.data(), "M2SB", 4);
    out[4] = 1;
    out[5] = 0;
    std::memcpy(out.data() + wire::kEnvelopeHeaderBytes, payload.data(), payload.size());
    return out;
  };

  const std::optional<int64_t> victim = watcher.WaitForVictim(std::chrono::seconds(60));
  for (int round = 0; victim && round < rounds && !watcher.victim_left(); ++round) {
    send(wire::kSessionChannel, CrashMessage(), false);
    if (!crash_only) {
      const int64_t session = *victim;
      const int64_t instance = watcher.server_instance();
      send(wire::kSessionChannel, wire::Encode(Control(session_control_t::RESET, session, 0)),
           false);
      send(wire::kSessionChannel,
           fake_envelope(wire::Encode(Control(session_control_t::BYE, session, 0))), false);
      wire::FeatureFrame frame;
      frame.session_id = session;
      frame.seq = INT64_MAX - 1;
      frame.features = {{1, {10.f, 10.f}}};
      send(wire::kFrameChannel, wire::EncodeFeatureFrame(frame), false);
      pose_estimate_t pose{};
      pose.version = pose_estimate_t::VERSION;
      pose.session_id = session;
      pose.server_instance = instance;
      pose.seq = 1 + round;
      pose.state = pose_estimate_t::STATE_OK;
      pose.world_from_camera =
          wire::ToMessage(Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(3.0, -2.0, 1.0)));
      send(wire::kPoseChannel, wire::Encode(pose), false);
      send(wire::kPoseChannel, fake_envelope(wire::Encode(pose)), false);
      send(wire::kSessionChannel,
           wire::Encode(Control(session_control_t::SESSION_ENDED, session, instance)), false);
      for (int h = 0; h < 8; ++h) {
        send(wire::kSessionChannel,
             wire::Encode(Control(session_control_t::HELLO, 1000 + 8 * round + h, 0)), false);
      }
      for (const Captured& c : watcher.TakeReplays(2)) send(c.channel, c.bytes, true);
    }
    ++tally.rounds;
    std::this_thread::sleep_for(std::chrono::milliseconds(period_ms));
  }
  stop = true;
  receiver.join();
  const nlohmann::json j = {{"victim_seen", victim.has_value()},
                            {"rounds", tally.rounds},
                            {"to_server_forged", tally.to_server_forged},
                            {"to_server_replayed", tally.to_server_replayed},
                            {"to_client_forged", tally.to_client_forged},
                            {"to_client_replayed", tally.to_client_replayed}};
  std::ofstream(report) << j.dump(2) << "\n";
  return victim ? 0 : 3;
}
