// The headless client's run: a scene and a trajectory resampled at `fps` become frames
// (projector -> noise -> codec with the vertex front end; rendered image -> ORB features with
// track ids -> codec with the ORB front end, OrbFrameSource), sent over a transport (on-device or
// LCM) in real time (frames the client cannot produce in time are skipped; the server's latest-wins
// queue skips the frames SLAM cannot take) or, with `fast`, one frame at a time waiting for each
// pose (deterministic). The outputs are written by reporting::WriteRunOutputs. A run that no server
// ever answered (none listening, the server full, or every answer refused) is an error.
//
//   HeadlessOptions options;            // default scene, default trajectory, on-device
//   options.fast = true;
//   Expected<RunMetrics> metrics = RunHeadless(options);
#pragma once

#include <functional>
#include <optional>
#include <string>

#include "m2s/common/bus_auth.h"
#include "m2s/common/feature_noise.h"
#include "m2s/common/projector.h"
#include "m2s/image_features/orb_front_end.h"
#include "m2s/reporting/run_outputs.h"
#include "m2s/server_app/session_manager.h"

namespace m2s::headless {

// The pixel noise the SLAM back end should assume for ORB features (slam::Options::pixel_sigma,
// 1 px by default): ORB keypoints of the rendered textured room are located to about 0.5 px
// (docs/design/orb_front_end.md); 0.7 keeps a margin. m2s_client sets it with --front-end orb.
inline constexpr double kOrbPixelSigma = 0.7;

struct HeadlessOptions {
  std::string mesh_path;        // empty: MakeDefaultScene()
  std::string trajectory_path;  // TUM; empty: DefaultTrajectory()
  // Scripted edits of the scene's parts (m2s/common/scene_events.h), applied before the first
  // frame at or after their time; needs the vertex front end and the CPU projector. The run's
  // map error is then measured against the positions at the end.
  std::string scene_events_path;
  Camera camera = Camera::FromHorizontalFov(640, 480, 90.0);
  double fps = 75.0;
  bool fast = false;
  bool on_device = true;
  std::string lcm_url = wire::kDefaultLcmUrl;
  wire::BusSecurityOptions bus;   // LCM only: key, encryption, replay checks
  std::string projector = "gpu";  // "gpu" (CPU fallback when EGL fails) or "cpu"
  ProjectorOptions projector_options = ProjectorOptions::Occluding();
  FeatureNoiseOptions noise;
  // "vertex": projected mesh vertices, ids = vertex ids. "orb": the scene rendered (textures
  // when the mesh has them; needs EGL), ORB features with track ids (orb); the noise options
  // must then be off, and neither the projector nor send_budget is used.
  std::string front_end = "vertex";
  image_features::OrbFrontEnd::Options orb;
  // At most this many features a frame are sent, the lowest-ranked ids (0: all); by default
  // the SLAM feature budget, so the server gets exactly the subset it would use.
  int send_budget = slam::Options().feature_budget;
  std::string out_dir = "out";
  bool progress = false;  // a progress line on stderr
  bool render_map = true;
  // Only the first max_frames frames (0: all), for short tests.
  int max_frames = 0;
  // How long to wait for a pose in --fast mode, and for the last pose at the end.
  double pose_timeout_s = 10.0;
  // The on-device server's localisation method: "" or "vertex_slam" (the built-in SLAM) or a
  // plug-in's name or path (m2s/plugin/plugin_system.h), with its config (a JSON object's text;
  // empty: none). A plug-in refuses map groups.
  std::string method;
  std::string method_config;
  // Server options of the on-device session manager.
  server_app::ServerOptions server;
  // When not empty, every message the client publishes is also written to this LCM log.
  std::string record_log;
  // The map group the session joins (m2s_client --map-group; empty: none).
  std::string map_group;
  // Session ids (0: random).
  uint64_t session_seed = 0;
  // Called after each frame is sent, with its index (tests inject events here).
  std::function<void(int64_t)> on_frame_sent;
};

// One line the caller should print (e.g. the GPU -> CPU fallback); empty when none.
struct HeadlessResult {
  reporting::RunMetrics metrics;
  std::string notice;
  client::ClientCounters counters;
};

Expected<HeadlessResult> RunHeadless(const HeadlessOptions& options);

// The front-end options alone (RunHeadless checks them too): an unknown front end, noise
// options or a feature count over the SLAM budget with the ORB front end, bad ORB options.
Status CheckFrontEnd(const HeadlessOptions& options);

}  // namespace m2s::headless
