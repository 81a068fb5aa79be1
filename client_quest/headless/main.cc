// m2s_client: the headless Mesh2SLAM client.
//
//   m2s_client [--mesh FILE --trajectory GT.tum] [--camera CAMERA.json | --width W --height H
//              --fov-deg F] [--fps F] [--fast] [--on-device | --lcm-url URL]
//              [--projector gpu|cpu] [--no-occlusion] [--noise-px S --outlier-ids P --dropout P
//              --seed N] [--front-end vertex|orb [--orb-features N]] [--key-file FILE
//              [--encrypt]] [--map-group NAME] [--out DIR]
//              [--method NAME [--method-config FILE.json]] [--scene-events FILE]
//
// --front-end orb: each frame is rendered (the mesh's textures when it has them) and turned
// into ORB features with track ids instead of projected vertices; metrics.json then reports
// the render, extraction and matching times and the tracking time per frame (front end +
// SLAM tracking). Needs EGL; the noise options do not apply.
//
// --method NAME (on-device only): the in-process server's localisation method: vertex_slam
// (default, the built-in SLAM) or a plug-in's name or path (docs/design/plugins.md), with its
// options from --method-config. A plug-in cannot join a map group.
//
// --map-group NAME: the session joins the server's map group NAME (collaborative SLAM: every
// client of a group shares one map); metrics.json then reports merged_at_s.
//
// --scene-events FILE: scripted run-time edits of the scene's parts (move, remove, add a copy;
// m2s/common/scene_events.h), applied at their times; the CPU projector follows them.
//
// Without --mesh / --trajectory it uses the embedded default scene and its trajectory.
// Prints one summary line (and a progress line while running on a terminal).
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <iostream>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "m2s/common/camera_io.h"
#include "m2s/common/logging.h"
#include "m2s/headless/headless_run.h"
#include "m2s/plugin/plugin_system.h"

