#include "m2s/replay/replay.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <unordered_map>

#include "m2s/client/map_replica.h"
#include "m2s/common/lcm_log.h"
#include "m2s/common/logging.h"
#include "m2s/common/scene.h"

namespace m2s::replay {
namespace {

struct SessionState {
  std::vector<client::FrameRecord> records;
  std::unordered_map<int64_t, size_t> by_seq;
  client::MapReplica replica;
  Camera camera;
};

int64_t SteadyMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// Feeds a log's frame and session messages through a synchronous SessionManager and collects
// what it publishes per session, as a live client would.
class Replayer {
 public:
  explicit Replayer(const ReplayOptions& options)
      : options_(options),
        server_options_(ForReplay(options.server)),
        manager_(server_options_, [this](const std::string& channel, std::vector<uint8_t> bytes) {
          OnPublish(channel, bytes);
        }) {}

  // Reads every event; returns where and how the log broke (empty when it did not).
  std::string Feed(wire::LcmLogReader* log, uint64_t file_size, ReplayResult* result);
  Expected<ReplayResult> Finish(ReplayResult result);

 private:
  static server_app::ServerOptions ForReplay(server_app::ServerOptions options) {
    options.synchronous = true;
    options.slam.deterministic = true;
    options.max_sessions = std::max(options.max_sessions, 64);
    return options;
  }
  void OnPublish(const std::string& channel, const std::vector<uint8_t>& bytes);
  void OnFrame(const wire::LcmLogEvent& event);

