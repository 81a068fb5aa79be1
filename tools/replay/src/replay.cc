#include "m2s/replay/replay.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
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

}  // namespace

Expected<ReplayResult> Replay(const ReplayOptions& options) {
  std::error_code ec;
  const auto file_size = std::filesystem::file_size(options.log_path, ec);
  if (ec) return Status::Error("cannot read log " + options.log_path + ": " + ec.message());
  std::ifstream log_file(options.log_path, std::ios::binary);
  if (!log_file) return Status::Error("cannot open log " + options.log_path);
  wire::LcmLogReader log(&log_file, file_size);

  ReplayResult result;
  std::map<int64_t, SessionState> sessions;
  std::mutex mutex;  // the publish callback runs in this thread; kept for clarity of ownership
  auto now_us = [] { return wire::WallClockMicros(); };

  server_app::ServerOptions server_options = options.server;
  server_options.synchronous = true;
  server_options.slam.deterministic = true;
  server_options.max_sessions = std::max(server_options.max_sessions, 64);
  auto on_publish = [&](const std::string& channel, std::vector<uint8_t> bytes) {
    std::lock_guard<std::mutex> lock(mutex);
    if (channel == wire::kPoseChannel) {
      auto pose = wire::DecodePoseEstimate(bytes.data(), bytes.size());
      if (!pose) return;
      auto it = sessions.find(pose->session_id);
      if (it == sessions.end()) return;
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
      r.latency_ms = static_cast<double>(now_us() - pose->frame_send_wall_us) * 1e-3;
    } else if (channel == wire::kMapChannel) {
      auto delta = wire::DecodeMapDelta(bytes.data(), bytes.size());
      if (!delta) return;
      auto it = sessions.find(delta->session_id);
      if (it != sessions.end()) it->second.replica.Apply(*delta);
    }
  };
  server_app::SessionManager manager(server_options, on_publish);

  wire::LcmLogEvent event;
  while (true) {
    const uint64_t position = log.position();  // the end of the previous event
    if (!log.Next(&event)) {
      if (!log.error().empty()) {
        result.log_problem = "log " + options.log_path + " broken at byte " +
                             std::to_string(position) + " of " + std::to_string(file_size) +
                             " (after " + std::to_string(result.events) +
                             " events): truncated or corrupt event (" + log.error() +
                             "); the events before it are used";
      }
      break;
    }
    if (event.skipped_bytes > 0 && result.log_problem.empty()) {
      result.log_problem = "log " + options.log_path + " corrupt at byte " +
                           std::to_string(position) + ": " + std::to_string(event.skipped_bytes) +
                           " bytes skipped to the next valid event";
    }
    ++result.events;
    const uint8_t* data = event.data.data();
    const size_t size = event.data.size();
    if (event.channel == wire::kFrameChannel) {
      auto frame = wire::DecodeFeatureFrame(data, size, {server_options.max_features});
      if (frame) {
        std::lock_guard<std::mutex> lock(mutex);
        auto [it, inserted] = sessions.try_emplace(frame->session_id);
        SessionState& s = it->second;
        if (inserted) s.replica.Reset(frame->session_id);
        if (!s.by_seq.count(frame->seq)) {
          client::FrameRecord r;
          r.seq = frame->seq;
          r.session_id = frame->session_id;
          r.capture_time_us = frame->capture_time_us;
          r.ground_truth_world_from_camera = frame->ground_truth_world_from_camera;
          r.num_features = static_cast<int>(frame->features.size());
          r.encoded_bytes = size;
          r.send_wall_us = now_us();
          s.by_seq[frame->seq] = s.records.size();
          s.records.push_back(r);
          s.camera = frame->camera;
        }
      }
      ++result.frames;
      // The send time of the replayed frame is now (latency = replay processing time).
      if (frame) {
        frame->send_wall_us = now_us();
        const std::vector<uint8_t> bytes = wire::EncodeFeatureFrame(*frame);
        manager.HandleMessage(event.channel, bytes.data(), bytes.size());
      } else {
        manager.HandleMessage(event.channel, data, size);
      }
    } else if (event.channel == wire::kSessionChannel) {
      manager.HandleMessage(event.channel, data, size);
    }
  }
  manager.Drain();
  result.server = manager.Counters();

  // The session with the most frames is the run's.
  const SessionState* best = nullptr;
  for (const auto& [id, s] : sessions) {
    if (!best || s.records.size() > best->records.size()) {
      best = &s;
      result.evaluated_session = id;
    }
  }
  if (!best) {
    return Status::Error("log " + options.log_path + " holds no valid frame" +
                         (result.log_problem.empty() ? "" : " (" + result.log_problem + ")"));
  }
  auto loaded_scene = LoadSceneOrDefault(options.mesh_path);
  if (!loaded_scene) return loaded_scene.status();
  Scene scene = std::move(*loaded_scene);
  headless::RunInfo info;
  info.projector = "replay";
  info.transport = "replay";
  info.fast = true;
  info.frames_total = static_cast<int64_t>(best->records.size());
  info.sessions = static_cast<int64_t>(sessions.size());
  info.render_map = options.render_map;
  if (best->records.size() >= 2) {
    const double span = static_cast<double>(best->records.back().capture_time_us -
                                            best->records.front().capture_time_us) *
                        1e-6;
    if (span > 0) info.fps = static_cast<double>(best->records.size() - 1) / span;
  }
  auto metrics = headless::WriteRunOutputs(options.out_dir, best->records, best->replica.Snapshot(),
                                           &scene, best->camera, info);
  if (!metrics) return metrics.status();
  result.metrics = std::move(*metrics);
  return result;
}

}  // namespace m2s::replay
