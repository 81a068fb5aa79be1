#include "m2s/headless/headless_run.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <deque>
#include <iostream>
#include <optional>
#include <thread>

#include "m2s/client/client_session.h"
#include "m2s/client/frame_source.h"
#include "m2s/client/on_device_transport.h"
#include "m2s/client/recording_transport.h"
#include "m2s/common/cpu_projector.h"
#include "m2s/common/logging.h"
#include "m2s/common/scene.h"
#include "m2s/common/scene_editor.h"
#include "m2s/common/scene_events.h"
#include "m2s/common/trajectory.h"
#include "m2s/gpu/projector_factory.h"
#include "m2s/headless/orb_frame_source.h"
#include "m2s/plugin/plugin_system.h"

namespace m2s::headless {
namespace {

using Clock = std::chrono::steady_clock;

constexpr double kProgressPeriodS = 0.5;
constexpr double kSyncMapTimeoutS = 5.0;

Expected<std::unique_ptr<Projector>> CreateProjector(const HeadlessOptions& options,
                                                     const Scene& scene, std::string* notice,
                                                     std::string* name) {
  auto kind = ParseProjectorKind(options.projector);
  if (!kind) return kind.status();
  if (*kind == ProjectorKind::kGpu) {
    auto gpu = MakeProjector(ProjectorKind::kGpu, scene, options.projector_options, nullptr);
    if (gpu) {
      *name = "gpu";
      return gpu;
    }
    *notice = "GPU projector unavailable (" + gpu.error() + "); using the CPU projector";
  }
  *name = "cpu";
  return MakeProjector(ProjectorKind::kCpu, scene, options.projector_options, nullptr);
}

// The frames of a run: the vertex front end (projector -> FrameSource) or the ORB one.
struct FrameMaker {
  std::unique_ptr<Projector> projector;
  std::unique_ptr<client::FrameSource> vertex;
  std::unique_ptr<OrbFrameSource> orb;