  const ReplayOptions& options_;
  const server_app::ServerOptions server_options_;
  // The publish callback runs in the feeding thread; the lock documents the shared state.
  std::mutex mutex_;
  std::map<int64_t, SessionState> sessions_;
  server_app::SessionManager manager_;
};

void Replayer::OnPublish(const std::string& channel, const std::vector<uint8_t>& bytes) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (channel == wire::kPoseChannel) {
    auto pose = wire::DecodePoseEstimate(bytes.data(), bytes.size());
    if (!pose) return;
    auto it = sessions_.find(pose->session_id);
    if (it == sessions_.end()) return;
    auto rec = it->second.by_seq.find(pose->seq);
    if (rec == it->second.by_seq.end()) return;
    client::FrameRecord& r = it->second.records[rec->second];
    auto estimate = wire::FromMessage(pose->world_from_camera);
    r.answered = true;
    r.state = pose->state;
    r.world_from_camera = estimate ? *estimate : Pose3();
    r.num_inliers = pose->num_inliers;
    r.keyframe_created = pose->keyframe_created;
    r.tracking_ms = pose->tracking_ms;
    r.latency_ms = static_cast<double>(SteadyMicros() - r.send_steady_us) * 1e-3;
  } else if (channel == wire::kMapChannel) {
    auto delta = wire::DecodeMapDelta(bytes.data(), bytes.size());
    if (!delta) return;
    auto it = sessions_.find(delta->session_id);
    if (it != sessions_.end()) it->second.replica.Apply(*delta);
  }
}

void Replayer::OnFrame(const wire::LcmLogEvent& event) {
  const uint8_t* data = event.data.data();
  const size_t size = event.data.size();
  auto frame = wire::DecodeFeatureFrame(data, size, {server_options_.max_features});
  if (!frame) {  // counted by the manager under its reason
    manager_.HandleMessage(event.channel, data, size);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto [it, inserted] = sessions_.try_emplace(frame->session_id);
    SessionState& s = it->second;
    if (inserted) s.replica.Reset(frame->session_id);
    if (!s.by_seq.count(frame->seq)) {
      client::FrameRecord r;
      r.seq = frame->seq;
      r.wire_seq = frame->seq;
      r.session_id = frame->session_id;
      r.capture_time_us = frame->capture_time_us;
      r.ground_truth_world_from_camera = frame->ground_truth_world_from_camera;
      r.num_features = static_cast<int>(frame->features.size());
      r.encoded_bytes = size;
      r.send_wall_us = wire::WallClockMicros();
      r.send_steady_us = SteadyMicros();  // latency = replay processing time
      s.by_seq[frame->seq] = s.records.size();
      s.records.push_back(r);
      s.camera = frame->camera;
    }
  }
  frame->send_wall_us = wire::WallClockMicros();
  const std::vector<uint8_t> bytes = wire::EncodeFeatureFrame(*frame);
  manager_.HandleMessage(event.channel, bytes.data(), bytes.size());
}

std::string Replayer::Feed(wire::LcmLogReader* log, uint64_t file_size, ReplayResult* result) {
  std::string problem;
  wire::LcmLogEvent event;
  while (true) {
    const uint64_t position = log->position();  // the end of the previous event
    if (!log->Next(&event)) {
      if (!log->error().empty()) {
        problem = "log " + options_.log_path + " broken at byte " + std::to_string(position) +
                  " of " + std::to_string(file_size) + " (after " + std::to_string(result->events) +
                  " events): truncated or corrupt event (" + log->error() +
                  "); the events before it are used";
      }
      break;
    }
    if (event.skipped_bytes > 0 && problem.empty()) {
      problem = "log " + options_.log_path + " corrupt at byte " + std::to_string(position) + ": " +
                std::to_string(event.skipped_bytes) + " bytes skipped to the next valid event";
    }
    ++result->events;
    if (event.channel == wire::kFrameChannel) {
      ++result->frames;
      OnFrame(event);
    } else if (event.channel == wire::kSessionChannel) {
      manager_.HandleMessage(event.channel, event.data.data(), event.data.size());
    }
  }
  manager_.Drain();
  result->server = manager_.Counters();
  return problem;
}

// The session with the most frames is the run's; its outputs are written.
Expected<ReplayResult> Replayer::Finish(ReplayResult result) {
  const SessionState* best = nullptr;
  for (const auto& [id, s] : sessions_) {
    if (!best || s.records.size() > best->records.size()) {
      best = &s;
      result.evaluated_session = id;
    }
  }
  if (!best) {
    return Status::Error("log " + options_.log_path + " holds no valid frame" +
                         (result.log_problem.empty() ? "" : " (" + result.log_problem + ")"));
  }
  auto loaded_scene = LoadSceneOrDefault(options_.mesh_path);
  if (!loaded_scene) return loaded_scene.status();
  Scene scene = std::move(*loaded_scene);
  reporting::RunInfo info;
  info.projector = "replay";
  info.transport = "replay";
  info.fast = true;
  info.frames_total = static_cast<int64_t>(best->records.size());
  info.sessions = static_cast<int64_t>(sessions_.size());
  info.render_map = options_.render_map;
  if (best->records.size() >= 2) {
    const double span = static_cast<double>(best->records.back().capture_time_us -
                                            best->records.front().capture_time_us) *
                        1e-6;
    if (span > 0) info.fps = static_cast<double>(best->records.size() - 1) / span;
  }
  auto metrics = reporting::WriteRunOutputs(options_.out_dir, best->records,
                                            best->replica.Snapshot(), &scene, best->camera, info);
  if (!metrics) return metrics.status();
  result.metrics = std::move(*metrics);
  return result;
}

}  // namespace

Expected<ReplayResult> Replay(const ReplayOptions& options) {
  std::error_code ec;
  const auto file_size = std::filesystem::file_size(options.log_path, ec);
  if (ec) return Status::Error("cannot read log " + options.log_path + ": " + ec.message());
  std::ifstream log_file(options.log_path, std::ios::binary);
  if (!log_file) return Status::Error("cannot open log " + options.log_path);
  wire::LcmLogReader log(&log_file, file_size);
  Replayer replayer(options);
  ReplayResult result;
  result.log_problem = replayer.Feed(&log, file_size, &result);
  return replayer.Finish(std::move(result));
}

}  // namespace m2s::replay
