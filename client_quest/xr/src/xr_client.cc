#include "m2s/xr/xr_client.h"

#include <poll.h>
#include <unistd.h>

#include <GLES3/gl3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "m2s/client/client_session.h"
#include "m2s/client/frame_source.h"
#include "m2s/client/on_device_transport.h"
#include "m2s/common/logging.h"
#include "m2s/common/scene.h"
#include "m2s/gpu/gl_context.h"
#include "m2s/gpu/projector_factory.h"
#include "m2s/plugin/plugin_system.h"
#include "m2s/render/map_renderer.h"
#include "m2s/reporting/run_outputs.h"
#include "m2s/xr/axis_conversion.h"
#include "m2s/xr/xr_session.h"
#include "overlay.h"

namespace m2s::xr {
namespace {

using Clock = std::chrono::steady_clock;
constexpr double kIdleWaitS = 0.002;  // between event polls while no session runs

double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

TimingStats Stats(std::vector<double> ms) {
  TimingStats s;
  s.n = static_cast<int64_t>(ms.size());
  if (ms.empty()) return s;
  std::sort(ms.begin(), ms.end());
  auto at = [&](double q) {
    return ms[std::min(ms.size() - 1, static_cast<size_t>(q * ms.size()))];
  };
  s.p50_ms = at(0.5);
  s.p95_ms = at(0.95);
  s.max_ms = ms.back();
  return s;
}

nlohmann::json ToJson(const TimingStats& s) {
  return {{"p50_ms", s.p50_ms}, {"p95_ms", s.p95_ms}, {"max_ms", s.max_ms}, {"n", s.n}};
}

// The EGLConfig of a context (the MNDX binding wants it).
EGLConfig ConfigOf(EGLDisplay display, EGLContext context) {
  EGLint id = 0;
  eglQueryContext(display, context, EGL_CONFIG_ID, &id);
  const EGLint attribs[] = {EGL_CONFIG_ID, id, EGL_NONE};
  EGLConfig config = nullptr;
  EGLint n = 0;
  eglChooseConfig(display, attribs, &config, 1, &n);
  return n == 1 ? config : nullptr;
}

// Non-blocking read of control keys from stdin (one per line: r, o, k, q).
std::vector<ControlEvent::Kind> ReadKeys() {
  std::vector<ControlEvent::Kind> keys;
  pollfd fd{STDIN_FILENO, POLLIN, 0};
  while (poll(&fd, 1, 0) > 0 && (fd.revents & POLLIN)) {
    char c = 0;
    if (read(STDIN_FILENO, &c, 1) != 1) break;
    if (c == 'r') keys.push_back(ControlEvent::Kind::kReset);
    if (c == 'o') keys.push_back(ControlEvent::Kind::kToggleOverlay);
    if (c == 'k') keys.push_back(ControlEvent::Kind::kToggleOtherKeyframes);
    if (c == 'q') keys.push_back(ControlEvent::Kind::kQuit);
  }
  return keys;
}

// One SLAM conversation: a transport and a client session on it (a reset makes a new one).
struct SlamLink {
  std::unique_ptr<client::Transport> transport;
  std::unique_ptr<client::ClientSession> session;
};

// `hello_timeout_s` 0 on the render thread: it does not wait for HELLO_ACK (poses count once
// the acknowledgement arrives; until then frames are sent all the same).
Expected<SlamLink> OpenLink(const XrClientOptions& options, uint64_t seed, double hello_timeout_s) {
  SlamLink link;
  if (options.on_device) {
    auto method = plugin::LoadMethod(options.method, options.method_config);
    if (!method) return method.status();
    link.transport =
        std::make_unique<client::OnDeviceTransport>(options.server, method->system, method->group);
  } else {
    link.transport = std::make_unique<client::LcmTransport>(options.lcm_url, options.bus);
  }
  client::ClientSessionOptions session_options;
  session_options.camera = options.camera;
  session_options.client_name = "m2s_xr_client";
  session_options.map_group = options.map_group;
  session_options.session_seed = seed;
  session_options.hello_timeout_s = hello_timeout_s;
  link.session = std::make_unique<client::ClientSession>(link.transport.get(), session_options);
  if (Status s = link.session->Start(); !s) return s;
  return link;
}

}  // namespace

Expected<std::vector<ControlEvent>> ParseControlEvents(const std::string& text) {
  std::vector<ControlEvent> events;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    if (item.empty()) continue;
    const size_t at = item.find('@');
    ControlEvent e;
    const std::string name = item.substr(0, at);
    if (name == "reset") {
      e.kind = ControlEvent::Kind::kReset;
    } else if (name == "overlay") {
      e.kind = ControlEvent::Kind::kToggleOverlay;
    } else if (name == "others") {
      e.kind = ControlEvent::Kind::kToggleOtherKeyframes;
    } else if (name == "quit") {
      e.kind = ControlEvent::Kind::kQuit;
    } else {
      return Status::Error("unknown control event '" + item + "' (reset, overlay, others, quit)");
    }
    char* end = nullptr;
    const std::string frame = at == std::string::npos ? "" : item.substr(at + 1);
    e.frame = std::strtoll(frame.c_str(), &end, 10);
    if (frame.empty() || *end != '\0' || e.frame < 0) {
      return Status::Error("control event '" + item + "' is not NAME@FRAME");
    }
    events.push_back(e);
  }
  return events;
}