int main(int argc, char** argv) {
  m2s::headless::HeadlessOptions options;
  std::string camera_json;
  int width = 640, height = 480;
  double fov_deg = 90.0;
  std::string lcm_url;
  bool on_device = false;
  CLI::App app{"Mesh2SLAM headless client: streams vertex features of a scene to a SLAM server"};
  app.add_option("--mesh", options.mesh_path, "Scene mesh (any format assimp reads)");
  app.add_option("--trajectory", options.trajectory_path, "Ground-truth trajectory (TUM)");
  app.add_option("--scene-events", options.scene_events_path,
                 "Scripted part edits: lines 'TIME move|remove|add PART ...' (CPU projector)");
  auto* camera_opt = app.add_option("--camera", camera_json, "CAMERA.json");
  auto* width_opt = app.add_option("--width", width, "Image width (px)")->capture_default_str();
  auto* height_opt = app.add_option("--height", height, "Image height (px)")->capture_default_str();
  auto* fov_opt =
      app.add_option("--fov-deg", fov_deg, "Horizontal field of view")->capture_default_str();
  camera_opt->excludes(width_opt)->excludes(height_opt)->excludes(fov_opt);
  app.add_option("--fps", options.fps, "Frame rate")->capture_default_str();
  app.add_flag("--fast", options.fast, "Every frame, as fast as possible, deterministic");
  auto* device_opt = app.add_flag("--on-device", on_device, "Run the server in-process (default)");
  auto* url_opt = app.add_option("--lcm-url", lcm_url, "LCM URL of a running m2s_server");
  device_opt->excludes(url_opt);
  app.add_option("--projector", options.projector, "gpu (default, CPU fallback) or cpu")
      ->capture_default_str();
  app.add_flag("--occlusion,!--no-occlusion", options.projector_options.occlusion,
               "Remove vertices hidden behind nearer surfaces (default; --no-occlusion projects "
               "every vertex in view, the paper's setting)");
  app.add_option("--noise-px", options.noise.pixel_noise_sigma, "Gaussian pixel noise (px)");
  app.add_option("--outlier-ids", options.noise.wrong_id_fraction, "Fraction of wrong ids");
  app.add_option("--dropout", options.noise.dropout_probability, "Feature dropout probability");
  app.add_option("--seed", options.noise.seed, "Noise seed");
  app.add_option("--front-end", options.front_end,
                 "vertex (projected mesh vertices) or orb (ORB features of rendered images)")
      ->check(CLI::IsMember({"vertex", "orb"}))
      ->capture_default_str();
  app.add_option("--orb-features", options.orb.num_features,
                 "--front-end orb: at most N ORB features a frame")
      ->capture_default_str();
  double duration_s = 0;
  app.add_option("--duration", duration_s, "Only the first S seconds of the trajectory");
  int budget = options.server.slam.feature_budget;
  app.add_option("--budget", budget,
                 "At most N features a frame, sent and used by SLAM: the balanced, id-stable "
                 "selection (0: all)")
      ->capture_default_str();
  std::string key_file;
  bool encrypt = false;
  double max_message_age_s = options.bus.opener.max_age_s;
  app.add_option("--key-file", key_file, "Shared secret of the bus: authenticate every message");
  app.add_flag("--encrypt", encrypt, "Also encrypt payloads (needs --key-file)");
  app.add_option("--max-message-age", max_message_age_s,
                 "Keyed bus: refuse messages older than S seconds (0: no check)")
      ->capture_default_str();
  app.add_option("--pose-timeout", options.pose_timeout_s,
                 "--fast: seconds to wait for each pose (a run nobody answers ends after one)")
      ->capture_default_str();
  app.add_option("--record", options.record_log, "Also write the sent messages to this LCM log");
  app.add_option("--map-group", options.map_group,
                 "Join this map group (at most 64 characters of A-Z a-z 0-9 _ . -)");
  app.add_option("--out", options.out_dir, "Output folder")->capture_default_str();
  app.add_flag(
      "--no-map-png", [&options](int64_t) { options.render_map = false; }, "Do not render map.png");
  std::string method_config;
  app.add_option("--method", options.method,
                 "On-device localisation method: vertex_slam (built in) or a plug-in's name or "
                 "path");
  app.add_option("--method-config", method_config, "The plug-in's options (JSON object file)");
  bool verbose = false;
  app.add_flag("--verbose", verbose,
               "--on-device: log the SLAM system's info and debug messages (initialisation, "
               "refusals, drift checks)");
  CLI11_PARSE(app, argc, argv);
  options.send_budget = options.server.slam.feature_budget = budget;

  if (m2s::Status name = m2s::wire::CheckMapGroupName(options.map_group); !name) {
    std::cerr << "m2s_client: --map-group: " << name.message() << "\n";
    return 2;
  }
  if (!m2s::plugin::IsBuiltinMethod(options.method) || !method_config.empty()) {
    if (!lcm_url.empty()) {
      std::cerr << "m2s_client: --method runs on-device; give it to m2s_server with --lcm-url\n";
      return 2;
    }
    if (!options.map_group.empty()) {
      std::cerr << "m2s_client: --map-group needs the built-in SLAM (--method vertex_slam)\n";
      return 2;
    }
  }
  if (!method_config.empty()) {
    auto text = m2s::plugin::ReadMethodConfig(method_config);
    if (!text) {
      std::cerr << "m2s_client: " << text.error() << "\n";
      return 2;
    }
    options.method_config = *text;
  }
  if (!camera_json.empty()) {
    auto camera = m2s::ReadCameraJson(camera_json);
    if (!camera) {
      std::cerr << "m2s_client: " << camera.error() << "\n";
      return 2;
    }
    options.camera = *camera;
  } else {
    if (!(fov_deg > 0 && fov_deg < 180)) {
      std::cerr << "m2s_client: --fov-deg must be in (0, 180)\n";
      return 2;
    }
    options.camera = m2s::Camera::FromHorizontalFov(width, height, fov_deg);
  }
  if (duration_s > 0)
    options.max_frames = std::max(1, static_cast<int>(duration_s * options.fps) + 1);
  auto security = m2s::wire::MakeBusSecurity(key_file, encrypt, max_message_age_s);
  if (!security) {
    std::cerr << "m2s_client: " << security.error() << "\n";
    return 2;
  }
  options.bus = *security;
  options.on_device = lcm_url.empty();
  if (!lcm_url.empty()) options.lcm_url = lcm_url;
  options.progress = isatty(STDERR_FILENO) != 0;
  m2s::SetMinLogLevel(verbose ? m2s::LogLevel::kDebug : m2s::LogLevel::kWarning);

  // ORB keypoints are not exact: the back end assumes their measured noise.
  if (options.front_end == "orb") options.server.slam.pixel_sigma = m2s::headless::kOrbPixelSigma;
  if (m2s::Status s = m2s::headless::CheckFrontEnd(options); !s) {
    std::cerr << "m2s_client: " << s.message() << "\n";
    return 2;
  }
  auto result = m2s::headless::RunHeadless(options);
  if (!result) {
    std::cerr << "m2s_client: " << result.error() << "\n";
    return 1;
  }
  if (!result->notice.empty()) std::cerr << "m2s_client: " << result->notice << "\n";
  std::cout << m2s::reporting::SummaryLine(result->metrics, options.out_dir) << "\n";
  if (!result->metrics.map_png.empty()) std::cout << "map: " << result->metrics.map_png << "\n";
  std::cout << "trajectory: " << result->metrics.trajectory_png << "\n";
  return 0;
}
