// m2s_xr_client: the OpenXR client on a desktop runtime (XR_MNDX_egl_enable), e.g. Monado or
// the simulated runtime of the tests (XR_RUNTIME_JSON=<build>/xr_sim_runtime/...json).
//
//   m2s_xr_client [--config FILE.json] [--mesh FILE] [--on-device | --lcm-url URL]
//                 [--projector gpu|cpu] [--width W --height H --fov-deg F] [--stage]
//                 [--frames N] [--events reset@N,overlay@N,others@N,quit@N] [--keys]
//                 [--no-overlay] [--no-mesh] [--no-occlusion] [--budget N] [--noise-px S] [--seed
//                 N]
//                 [--key-file FILE [--encrypt]] [--out DIR]
//
// The JSON config (the file a headset build reads from its storage) has the same settings:
//   {"mesh": "", "transport": "on-device" | "lcm", "lcm_url": "udpm://...?ttl=0",
//    "key_file": "/path/to/bus.key", "encrypt": false,
//    "projector": "gpu", "occlusion": true, "camera": {"width": 640, "height": 480, "fov_deg": 90},
//    "stage": false, "frames": 0, "events": "", "overlay": true, "other_keyframes": true,
//    "mesh_visible": true, "map_group": "", "out": "out"}
// "method" (default "vertex_slam", the built-in SLAM) names the on-device localisation method:
// a plug-in's name or path (docs/design/plugins.md), "method_config" its options (an object).
// "map_group" names the shared map the SLAM session joins (sent in its HELLO); empty: a map of
// its own. Controller buttons (OpenXR actions) work whatever the config; see xr_actions.h.
// Flags given on the command line override the file.
#include <fstream>
#include <iostream>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "m2s/common/bus_auth.h"
#include "m2s/common/logging.h"
#include "m2s/xr/xr_client.h"

