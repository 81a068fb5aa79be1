#include "m2s/xr/xr_client.h"

#include <poll.h>
#include <unistd.h>

#include <GLES3/gl3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
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
#include "m2s/headless/run_outputs.h"
#include "m2s/render/map_renderer.h"
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

// Non-blocking read of control keys from stdin (one per line: r, o, q).
std::vector<ControlEvent::Kind> ReadKeys() {
  std::vector<ControlEvent::Kind> keys;
  pollfd fd{STDIN_FILENO, POLLIN, 0};
  while (poll(&fd, 1, 0) > 0 && (fd.revents & POLLIN)) {
    char c = 0;
    if (read(STDIN_FILENO, &c, 1) != 1) break;
    if (c == 'r') keys.push_back(ControlEvent::Kind::kReset);
    if (c == 'o') keys.push_back(ControlEvent::Kind::kToggleOverlay);
    if (c == 'q') keys.push_back(ControlEvent::Kind::kQuit);
  }
  return keys;
}

// One SLAM conversation: a transport and a client session on it (a reset makes a new one).
struct SlamLink {
  std::unique_ptr<client::Transport> transport;
  std::unique_ptr<client::ClientSession> session;
};

// `hello_timeout_s` 0 on the render thread: frames open the session if HELLO_ACK is late.
Expected<SlamLink> OpenLink(const XrClientOptions& options, uint64_t seed, double hello_timeout_s) {
  SlamLink link;
  if (options.on_device) {
    link.transport = std::make_unique<client::OnDeviceTransport>(options.server);
  } else {
    link.transport = std::make_unique<client::LcmTransport>(options.lcm_url, options.bus);
  }
  client::ClientSessionOptions session_options;
  session_options.camera = options.camera;
  session_options.client_name = "m2s_xr_client";
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
    } else if (name == "quit") {
      e.kind = ControlEvent::Kind::kQuit;
    } else {
      return Status::Error("unknown control event '" + item + "' (reset, overlay, quit)");
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

bool XrClientOptions::Check(std::string* why) const {
  if (!camera.Check(why)) return false;
  if (!projector_options.Check(why) || !noise.Check(why) || !server.Check(why)) return false;
  if (send_budget < 0) {
    *why = "send_budget must be >= 0 (0: all features)";
    return false;
  }
  if (max_frames < 0 || align_every_frames < 1 || !(final_pose_timeout_s >= 0)) {
    *why = "max_frames >= 0, align_every_frames >= 1 and final_pose_timeout_s >= 0 required";
    return false;
  }
  if (out_dir.empty()) {
    *why = "out_dir is empty";
    return false;
  }
  return true;
}

Expected<XrClientResult> RunXrClient(const XrClientOptions& options, XrPlatform* platform) {
  std::string why;
  if (!options.Check(&why)) return Status::Error(why);
  const auto run_start = Clock::now();

  // The app's GLES context: the runtime renders from its swapchains, the projector computes in
  // it, the renderer draws in it. Current on this (the render) thread throughout.
  auto gl = GlContext::CreateHeadless();
  if (!gl) return Status::Error("no GLES context: " + gl.error());
  EglHandles egl;
  egl.display = static_cast<EGLDisplay>((*gl)->egl_display());
  egl.context = static_cast<EGLContext>((*gl)->egl_context());
  egl.config = ConfigOf(egl.display, egl.context);

  auto loaded_scene = LoadSceneOrDefault(options.mesh_path);
  if (!loaded_scene) return loaded_scene.status();
  Scene scene = std::move(*loaded_scene);
  auto kind = ParseProjectorKind(options.projector);
  if (!kind) return kind.status();
  auto projector = MakeProjector(*kind, scene, options.projector_options, gl->get());
  std::string projector_name(ToString(*kind));
  if (!projector && *kind == ProjectorKind::kGpu) {
    M2S_LOG(kWarning) << "GPU projector unavailable (" << projector.error() << "); using the CPU";
    projector = MakeProjector(ProjectorKind::kCpu, scene, options.projector_options, nullptr);
    projector_name = "cpu";
  }
  if (!projector) return projector.status();
  client::FrameSource source(projector->get(), options.camera, options.noise,
                             static_cast<uint32_t>(scene.num_vertices()), options.send_budget);

  MapRendererOptions render_options;
  render_options.mesh_style = options.draw_mesh ? MapRendererOptions::MeshStyle::kShaded
                                                : MapRendererOptions::MeshStyle::kHidden;
  auto renderer = MapRenderer::Create(render_options);
  if (!renderer) return renderer.status();
  if (Status s = (*renderer)->SetMesh(scene.positions, scene.triangles); !s) return s;
  (*renderer)->SetFrustumCamera(options.camera);

  constexpr double kStartHelloTimeoutS = 2.0;  // before the frame loop: waiting is fine
  auto link = OpenLink(options, 0, kStartHelloTimeoutS);
  if (!link) return link.status();
  std::vector<client::FrameRecord> finished_records;  // of sessions ended by a reset

  XrSessionOptions xr_options;
  xr_options.stage_space = options.stage_space;
  auto xr = XrSessionDriver::Create(xr_options, platform, egl);
  if (!xr) return xr.status();

  XrClientResult result;
  Overlay overlay;
  bool overlay_visible = options.overlay;
  std::vector<double> projection_ms, handoff_ms, overlay_ms, frame_ms;
  int64_t resets = 0, toggles = 0;
  XrTime first_display_time = 0, last_display_time = 0;
  bool exit_requested = false;
  for (;;) {
    const LoopAction action = (*xr)->PollEvents();
    if (action == LoopAction::kExit) break;
    std::vector<ControlEvent::Kind> controls;
    for (const ControlEvent& e : options.events) {
      if (e.frame == (*xr)->frames_begun()) controls.push_back(e.kind);
    }
    if (options.platform_events && !options.platform_events()) {
      controls.push_back(ControlEvent::Kind::kQuit);
    }
    if (options.stdin_keys) {
      for (ControlEvent::Kind k : ReadKeys()) controls.push_back(k);
    }
    for (ControlEvent::Kind k : controls) {
      if (k == ControlEvent::Kind::kToggleOverlay) {
        overlay_visible = !overlay_visible;
        ++toggles;
        M2S_LOG(kInfo) << "overlay " << (overlay_visible ? "on" : "off");
      } else if (k == ControlEvent::Kind::kQuit && !exit_requested) {
        exit_requested = true;
        (*xr)->RequestExit();
      } else if (k == ControlEvent::Kind::kReset) {
        // A new SLAM session; the old one's frames stay in the records.
        for (const auto& r : link->session->Records()) finished_records.push_back(r);
        link->session->End();
        const auto reset_start = Clock::now();
        auto fresh = OpenLink(options, 0, /*hello_timeout_s=*/0.0);
        if (!fresh) return fresh.status();
        link = std::move(fresh);
        overlay.Reset();
        ++resets;
        M2S_LOG(kInfo) << "SLAM reset: new session " << link->session->session_id() << " ("
                       << MsSince(reset_start) << " ms on the render thread)";
      }
    }
    if (action == LoopAction::kIdle) {
      std::this_thread::sleep_for(std::chrono::duration<double>(kIdleWaitS));
      continue;
    }
    FrameInfo frame;
    if (!(*xr)->BeginFrame(&frame)) continue;
    const auto frame_start = Clock::now();
    if (first_display_time == 0) first_display_time = frame.display_time;
    last_display_time = frame.display_time;
    const bool visible = (*xr)->state() == XR_SESSION_STATE_VISIBLE || (*xr)->focused();
    if (frame.view_valid && visible) {
      // The centre eye (VIEW space) is the SLAM camera.
      const Pose3 world_from_camera = WorldFromCameraFromXrView(frame.world_from_view_xr);
      const auto t0 = Clock::now();
      auto features = source.Make(world_from_camera, frame.display_time / 1000,
                                  static_cast<uint64_t>(frame.index));
      projection_ms.push_back(MsSince(t0));
      if (!features) return Status::Error("projection failed: " + features.error());
      const auto t1 = Clock::now();
      auto seq = link->session->Send(std::move(*features));
      handoff_ms.push_back(MsSince(t1));
      if (!seq) M2S_LOG(kWarning) << "frame not sent: " << seq.error();
      if (seq) ++result.frames_sent;
    }
    const auto t2 = Clock::now();
    overlay.Update(*link->session, frame.index % options.align_every_frames == 0, overlay_visible,
                   renderer->get());
    overlay_ms.push_back(MsSince(t2));
    if (frame.should_render) {
      for (int eye = 0; eye < 2; ++eye) {
        const EyeView& view = frame.eyes[eye];
        (*xr)->RenderEye(eye, [&](int, int) {
          const Eigen::Matrix4f v = GlViewFromXrPose(view.world_from_eye_xr).cast<float>();
          const Eigen::Matrix4f p =
              GlProjectionFromXrFov(view.fov, xr_options.near_m, xr_options.far_m).cast<float>();
          if (Status s = (*renderer)->Draw(v, p); !s) M2S_LOG(kWarning) << s.message();
        });
      }
      ++result.frames_rendered;
    }
    (*xr)->EndFrame(frame);
    frame_ms.push_back(MsSince(frame_start));
    if (options.max_frames > 0 && (*xr)->frames_begun() >= options.max_frames && !exit_requested) {
      exit_requested = true;
      (*xr)->RequestExit();
    }
  }
  result.frames = (*xr)->frames_begun();
  const double display_rate_hz =
      result.frames > 1 && last_display_time > first_display_time
          ? (result.frames - 1) * 1e9 / static_cast<double>(last_display_time - first_display_time)
          : 0.0;
  result.sessions = (*xr)->sessions_created();
  result.instance_lost = (*xr)->instance_lost();
  const std::string xr_error = (*xr)->error();
  const std::vector<std::string> state_log = (*xr)->state_log();
  const std::string runtime_name = (*xr)->runtime_name();
  xr->reset();  // every OpenXR handle, before the GL objects and the context go
  if (!xr_error.empty()) return Status::Error("OpenXR: " + xr_error);

  // Let SLAM catch up with the frames already handed over, then write the outputs.
  const std::vector<client::FrameRecord> last = link->session->Records();
  if (!last.empty()) link->session->WaitForPose(last.back().seq, options.final_pose_timeout_s);
  link->session->SyncMap(options.final_pose_timeout_s);
  std::vector<client::FrameRecord> records = finished_records;
  for (const auto& r : link->session->Records()) records.push_back(r);
  const client::MapSnapshot map = link->session->replica().Snapshot();
  const client::ClientCounters counters = link->session->Counters();
  link->session->End();
  result.slam_sessions = resets + 1;

  headless::RunInfo info;
  info.projector = projector_name;
  info.transport = options.on_device ? "on-device" : "lcm";
  info.fps = display_rate_hz;
  info.frames_total = result.frames_sent;
  info.sessions = counters.sessions_started + resets;
  info.server_restarts = counters.server_restarts;
  info.resync_requests = counters.resync_requests;
  info.wall_s = std::chrono::duration<double>(Clock::now() - run_start).count();
  std::error_code ignored;
  std::filesystem::create_directories(options.out_dir, ignored);
  auto metrics =
      headless::WriteRunOutputs(options.out_dir, records, map, &scene, options.camera, info);
  if (!metrics) return metrics.status();
  result.ate_rmse = metrics->ate_rmse;
  result.projection = Stats(projection_ms);
  result.handoff = Stats(handoff_ms);
  result.overlay = Stats(overlay_ms);
  result.frame = Stats(frame_ms);

  const nlohmann::json json = {{"runtime", runtime_name},
                               {"transport", info.transport},
                               {"projector", projector_name},
                               {"frames", result.frames},
                               {"frames_sent", result.frames_sent},
                               {"frames_rendered", result.frames_rendered},
                               {"openxr_sessions", result.sessions},
                               {"slam_sessions", result.slam_sessions},
                               {"overlay_toggles", toggles},
                               {"instance_lost", result.instance_lost},
                               {"ate_rmse", result.ate_rmse},
                               {"map_points", metrics->map_points},
                               {"keyframes", metrics->keyframes},
                               {"render_thread_ms",
                                {{"projection", ToJson(result.projection)},
                                 {"handoff", ToJson(result.handoff)},
                                 {"overlay_update", ToJson(result.overlay)},
                                 {"frame_total", ToJson(result.frame)}}},
                               {"session_states", state_log}};
  std::ofstream(options.out_dir + "/xr_metrics.json") << json.dump(2) << "\n";

  char line[512];
  std::snprintf(line, sizeof(line),
                "m2s_xr_client: %lld frames (%lld sent, %lld rendered), %lld OpenXR session(s), "
                "ATE %.4f m; render thread p50/p95: projection %.2f/%.2f ms, hand-off "
                "%.3f/%.3f ms, overlay %.3f/%.3f ms; outputs in %s",
                static_cast<long long>(result.frames), static_cast<long long>(result.frames_sent),
                static_cast<long long>(result.frames_rendered),
                static_cast<long long>(result.sessions), result.ate_rmse, result.projection.p50_ms,
                result.projection.p95_ms, result.handoff.p50_ms, result.handoff.p95_ms,
                result.overlay.p50_ms, result.overlay.p95_ms, options.out_dir.c_str());
  result.summary = line;
  renderer->reset();
  projector->reset();
  return result;
}

}  // namespace m2s::xr