  Expected<wire::FeatureFrame> Make(const Pose3& world_from_camera, int64_t capture_time_us,
                                    uint64_t frame_index, reporting::FrontEndTime* time) {
    if (orb) return orb->Make(world_from_camera, capture_time_us, time);
    auto frame = vertex->Make(world_from_camera, capture_time_us, frame_index);
    time->projection_ms = vertex->last_projection_ms();
    return frame;
  }
};

Expected<FrameMaker> CreateFrameMaker(const HeadlessOptions& options, const Scene& scene,
                                      std::string* notice, std::string* projector_name) {
  FrameMaker maker;
  if (options.front_end == "orb") {
    Expected<RenderMesh> mesh = options.mesh_path.empty()
                                    ? Expected<RenderMesh>(MakeRenderMesh(scene))
                                    : LoadRenderMesh(options.mesh_path);
    if (!mesh) return mesh.status();
    auto orb = OrbFrameSource::Create(*mesh, options.camera, options.orb);
    if (!orb) return orb.status();
    maker.orb = std::move(*orb);
    *projector_name = "none";
    return maker;
  }
  auto projector = CreateProjector(options, scene, notice, projector_name);
  if (!projector) return projector.status();
  maker.projector = std::move(*projector);
  maker.vertex = std::make_unique<client::FrameSource>(
      maker.projector.get(), options.camera, options.noise,
      static_cast<uint32_t>(scene.num_vertices()), options.send_budget);
  return maker;
}

}  // namespace

Status CheckFrontEnd(const HeadlessOptions& options) {
  if (options.front_end == "vertex") return Status::Ok();
  if (options.front_end != "orb") {
    return Status::Error("front end must be vertex or orb, not '" + options.front_end + "'");
  }
  if (options.noise.Enabled()) {
    return Status::Error(
        "the ORB front end extracts features from rendered images: the feature noise options "
        "(pixel noise, wrong ids, dropout) apply to the vertex front end only");
  }
  const int server_budget = options.server.slam.feature_budget;
  if (server_budget > 0 && options.orb.num_features > server_budget) {
    return Status::Error("ORB features a frame (" + std::to_string(options.orb.num_features) +
                         ") exceed the SLAM feature budget (" + std::to_string(server_budget) +
                         "): raise the budget or lower the ORB feature count");
  }
  return options.orb.Check().Prefixed("ORB options: ");
}

Expected<HeadlessResult> RunHeadless(const HeadlessOptions& options) {
  if (!(options.fps > 0 && options.fps <= 10000))
    return Status::Error("--fps must be in (0, 10000]");
  if (Status s = options.camera.Check(); !s) return s.Prefixed("camera: ");
  if (Status s = options.noise.Check(); !s) return s.Prefixed("noise: ");
  if (Status s = options.projector_options.Check(); !s) return s.Prefixed("projector: ");
  if (options.send_budget < 0) return Status::Error("send_budget must be >= 0 (0: all)");
  if (Status s = CheckFrontEnd(options); !s) return s;

  std::vector<SceneEvent> events;
  if (!options.scene_events_path.empty()) {
    if (options.front_end != "vertex")
      return Status::Error("--scene-events needs the vertex front end");
    auto read = ReadSceneEvents(options.scene_events_path);
    if (!read) return read.status();
    events = std::move(*read);
  }
  auto loaded_scene = LoadSceneOrDefault(options.mesh_path);
  if (!loaded_scene) return loaded_scene.status();
  Scene scene = std::move(*loaded_scene);
  Expected<Trajectory> trajectory = LoadTrajectoryOrDefault(options.trajectory_path);
  if (!trajectory) return trajectory.status();
  auto resampled = trajectory->Resample(options.fps);
  if (!resampled) return resampled.status();
  const size_t num_frames = options.max_frames > 0
                                ? std::min<size_t>(resampled->size(), options.max_frames)
                                : resampled->size();

  HeadlessResult result;
  std::string projector_name;
  auto frame_maker = CreateFrameMaker(options, scene, &result.notice, &projector_name);
  if (!frame_maker) return frame_maker.status();
  // Scene events: the editor owns the scene from here on, the CPU projector follows it.
  std::optional<SceneEditor> editor;
  CpuProjector* followed = nullptr;
  const Scene* current_scene = &scene;
  size_t next_event = 0;
  if (!options.scene_events_path.empty()) {
    followed = dynamic_cast<CpuProjector*>(frame_maker->projector.get());
    if (followed == nullptr)
      return Status::Error("--scene-events needs the CPU projector (--projector cpu)");
    editor.emplace(std::move(scene));
    current_scene = &editor->scene();
  }

  std::unique_ptr<client::Transport> transport;
  if (options.on_device) {
    server_app::ServerOptions server = options.server;
    server.slam.deterministic = server.slam.deterministic || options.fast;
    auto method = plugin::LoadMethod(options.method, options.method_config);
    if (!method) return method.status();
    transport = std::make_unique<client::OnDeviceTransport>(server, method->system, method->group);
  } else {
    transport = std::make_unique<client::LcmTransport>(options.lcm_url, options.bus);
  }
  if (!options.record_log.empty()) {
    transport =
        std::make_unique<client::RecordingTransport>(std::move(transport), options.record_log);
  }
  client::ClientSessionOptions session_options;
  session_options.camera = options.camera;
  session_options.deterministic = options.fast;
  session_options.session_seed = options.session_seed;
  session_options.map_group = options.map_group;
  client::ClientSession session(transport.get(), session_options);
  if (Status s = session.Start(); !s) return s;

  reporting::RunInfo info;
  info.projector = projector_name;
  info.transport = options.on_device ? "on-device" : "lcm";
  info.fps = options.fps;
  info.fast = options.fast;
  info.frames_total = static_cast<int64_t>(num_frames);
  info.render_map = options.render_map;
  info.front_end = options.front_end;
  info.ids_are_vertices = options.front_end == "vertex";

  // A frame: the scene events due by its time applied, then the front end's features.
  auto prepare = [&](size_t k, reporting::FrontEndTime* time) -> Expected<wire::FeatureFrame> {
    const TimedPose& pose = (*resampled)[k];
    for (; next_event < events.size() &&
           events[next_event].time_s <= pose.timestamp - (*resampled)[0].timestamp;
         ++next_event) {
      const auto change = ApplySceneEvent(events[next_event], &*editor);
      const Status applied =
          change ? followed->ApplyChange(editor->scene(), *change) : change.status();
      if (!applied) return applied.Prefixed("scene event " + std::to_string(next_event + 1) + ": ");
    }
    auto frame =
        frame_maker->Make(pose.world_from_camera, std::llround(pose.timestamp * 1e6), k, time);
    if (!frame) {
      return Status::Error((frame_maker->orb ? "ORB front end failed: " : "projection failed: ") +
                           frame.error());
    }
    return frame;
  };

  const auto start = Clock::now();
  auto next_progress = start;
  const auto period = std::chrono::duration<double>(1.0 / options.fps);
  int64_t last_seq = 0;
  // With --fast, the front end runs ahead of the server (it does not depend on the answers):
  // frame k + 1 is made while the server tracks frame k, and sent as soon as fewer than
  // `in_flight` frames are unanswered (up to 3: a keyframe's local mapping takes several
  // frames' time). The in-process server queues up to queue_capacity frames per session and
  // drops only beyond that, so it sees every frame, in order, and tracks each as without the
  // overlap (a remote server's queue is unknown: one frame at a time).
  const size_t in_flight =
      options.on_device ? static_cast<size_t>(std::clamp(options.server.queue_capacity, 1, 3)) : 1;
  std::deque<int64_t> unanswered;
  std::optional<Expected<wire::FeatureFrame>> ahead;
  reporting::FrontEndTime ahead_time;
  bool no_answer = false;
  for (size_t k = 0; k < num_frames && !no_answer; ++k) {
    if (!options.fast) {
      const auto due = start + std::chrono::duration_cast<Clock::duration>(period * k);
      const auto now = Clock::now();
      if (now > due + std::chrono::duration_cast<Clock::duration>(period)) {
        ++info.frames_skipped_client;  // more than a frame late: real time moves on
        continue;
      }
      std::this_thread::sleep_until(due);
    }
    reporting::FrontEndTime time;
    Expected<wire::FeatureFrame> frame = Status::Error("no frame");
    if (ahead) {
      frame = std::move(*ahead);
      time = ahead_time;
      ahead.reset();
    } else {
      frame = prepare(k, &time);
    }
    if (!frame) return frame.status();
    while (options.fast && unanswered.size() >= in_flight) {
      if (!session.WaitForPose(unanswered.front(), options.pose_timeout_s) &&
          session.Counters().poses_received == 0) {
        no_answer = true;  // nobody answers; reported below
        break;
      }
      unanswered.pop_front();
    }
    if (no_answer) break;
    auto seq = session.Send(std::move(*frame));
    if (!seq) return seq.status();
    last_seq = *seq;
    if (options.fast) unanswered.push_back(*seq);
    time.seq = *seq;
    info.front_end_times.push_back(time);
    if (options.on_frame_sent) options.on_frame_sent(static_cast<int64_t>(k));
    if (options.fast && k + 1 < num_frames) {
      ahead_time = reporting::FrontEndTime{};
      ahead = prepare(k + 1, &ahead_time);
    }
    if (options.progress && Clock::now() >= next_progress) {
      const client::ClientCounters c = session.Counters();
      std::fprintf(stderr, "\rframe %zu/%zu  poses %lld  skipped %lld  map %zu points   ", k + 1,
                   num_frames, static_cast<long long>(c.poses_received),
                   static_cast<long long>(info.frames_skipped_client),
                   session.replica().num_points());
      next_progress = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>(kProgressPeriodS));
    }
  }
  if (options.progress) std::fprintf(stderr, "\r%*s\r", 70, "");
  const bool answered = session.Counters().poses_received > 0;
  if (answered && last_seq > 0) session.WaitForPose(last_seq, options.pose_timeout_s);
  if (answered && !session.SyncMap(kSyncMapTimeoutS)) {
    M2S_LOG(kWarning) << "no full map before the end";
  }
  info.wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  frame_maker->orb.reset();  // its GL context goes before the outputs make their own
  const std::vector<client::FrameRecord> records = session.Records();
  const client::MapSnapshot map = session.replica().Snapshot();
  result.counters = session.Counters();
  const std::string rejection = session.LastRejection();
  session.End();
  if (result.counters.poses_received == 0 && !records.empty()) {
    const client::ClientCounters& c = result.counters;
    return Status::Error("no server answered: " + std::to_string(records.size()) +
                         " frames sent, " + std::to_string(c.acks) + " HELLO acknowledgements, " +
                         std::to_string(c.rejected) + " refusals" +
                         (c.rejected > 0 ? " (last: " + rejection + ")" : "") + ", " +
                         std::to_string(c.refused_by_transport) +
                         " messages refused by the bus checks (wrong key?)");
  }
  info.sessions = result.counters.sessions_started;
  info.server_restarts = result.counters.server_restarts;
  info.resync_requests = result.counters.resync_requests;
  info.bus_refused = result.counters.refused_by_transport;
  info.foreign_server_messages = result.counters.foreign_server_messages;
  info.map_group = options.map_group;
  info.servers_seen = result.counters.servers_seen;
  auto metrics = reporting::WriteRunOutputs(options.out_dir, records, map, current_scene,
                                            options.camera, info);
  if (!metrics) return metrics.status();
  result.metrics = std::move(*metrics);
  return result;
}

}  // namespace m2s::headless
