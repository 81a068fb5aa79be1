// m2s_replay: replays an lcm-logger log of a Mesh2SLAM session through the server's session
// logic, deterministically and as fast as possible, and writes the same outputs as the live
// run (trajectory.tum, keyframes.tum, groundtruth.tum, metrics.json, trajectory.png, map.png).
//
//   m2s_replay LOG [--out DIR] [--mesh FILE] [--no-map-png]
#include <iostream>

#include <CLI/CLI.hpp>

#include "m2s/common/logging.h"
#include "m2s/replay/replay.h"

int main(int argc, char** argv) {
  m2s::replay::ReplayOptions options;
  CLI::App app{"Mesh2SLAM replay: an lcm-logger log through the SLAM server, deterministic"};
  app.add_option("LOG", options.log_path, "lcm-logger log file")->required();
  app.add_option("--out", options.out_dir, "Output folder")->capture_default_str();
  app.add_option("--mesh", options.mesh_path, "The run's scene (default: the default scene)");
  app.add_flag(
      "--no-map-png", [&options](int64_t) { options.render_map = false; }, "Do not render map.png");
  CLI11_PARSE(app, argc, argv);
  m2s::SetMinLogLevel(m2s::LogLevel::kWarning);
  auto result = m2s::replay::Replay(options);
  if (!result) {
    std::cerr << "m2s_replay: " << result.error() << "\n";
    return 1;
  }
  if (!result->log_problem.empty()) std::cerr << "m2s_replay: " << result->log_problem << "\n";
  std::cout << m2s::reporting::SummaryLine(result->metrics, options.out_dir) << "\n";
  if (!result->metrics.map_png.empty()) std::cout << "map: " << result->metrics.map_png << "\n";
  std::cout << "trajectory: " << result->metrics.trajectory_png << "\n";
  return 0;
}
