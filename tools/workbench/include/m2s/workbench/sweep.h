// Sweeps of the workbench (m2s_bench): localisation methods x scenes x frame rates x noise
// levels, each cell one deterministic `m2s_client --on-device --fast` run in its own folder.
//
// A sweep file is JSON (paths relative to the file's folder):
//   {
//     "methods": [{"name": "vertex"},                          // the built-in SLAM
//                 {"name": "orb", "front_end": "orb"},         // ORB features on rendered images
//                 {"name": "pnp", "plugin": "pnp_odometry"},   // a plug-in, by name or path
//                 {"name": "mine", "plugin": "python", "plugin_config": "cfg.json"}],
//     "scenes": [{"name": "room"},                             // no mesh: the default scene
//                {"name": "house", "mesh": "house.obj", "trajectory": "walk.tum",
//                 "camera": "CAMERA.json", "duration_s": 20, "args": ["--scale", "0.01"]}],
//     "fps": [30, 60, 75], "noise_px": [0, 0.5, 1.0], "outlier_ids": [0, 0.01],
//     "occlusion": true, "duration_s": 0, "timeout_s": 600, "client_args": ["--budget", "1000"]
//   }
// Every list but methods and scenes is optional (defaults: fps [30], noise_px [0],
// outlier_ids [0]). Unknown keys are errors, so a typo does not silently run another sweep.
// Feature noise does not apply to image front ends: those cells are reported as skipped.
//
//   Expected<SweepConfig> config = ReadSweepConfig("sweep.json");
//   for (const Cell& cell : ExpandCells(*config)) ClientArguments(*config, cell, "out/runs/x");
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "m2s/common/status.h"

namespace m2s::workbench {

struct MethodSpec {
  std::string name;                  // the column label; [A-Za-z0-9_.-]+
  std::string front_end = "vertex";  // m2s_client --front-end
  std::string plugin;                // m2s_client --method (empty: the built-in SLAM)
  std::string plugin_config;         // m2s_client --method-config (absolute after parsing)
  std::vector<std::string> args;     // more m2s_client arguments
  bool takes_feature_noise() const { return front_end == "vertex"; }
};

struct SceneSpec {
  std::string name;        // [A-Za-z0-9_.-]+
  std::string mesh;        // empty: the embedded default scene
  std::string trajectory;  // empty: the client's default trajectory
  std::string camera;      // CAMERA.json; empty: the client's default camera
  double duration_s = 0;   // only the first seconds of the trajectory (0: all)
  std::vector<std::string> args;
};

struct SweepConfig {
  std::vector<MethodSpec> methods;
  std::vector<SceneSpec> scenes;
  std::vector<double> fps = {30.0};
  std::vector<double> noise_px = {0.0};
  std::vector<double> outlier_ids = {0.0};
  bool occlusion = true;
  double duration_s = 0;   // the first seconds of every trajectory (0: all); a scene's wins
  double timeout_s = 600;  // per run
  std::vector<std::string> client_args;

  Status Check() const;
};

// Parses a sweep; relative paths are resolved against base_dir.
Expected<SweepConfig> ParseSweepConfig(const nlohmann::json& json, const std::string& base_dir);
Expected<SweepConfig> ReadSweepConfig(const std::string& path);

// One run of the sweep.
struct Cell {
  size_t method = 0;  // index into SweepConfig::methods
  size_t scene = 0;   // index into SweepConfig::scenes
  double fps = 30.0;
  double noise_px = 0.0;
  double outlier_ids = 0.0;

  // "method__scene__30fps__n0.5__o0.01": the run's folder name, unique within a sweep.
  std::string Name(const SweepConfig& config) const;
};

// Every combination, in the order methods, scenes, fps, noise_px, outlier_ids (outermost first).
std::vector<Cell> ExpandCells(const SweepConfig& config);

// Why the cell does not run (empty when it does): feature noise with an image front end.
std::string SkipReason(const SweepConfig& config, const Cell& cell);

// The m2s_client arguments of a cell (without the executable), writing into out_dir.
std::vector<std::string> ClientArguments(const SweepConfig& config, const Cell& cell,
                                         const std::string& out_dir);

}  // namespace m2s::workbench
