// SLAM accuracy benchmark: ATE (Sim3 aligned), lost / skipped frames, map error and Track()
// times on the default scene for the default trajectory and generated room sequences, at
// several frame rates, with noise-free features, noisy features (0.5 px + 1% wrong ids) and in
// real time (wall-clock pacing into the latest-wins queue).
//
//   bench_slam_accuracy                               # everything (about 25 min)
//   bench_slam_accuracy --fps 30 --duration 20 --modes noise-free --sequences default
//   bench_slam_accuracy --json results.json
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "accuracy_run.h"

namespace {

using m2s::bench::RunMetrics;

constexpr double kNoiseFreeAteBoundM = 0.001;
constexpr double kNoisyAteBoundM = 0.005;

bool Passes(const RunMetrics& m) {
  const bool noisy = m.mode.find("noisy") != std::string::npos;
  return m.ate_rmse_m >= 0.0 && m.ate_rmse_m < (noisy ? kNoisyAteBoundM : kNoiseFreeAteBoundM) &&
         m.lost == 0;
}

nlohmann::json ToJson(const RunMetrics& m) {
  return {{"sequence", m.sequence},
          {"mode", m.mode},
          {"fps", m.fps},
          {"frames", m.frames},
          {"tracked", m.tracked},
          {"init_frames", m.init_frames},
          {"lost", m.lost},
          {"rejected", m.rejected},
          {"skipped", m.skipped},
          {"relocalisations", m.relocalisations},
          {"maps", m.maps},
          {"frames_in_unmerged_maps", m.frames_in_unmerged_maps},
          {"loop_corrections", m.loop_corrections},
          {"keyframes", m.keyframes},
          {"map_points", m.map_points},
          {"shown_points", m.shown_points},
          {"mean_features", m.mean_features},
          {"ate_rmse_m", m.ate_rmse_m},
          {"ate_max_m", m.ate_max_m},
          {"ate_online_rmse_m", m.ate_online_rmse_m},
          {"map_rmse_m", m.map_rmse_m},
          {"map_median_m", m.map_median_m},
          {"map_p90_m", m.map_p90_m},
          {"map_p95_m", m.map_p95_m},
          {"map_far_fraction", m.map_far_fraction},
          {"scale", m.scale},
          {"track_median_ms", m.track_median_ms},
          {"track_p90_ms", m.track_p90_ms},
          {"keyframe_median_ms", m.keyframe_median_ms},
          {"wall_s", m.wall_s},
          {"pass", Passes(m)}};
}

void PrintHeader() {
  std::printf(
      "%-10s %-20s %5s %6s %6s %5s %5s %6s %4s %5s %6s %6s %10s %10s %10s %10s %10s %10s %10s "
      "%6s %7s %7s %7s %5s\n",
      "sequence", "mode", "fps", "frames", "track", "init", "lost", "skip", "KFs", "feat", "points",
      "shown", "ATE[mm]", "ATEonl[mm]", "ATEmax[mm]", "map[mm]", "mapmed[mm]", "map90[mm]",
      "map95[mm]", "far[%]", "trk[ms]", "p90[ms]", "KF[ms]", "pass");
}

void PrintRow(const RunMetrics& m) {
  std::printf(
      "%-10s %-20s %5.0f %6d %6d %5d %5d %6d %4d %5.0f %6d %6d %10.4f %10.4f %10.4f %10.4f %10.4f "
      "%10.4f %10.4f %6.2f %7.3f %7.3f %7.2f %5s\n",
      m.sequence.c_str(), m.mode.c_str(), m.fps, m.frames, m.tracked, m.init_frames, m.lost,
      m.skipped, m.keyframes, m.mean_features, m.map_points, m.shown_points, 1e3 * m.ate_rmse_m,
      1e3 * m.ate_online_rmse_m, 1e3 * m.ate_max_m, 1e3 * m.map_rmse_m, 1e3 * m.map_median_m,
      1e3 * m.map_p90_m, 1e3 * m.map_p95_m, 100.0 * m.map_far_fraction, m.track_median_ms,
      m.track_p90_ms, m.keyframe_median_ms, Passes(m) ? "yes" : "NO");
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Mesh2SLAM accuracy benchmark (ATE, lost/skipped frames, map error)"};
  std::vector<double> fps = {30, 60, 75, 120};
  std::vector<std::string> modes = {"noise-free", "noisy", "realtime"};
  std::vector<std::string> sequences = {"default", "room-s2", "room-s3"};
  double duration_s = 0.0;
  int feature_budget = -1;
  double init_parallax_deg = -1.0;
  int vertex_stride = 1;
  double max_point_uncertainty = -1.0;
  int min_constrained_points = -1;
  double noise_px = 0.5;
  double wrong_ids = 0.01;
  std::string json_path;
  std::string dump_dir;
  std::optional<double> acceleration_sigma;
  app.add_option("--fps", fps, "frame rates")->check(CLI::PositiveNumber);
  app.add_option("--modes", modes, "noise-free, noisy, realtime, realtime-noisy")
      ->check(CLI::IsMember({"noise-free", "noisy", "realtime", "realtime-noisy"}));
  app.add_option("--sequences", sequences, "default and/or room-s<seed>");
  app.add_option("--duration", duration_s, "sequence length in seconds (0: 60 s)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--budget", feature_budget,
                 "features SLAM uses per frame, the balanced selection of the visible vertices "
                 "(0: all; default: the library's)")
      ->check(CLI::Range(-1, 1 << 30));
  app.add_option("--init-parallax-deg", init_parallax_deg,
                 "slam::Options::initializer.min_parallax_deg (default: the library's)")
      ->check(CLI::PositiveNumber);
  app.add_option("--max-point-uncertainty", max_point_uncertainty,
                 "slam::Options::mapper.max_point_uncertainty: points shown and used for "
                 "tracking (inf: all; default: the library's)")
      ->check(CLI::PositiveNumber);
  app.add_option("--min-constrained-points", min_constrained_points,
                 "slam::Options::tracker.min_constrained_points (default: the library's)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--vertex-stride", vertex_stride,
                 "use only vertices with id % stride == 0 (a consistent, sparser scene)")
      ->check(CLI::PositiveNumber);
  app.add_option("--noise-px", noise_px, "noisy modes: Gaussian pixel noise sigma")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--wrong-ids", wrong_ids, "noisy modes: fraction of features with a wrong id")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--dump-trajectories", dump_dir,
                 "write aligned estimate and truth (TUM) per run into this folder");
  app.add_option("--acceleration-sigma", acceleration_sigma,
                 "slam::Options::refine_acceleration_sigma in map units/s^2: the motion prior of "
                 "RefineMap's last step (0: none; default: the library's)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--json", json_path, "also write the results as JSON to this file");
  CLI11_PARSE(app, argc, argv);