Status XrClientOptions::Check() const {
  if (Status s = camera.Check(); !s) return s;
  if (Status s = projector_options.Check(); !s) return s.Prefixed("projector: ");
  if (Status s = noise.Check(); !s) return s.Prefixed("noise: ");
  if (Status s = server.Check(); !s) return s.Prefixed("server: ");
  if (send_budget < 0) {
    return Status::Error("send_budget must be >= 0 (0: all features)");
  }
  if (max_frames < 0 || align_every_frames < 1 || !(final_pose_timeout_s >= 0)) {
    return Status::Error(
        "max_frames >= 0, align_every_frames >= 1 and final_pose_timeout_s >= 0 required");
  }
  if (out_dir.empty()) {
    return Status::Error("out_dir is empty");
  }
  if (!plugin::IsBuiltinMethod(method) && !map_group.empty()) {
    return Status::Error("map_group needs the built-in SLAM (method \"vertex_slam\")");
  }
  return Status::Ok();
}

namespace {

// One run of the app, step by step: Create (GL context, scene, projector, renderer, SLAM link,
// OpenXR session), then per loop iteration ApplyControls and RenderFrame, then Finish (the
// outputs). Lives on the render thread.
class XrRun {
 public:
  static Expected<std::unique_ptr<XrRun>> Create(const XrClientOptions& options,
                                                 XrPlatform* platform);
  // Polls the runtime; false when the app should stop.
  bool Poll(LoopAction* action) {
    *action = xr_->PollEvents();
    return *action != LoopAction::kExit;
  }
  Status ApplyControls();
  Status RenderFrame();
  Expected<XrClientResult> Finish();

 private:
  explicit XrRun(const XrClientOptions& options) : options_(options) {}
  std::vector<ControlEvent::Kind> PendingControls();
  Status ResetSlam();
  Status WriteOutputs(const reporting::RunInfo& info, const reporting::RunMetrics& metrics,
                      const std::vector<std::string>& state_log, const std::string& runtime);