namespace {

using m2s::xr::XrClientOptions;

// Applies the JSON config to the options; false with a reason on a bad file or field.
bool ApplyConfig(const std::string& path, XrClientOptions* options, std::string* events,
                 std::string* key_file, bool* encrypt, std::string* why) {
  std::ifstream file(path);
  if (!file) {
    *why = "cannot open config '" + path + "'";
    return false;
  }
  try {
    const nlohmann::json j = nlohmann::json::parse(file);
    options->mesh_path = j.value("mesh", options->mesh_path);
    const std::string transport = j.value("transport", std::string("on-device"));
    if (transport != "on-device" && transport != "lcm") {
      *why = "config: transport must be \"on-device\" or \"lcm\"";
      return false;
    }
    options->on_device = transport == "on-device";
    options->lcm_url = j.value("lcm_url", options->lcm_url);
    *key_file = j.value("key_file", *key_file);
    *encrypt = j.value("encrypt", *encrypt);
    options->projector = j.value("projector", options->projector);
    options->projector_options.occlusion =
        j.value("occlusion", options->projector_options.occlusion);
    if (j.contains("camera")) {
      const auto& c = j.at("camera");
      options->camera = m2s::Camera::FromHorizontalFov(
          c.value("width", 640), c.value("height", 480), c.value("fov_deg", 90.0));
    }
    options->stage_space = j.value("stage", options->stage_space);
    options->max_frames = j.value("frames", options->max_frames);
    *events = j.value("events", *events);
    options->overlay = j.value("overlay", options->overlay);
    options->show_other_keyframes = j.value("other_keyframes", options->show_other_keyframes);
    options->map_group = j.value("map_group", options->map_group);
    options->method = j.value("method", options->method);
    if (j.contains("method_config")) {
      if (!j.at("method_config").is_object()) {
        *why = "config: method_config must be a JSON object";
        return false;
      }
      options->method_config = j.at("method_config").dump();
    }
    options->draw_mesh = j.value("mesh_visible", options->draw_mesh);
    options->out_dir = j.value("out", options->out_dir);
  } catch (const nlohmann::json::exception& e) {
    *why = "config '" + path + "': " + e.what();
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Mesh2SLAM OpenXR client (OpenXR + GLES through EGL)"};
  std::string config_path, mesh, lcm_url, projector, events, out;
  bool on_device = false, stage = false, keys = false, no_overlay = false, no_mesh = false;
  int width = 640, height = 480, frames = 0;
  double fov_deg = 90.0;
  app.add_option("--config", config_path, "JSON config file (flags override it)");
  app.add_option("--mesh", mesh, "scene mesh (any assimp format); default: the embedded room");
  auto* on_device_flag = app.add_flag("--on-device", on_device, "run SLAM in-process (default)");
  auto* lcm_flag = app.add_option("--lcm-url", lcm_url, "send frames to an m2s_server over LCM");
  auto* projector_flag = app.add_option("--projector", projector, "gpu (default) or cpu");
  auto* width_flag = app.add_option("--width", width, "projection camera width");
  auto* height_flag = app.add_option("--height", height, "projection camera height");
  auto* fov_flag = app.add_option("--fov-deg", fov_deg, "projection camera horizontal fov");
  auto* stage_flag = app.add_flag("--stage", stage, "world space STAGE instead of LOCAL");
  auto* frames_flag = app.add_option("--frames", frames, "request exit after N frames");
  auto* events_flag = app.add_option("--events", events, "scripted controls, e.g. reset@200");
  app.add_flag("--keys", keys,
               "read r (reset) / o (overlay) / k (other agents' keyframes) / q (quit) from stdin");
  auto* overlay_flag = app.add_flag("--no-overlay", no_overlay, "start with the overlay off");
  auto* mesh_flag = app.add_flag("--no-mesh", no_mesh, "do not draw the scene mesh");
  bool no_occlusion = false;
  auto* occlusion_flag = app.add_flag(
      "--no-occlusion", no_occlusion,
      "project every vertex in view, hidden ones too (the paper's setting; default: occlusion)");
  auto* out_flag = app.add_option("--out", out, "output folder (default out)");
  m2s::FeatureNoiseOptions noise;
  int budget = 0;
  auto* budget_flag = app.add_option(
      "--budget", budget, "most features per frame, sent and used by SLAM (balanced, 0: all)");
  app.add_option("--noise-px", noise.pixel_noise_sigma, "pixel noise sigma");
  app.add_option("--seed", noise.seed, "noise seed");
  std::string key_file_flag;
  bool encrypt_flag = false;
  app.add_option("--key-file", key_file_flag, "shared secret of the LCM bus (authenticated)");
  app.add_flag("--encrypt", encrypt_flag, "also encrypt payloads (needs a key)");
  on_device_flag->excludes(lcm_flag);
  CLI11_PARSE(app, argc, argv);

  XrClientOptions options;
  std::string why, event_text, key_file;
  bool encrypt = false;
  if (!config_path.empty() &&
      !ApplyConfig(config_path, &options, &event_text, &key_file, &encrypt, &why)) {
    std::cerr << "m2s_xr_client: " << why << "\n";
    return 2;
  }
  if (!key_file_flag.empty()) key_file = key_file_flag;
  auto security =
      m2s::wire::MakeBusSecurity(key_file, encrypt || encrypt_flag, options.bus.opener.max_age_s);
  if (!security) {
    std::cerr << "m2s_xr_client: " << security.error() << "\n";
    return 2;
  }
  options.bus = *security;
  if (!mesh.empty()) options.mesh_path = mesh;
  if (*on_device_flag) options.on_device = true;
  if (*lcm_flag) {
    options.on_device = false;
    options.lcm_url = lcm_url;
  }
  if (*projector_flag) options.projector = projector;
  if (*width_flag || *height_flag || *fov_flag) {
    options.camera = m2s::Camera::FromHorizontalFov(width, height, fov_deg);
  }
  if (*stage_flag) options.stage_space = true;
  if (*frames_flag) options.max_frames = frames;
  if (*events_flag) event_text = events;
  if (*overlay_flag) options.overlay = false;
  if (*mesh_flag) options.draw_mesh = false;
  if (*occlusion_flag) options.projector_options.occlusion = false;
  if (*out_flag) options.out_dir = out;
  options.stdin_keys = keys;
  options.noise = noise;
  if (*budget_flag) options.send_budget = options.server.slam.feature_budget = budget;
  auto parsed = m2s::xr::ParseControlEvents(event_text);
  if (!parsed) {
    std::cerr << "m2s_xr_client: " << parsed.error() << "\n";
    return 2;
  }
  options.events = *parsed;
  if (m2s::Status valid = options.Check(); !valid) {
    std::cerr << "m2s_xr_client: " << valid.message() << "\n";
    return 2;
  }
  auto platform = m2s::xr::MakePlatform(nullptr);
  auto result = m2s::xr::RunXrClient(options, platform.get());
  if (!result) {
    std::cerr << "m2s_xr_client: " << result.error() << "\n";
    return 1;
  }
  std::cout << result->summary << std::endl;
  return 0;
}