  std::vector<uint64_t> seeds;
  for (const std::string& name : sequences) {
    if (name == "default") continue;
    if (name.rfind("room-s", 0) != 0) {
      std::cerr << "bench_slam_accuracy: unknown sequence '" << name
                << "' (default, room-s<seed>)\n";
      return 2;
    }
    try {
      seeds.push_back(std::stoull(name.substr(6)));
    } catch (const std::exception&) {
      std::cerr << "bench_slam_accuracy: bad seed in sequence name '" << name << "'\n";
      return 2;
    }
  }
  m2s::Expected<std::vector<m2s::bench::Sequence>> made =
      m2s::bench::MakeSequences(seeds, duration_s);
  if (!made) {
    std::cerr << "bench_slam_accuracy: " << made.error() << "\n";
    return 1;
  }
  const bool want_default =
      std::find(sequences.begin(), sequences.end(), "default") != sequences.end();
  const m2s::Scene scene = m2s::MakeDefaultScene();

  nlohmann::json rows = nlohmann::json::array();
  bool all_pass = true;
  PrintHeader();
  for (const m2s::bench::Sequence& sequence : *made) {
    if (sequence.name == "default" && !want_default) continue;
    for (const std::string& mode : modes) {
      for (double rate : fps) {
        m2s::bench::RunConfig config;
        config.acceleration_sigma = acceleration_sigma;
        config.fps = rate;
        config.noisy = mode == "noisy" || mode == "realtime-noisy";
        config.realtime = mode.rfind("realtime", 0) == 0;
        config.feature_budget = feature_budget;
        config.init_min_parallax_deg = init_parallax_deg;
        config.max_point_uncertainty = max_point_uncertainty;
        config.min_constrained_points = min_constrained_points;
        config.vertex_stride = vertex_stride;
        config.noise_px = noise_px;
        if (!dump_dir.empty()) {
          config.dump_prefix = dump_dir + "/" + sequence.name + "_" + mode + "_" +
                               std::to_string(static_cast<int>(rate));
        }
        config.wrong_id_fraction = wrong_ids;
        m2s::Expected<RunMetrics> metrics = m2s::bench::RunAccuracy(scene, sequence, config);
        if (!metrics) {
          std::cerr << "bench_slam_accuracy: " << sequence.name << " " << mode << " " << rate
                    << " fps: " << metrics.error() << "\n";
          return 1;
        }
        PrintRow(*metrics);
        all_pass = all_pass && Passes(*metrics);
        rows.push_back(ToJson(*metrics));
      }
    }
  }
  std::printf("all within bounds (noise-free ATE < 1 mm, noisy < 5 mm, no lost frames): %s\n",
              all_pass ? "yes" : "NO");
  if (!json_path.empty()) {
    std::ofstream out(json_path);
    out << rows.dump(2) << "\n";
    if (!out) {
      std::cerr << "bench_slam_accuracy: cannot write " << json_path << "\n";
      return 1;
    }
  }
  return 0;
}
