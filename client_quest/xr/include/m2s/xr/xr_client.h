// The OpenXR client's run: the headset's VIEW pose drives the projector on the app's own GLES
// context, frames go to the server over any transport (LCM or on-device) through the client
// core (m2s::client), and the map replica, the keyframes and the estimated against the true
// head pose are drawn in both eyes over the scene mesh.
//
// Per frame on the render thread: PollEvents, xrWaitFrame/xrBeginFrame, VIEW pose ->
// world_from_camera (axis_conversion.h), projection (FrameSource), hand-off
// (ClientSession::Send: encode + publish or enqueue; never waits for SLAM), overlay update
// (new map revision, Sim3 alignment of the SLAM frame to the world from estimated/true pose
// pairs), both eyes drawn by MapRenderer, xrEndFrame. The render thread's time on projection,
// hand-off and overlay is measured per frame and reported (p50/p95) at exit and in
// xr_metrics.json.
//
// Controls (controller buttons through OpenXR actions, xr_actions.h; keys on stdin; scripted
// events): reset SLAM (a new session: the map starts again), toggle the overlay, toggle other
// agents' keyframes (drawn in their own colour, or hidden), quit.
//
//   XrClientOptions options;  // default scene, on-device, GPU projector
//   auto platform = xr::MakePlatform(nullptr);
//   Expected<XrClientResult> result = RunXrClient(options, platform.get());
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "m2s/common/bus_auth.h"
#include "m2s/common/camera.h"
#include "m2s/common/feature_noise.h"
#include "m2s/common/projector.h"
#include "m2s/common/status.h"
#include "m2s/common/wire_format.h"
#include "m2s/server_app/session_manager.h"
#include "m2s/xr/xr_platform.h"

namespace m2s::xr {

struct ControlEvent {
  enum class Kind { kReset, kToggleOverlay, kToggleOtherKeyframes, kQuit };
  Kind kind = Kind::kQuit;
  int64_t frame = 0;  // frame index (frames begun) at which it fires
};

// Parses "reset@200,overlay@250,others@300,quit@400" (names: reset, overlay, others, quit).
Expected<std::vector<ControlEvent>> ParseControlEvents(const std::string& text);

struct XrClientOptions {
  std::string mesh_path;  // empty: the embedded default scene
  // The virtual camera the features are projected with (the centre eye's pose).
  Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  bool on_device = true;
  std::string lcm_url = wire::kDefaultLcmUrl;
  wire::BusSecurityOptions bus;   // LCM only: key ("key_file" in the config), encryption
  std::string projector = "gpu";  // "gpu" (CPU fallback when GLES 3.1 compute fails) or "cpu"
  ProjectorOptions projector_options = ProjectorOptions::Occluding();
  FeatureNoiseOptions noise;
  // Features sent per frame: the lowest-ranked ids (0: all); default the SLAM feature budget.
  int send_budget = slam::Options().feature_budget;
  server_app::ServerOptions server;  // the on-device server
  // The on-device server's localisation method ("" or "vertex_slam": the built-in SLAM; else a
  // plug-in's name or path) and its config (a JSON object's text; empty: none).
  std::string method;
  std::string method_config;
  bool stage_space = false;          // world = STAGE instead of LOCAL
  bool overlay = true;               // draw map points, keyframes and poses at start
  bool show_other_keyframes = true;  // draw other agents' keyframes (own colour) at start
  // The map group the SLAM session joins (HELLO); empty: a map of its own.
  std::string map_group;
  bool draw_mesh = true;             // draw the scene mesh (the virtual world)
  int max_frames = 0;                // request exit after this many frames (0: runtime decides)
  std::vector<ControlEvent> events;  // scripted controls
  bool stdin_keys = false;      // r: reset, o: overlay, k: other keyframes, q: quit (one per line)
  int align_every_frames = 15;  // how often the overlay's Sim3 alignment is refreshed
  double final_pose_timeout_s = 5.0;
  std::string out_dir = "out";
  // Called once per loop iteration on the render thread (the Android looper); returning false
  // asks the runtime to end the session. Empty on desktop.
  std::function<bool()> platform_events;
  Status Check() const;
};

struct TimingStats {
  double p50_ms = 0.0, p95_ms = 0.0, max_ms = 0.0;
  int64_t n = 0;
};

struct XrClientResult {
  int64_t frames = 0;       // frames begun
  int64_t frames_sent = 0;  // frames projected and handed to the transport
  int64_t frames_rendered = 0;
  int64_t sessions = 0;            // OpenXR sessions created (more than 1 after a session loss)
  int64_t slam_sessions = 0;       // client sessions (1 + resets)
  int64_t controller_presses = 0;  // OpenXR action presses (each applied as a control)
  bool instance_lost = false;
  double ate_rmse = -1.0;  // from the run outputs (Sim3-aligned)
  TimingStats projection, handoff, overlay, frame;
  std::string summary;  // one line
};

// Runs until the runtime ends the session (or the instance is lost, or max_frames / quit),
// then writes trajectory.tum, groundtruth.tum, keyframes.tum, metrics.json, trajectory.png,
// map.png and xr_metrics.json to out_dir.
Expected<XrClientResult> RunXrClient(const XrClientOptions& options, XrPlatform* platform);

}  // namespace m2s::xr