  const XrClientOptions& options_;
  const Clock::time_point start_ = Clock::now();
  std::unique_ptr<GlContext> gl_;
  Scene scene_;
  std::unique_ptr<Projector> projector_;
  std::string projector_name_;
  std::unique_ptr<client::FrameSource> source_;
  std::unique_ptr<MapRenderer> renderer_;
  std::optional<SlamLink> link_;
  std::vector<client::FrameRecord> finished_records_;  // of sessions ended by a reset
  XrSessionOptions xr_options_;
  std::unique_ptr<XrSessionDriver> xr_;
  Overlay overlay_;
  bool overlay_visible_ = true;
  bool other_keyframes_visible_ = true;
  bool exit_requested_ = false;
  int64_t resets_ = 0, toggles_ = 0, other_toggles_ = 0;
  XrTime first_display_time_ = 0, last_display_time_ = 0;
  std::vector<double> projection_ms_, handoff_ms_, overlay_ms_, frame_ms_;
  XrClientResult result_;
};

Expected<std::unique_ptr<XrRun>> XrRun::Create(const XrClientOptions& options,
                                               XrPlatform* platform) {
  std::unique_ptr<XrRun> run(new XrRun(options));
  run->overlay_visible_ = options.overlay;
  run->other_keyframes_visible_ = options.show_other_keyframes;
  // The app's GLES context: the runtime renders from its swapchains, the projector computes in
  // it, the renderer draws in it. Current on this (the render) thread throughout.
  auto gl = GlContext::CreateHeadless();
  if (!gl) return Status::Error("no GLES context: " + gl.error());
  run->gl_ = std::move(*gl);
  EglHandles egl;
  egl.display = static_cast<EGLDisplay>(run->gl_->egl_display());
  egl.context = static_cast<EGLContext>(run->gl_->egl_context());
  egl.config = ConfigOf(egl.display, egl.context);

  auto loaded_scene = LoadSceneOrDefault(options.mesh_path);
  if (!loaded_scene) return loaded_scene.status();
  run->scene_ = std::move(*loaded_scene);
  auto kind = ParseProjectorKind(options.projector);
  if (!kind) return kind.status();
  auto projector = MakeProjector(*kind, run->scene_, options.projector_options, run->gl_.get());
  run->projector_name_ = ToString(*kind);
  if (!projector && *kind == ProjectorKind::kGpu) {
    M2S_LOG(kWarning) << "GPU projector unavailable (" << projector.error() << "); using the CPU";
    projector = MakeProjector(ProjectorKind::kCpu, run->scene_, options.projector_options, nullptr);
    run->projector_name_ = "cpu";
  }
  if (!projector) return projector.status();
  run->projector_ = std::move(*projector);
  run->source_ = std::make_unique<client::FrameSource>(
      run->projector_.get(), options.camera, options.noise,
      static_cast<uint32_t>(run->scene_.num_vertices()), options.send_budget);

  MapRendererOptions render_options;
  render_options.mesh_style = options.draw_mesh ? MapRendererOptions::MeshStyle::kShaded
                                                : MapRendererOptions::MeshStyle::kHidden;
  auto renderer = MapRenderer::Create(render_options);
  if (!renderer) return renderer.status();
  run->renderer_ = std::move(*renderer);
  if (Status s = run->renderer_->SetMesh(run->scene_.positions, run->scene_.triangles); !s) {
    return s;
  }
  run->renderer_->SetFrustumCamera(options.camera);

  constexpr double kStartHelloTimeoutS = 2.0;  // before the frame loop: waiting is fine
  auto link = OpenLink(options, 0, kStartHelloTimeoutS);
  if (!link) return link.status();
  run->link_ = std::move(*link);

  run->xr_options_.stage_space = options.stage_space;
  auto xr = XrSessionDriver::Create(run->xr_options_, platform, egl);
  if (!xr) return xr.status();
  run->xr_ = std::move(*xr);
  return run;
}

std::vector<ControlEvent::Kind> XrRun::PendingControls() {
  std::vector<ControlEvent::Kind> controls;
  for (const ControlEvent& e : options_.events) {
    if (e.frame == xr_->frames_begun()) controls.push_back(e.kind);
  }
  if (options_.platform_events && !options_.platform_events()) {
    controls.push_back(ControlEvent::Kind::kQuit);
  }
  if (options_.stdin_keys) {
    for (ControlEvent::Kind k : ReadKeys()) controls.push_back(k);
  }
  for (ControllerAction a : xr_->TakeControllerPresses()) {
    switch (a) {
      case ControllerAction::kResetSlam:
        controls.push_back(ControlEvent::Kind::kReset);
        break;
      case ControllerAction::kToggleOverlay:
        controls.push_back(ControlEvent::Kind::kToggleOverlay);
        break;
      case ControllerAction::kToggleOtherKeyframes:
        controls.push_back(ControlEvent::Kind::kToggleOtherKeyframes);
        break;
    }
  }
  return controls;
}

Status XrRun::ApplyControls() {
  for (ControlEvent::Kind k : PendingControls()) {
    if (k == ControlEvent::Kind::kToggleOverlay) {
      overlay_visible_ = !overlay_visible_;
      ++toggles_;
      M2S_LOG(kInfo) << "overlay " << (overlay_visible_ ? "on" : "off");
    } else if (k == ControlEvent::Kind::kToggleOtherKeyframes) {
      other_keyframes_visible_ = !other_keyframes_visible_;
      ++other_toggles_;
      M2S_LOG(kInfo) << "other agents' keyframes " << (other_keyframes_visible_ ? "on" : "off");
    } else if (k == ControlEvent::Kind::kQuit && !exit_requested_) {
      exit_requested_ = true;
      xr_->RequestExit();
    } else if (k == ControlEvent::Kind::kReset) {
      if (Status s = ResetSlam(); !s) return s;
    }
  }
  return Status::Ok();
}

// A new SLAM session; the old one's frames stay in the records.
Status XrRun::ResetSlam() {
  for (const auto& r : link_->session->Records()) finished_records_.push_back(r);
  link_->session->End();
  const auto reset_start = Clock::now();
  auto fresh = OpenLink(options_, 0, /*hello_timeout_s=*/0.0);
  if (!fresh) return fresh.status();
  link_ = std::move(*fresh);
  overlay_.Reset();
  ++resets_;
  M2S_LOG(kInfo) << "SLAM reset: new session " << link_->session->session_id() << " ("
                 << MsSince(reset_start) << " ms on the render thread)";
  return Status::Ok();
}

Status XrRun::RenderFrame() {
  FrameInfo frame;
  if (!xr_->BeginFrame(&frame)) return Status::Ok();
  const auto frame_start = Clock::now();
  if (first_display_time_ == 0) first_display_time_ = frame.display_time;
  last_display_time_ = frame.display_time;
  const bool visible = xr_->state() == XR_SESSION_STATE_VISIBLE || xr_->focused();
  if (frame.view_valid && visible) {
    // The centre eye (VIEW space) is the SLAM camera.
    const Pose3 world_from_camera = WorldFromCameraFromXrView(frame.world_from_view_xr);
    const auto t0 = Clock::now();
    auto features = source_->Make(world_from_camera, frame.display_time / 1000,
                                  static_cast<uint64_t>(frame.index));
    projection_ms_.push_back(MsSince(t0));
    if (!features) return Status::Error("projection failed: " + features.error());
    const auto t1 = Clock::now();
    auto seq = link_->session->Send(std::move(*features));
    handoff_ms_.push_back(MsSince(t1));
    if (!seq) M2S_LOG(kWarning) << "frame not sent: " << seq.error();
    if (seq) ++result_.frames_sent;
  }
  const auto t2 = Clock::now();
  overlay_.Update(*link_->session, frame.index % options_.align_every_frames == 0, overlay_visible_,
                  other_keyframes_visible_, renderer_.get());
  overlay_ms_.push_back(MsSince(t2));
  if (frame.should_render) {
    for (int eye = 0; eye < 2; ++eye) {
      const EyeView& view = frame.eyes[eye];
      xr_->RenderEye(eye, [&](int, int) {
        const Eigen::Matrix4f v = GlViewFromXrPose(view.world_from_eye_xr).cast<float>();
        const Eigen::Matrix4f p =
            GlProjectionFromXrFov(view.fov, xr_options_.near_m, xr_options_.far_m).cast<float>();
        if (Status s = renderer_->Draw(v, p); !s) M2S_LOG(kWarning) << s.message();
      });
    }
    ++result_.frames_rendered;
  }
  xr_->EndFrame(frame);
  frame_ms_.push_back(MsSince(frame_start));
  if (options_.max_frames > 0 && xr_->frames_begun() >= options_.max_frames && !exit_requested_) {
    exit_requested_ = true;
    xr_->RequestExit();
  }
  return Status::Ok();
}

Expected<XrClientResult> XrRun::Finish() {
  result_.frames = xr_->frames_begun();
  const double display_rate_hz =
      result_.frames > 1 && last_display_time_ > first_display_time_
          ? (result_.frames - 1) * 1e9 /
                static_cast<double>(last_display_time_ - first_display_time_)
          : 0.0;
  result_.sessions = xr_->sessions_created();
  result_.instance_lost = xr_->instance_lost();
  result_.controller_presses = xr_->controller_presses();
  const std::string xr_error = xr_->error();
  const std::vector<std::string> state_log = xr_->state_log();
  const std::string runtime_name = xr_->runtime_name();
  xr_.reset();  // every OpenXR handle, before the GL objects and the context go
  if (!xr_error.empty()) return Status::Error("OpenXR: " + xr_error);

  // Let SLAM catch up with the frames already handed over, then write the outputs.
  const std::vector<client::FrameRecord> last = link_->session->Records();
  if (!last.empty()) link_->session->WaitForPose(last.back().seq, options_.final_pose_timeout_s);
  link_->session->SyncMap(options_.final_pose_timeout_s);
  std::vector<client::FrameRecord> records = finished_records_;
  for (const auto& r : link_->session->Records()) records.push_back(r);
  const client::MapSnapshot map = link_->session->replica().Snapshot();
  const client::ClientCounters counters = link_->session->Counters();
  link_->session->End();
  result_.slam_sessions = resets_ + 1;

  reporting::RunInfo info;
  info.projector = projector_name_;
  info.transport = options_.on_device ? "on-device" : "lcm";
  info.fps = display_rate_hz;
  info.frames_total = result_.frames_sent;
  info.sessions = counters.sessions_started + resets_;
  info.server_restarts = counters.server_restarts;
  info.resync_requests = counters.resync_requests;
  info.bus_refused = counters.refused_by_transport;
  info.foreign_server_messages = counters.foreign_server_messages;
  info.wall_s = std::chrono::duration<double>(Clock::now() - start_).count();
  std::error_code ignored;
  std::filesystem::create_directories(options_.out_dir, ignored);
  auto metrics =
      reporting::WriteRunOutputs(options_.out_dir, records, map, &scene_, options_.camera, info);
  if (!metrics) return metrics.status();
  result_.ate_rmse = metrics->ate_rmse;
  result_.projection = Stats(projection_ms_);
  result_.handoff = Stats(handoff_ms_);
  result_.overlay = Stats(overlay_ms_);
  result_.frame = Stats(frame_ms_);
  if (Status s = WriteOutputs(info, *metrics, state_log, runtime_name); !s) return s;
  renderer_.reset();
  projector_.reset();
  return result_;
}

Status XrRun::WriteOutputs(const reporting::RunInfo& info, const reporting::RunMetrics& metrics,
                           const std::vector<std::string>& state_log, const std::string& runtime) {
  const nlohmann::json json = {{"runtime", runtime},
                               {"transport", info.transport},
                               {"projector", projector_name_},
                               {"frames", result_.frames},
                               {"frames_sent", result_.frames_sent},
                               {"frames_rendered", result_.frames_rendered},
                               {"openxr_sessions", result_.sessions},
                               {"slam_sessions", result_.slam_sessions},
                               {"overlay_toggles", toggles_},
                               {"other_keyframe_toggles", other_toggles_},
                               {"controller_presses", result_.controller_presses},
                               {"map_group", options_.map_group},
                               {"instance_lost", result_.instance_lost},
                               {"ate_rmse", result_.ate_rmse},
                               {"map_points", metrics.map_points},
                               {"keyframes", metrics.keyframes},
                               {"render_thread_ms",
                                {{"projection", ToJson(result_.projection)},
                                 {"handoff", ToJson(result_.handoff)},
                                 {"overlay_update", ToJson(result_.overlay)},
                                 {"frame_total", ToJson(result_.frame)}}},
                               {"session_states", state_log}};
  const std::string path = options_.out_dir + "/xr_metrics.json";
  std::ofstream out(path);
  out << json.dump(2) << "\n";
  if (!out) return Status::Error("cannot write " + path);

  char line[512];
  std::snprintf(line, sizeof(line),
                "m2s_xr_client: %lld frames (%lld sent, %lld rendered), %lld OpenXR session(s), "
                "ATE %.4f m; render thread p50/p95: projection %.2f/%.2f ms, hand-off "
                "%.3f/%.3f ms, overlay %.3f/%.3f ms; outputs in %s",
                static_cast<long long>(result_.frames), static_cast<long long>(result_.frames_sent),
                static_cast<long long>(result_.frames_rendered),
                static_cast<long long>(result_.sessions), result_.ate_rmse,
                result_.projection.p50_ms, result_.projection.p95_ms, result_.handoff.p50_ms,
                result_.handoff.p95_ms, result_.overlay.p50_ms, result_.overlay.p95_ms,
                options_.out_dir.c_str());
  result_.summary = line;
  return Status::Ok();
}

}  // namespace

Expected<XrClientResult> RunXrClient(const XrClientOptions& options, XrPlatform* platform) {
  if (Status s = options.Check(); !s) return s;
  auto run = XrRun::Create(options, platform);
  if (!run) return run.status();
  LoopAction action{};
  while ((*run)->Poll(&action)) {
    if (Status s = (*run)->ApplyControls(); !s) return s;
    if (action == LoopAction::kIdle) {
      std::this_thread::sleep_for(std::chrono::duration<double>(kIdleWaitS));
      continue;
    }
    if (Status s = (*run)->RenderFrame(); !s) return s;
  }
  return (*run)->Finish();
}

}  // namespace m2s::xr
