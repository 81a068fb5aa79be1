// Scene-diversity benchmark: every scene of a manifest (tools/bench_slam/scenes.json, meshes
// gathered by tools/bench_slam/make_corpus.sh) x every motion (head, hand-held, drone) x every
// feature mode (noise-free, noisy = 0.5 px + 1% wrong ids, noisy with occlusion), deterministic
// (mapping inline), one frame rate. Prints a markdown table: ATE (of the final trajectory,
// after System::RefineMap, and online), tracked frames (in brackets those that got their pose
// once their map initialised), lost frames (frames with fewer than --min-visible visible
// vertices are counted apart), keyframes, map error.
//
//   tools/bench_slam/make_corpus.sh
//   bench_scenes --manifest tools/bench_slam/scenes.json --mesh-root ~/.cache/m2s-corpus/meshes
//   bench_scenes ... --scenes lowpoly-interior --motions drone --modes noisy --duration 10
//   bench_scenes ... --list          # the scenes: vertices, triangles, obstacles, targets
//   bench_scenes --mesh dragons.ply --trajectory walk.tum --name large-world
//                                    # one scene file with its own trajectory (the large-world
//                                    # row; the projector uses every core)
//   bench_scenes ... --motions-only --write-motion out/   # the motions and composed scenes
//   bench_scenes ... --dump out/     # each run's aligned estimate and ground truth (TUM)
//   bench_scenes ... --verbose       # the SLAM system's debug log (initialisation refusals)
//   bench_scenes ... --no-refine     # final trajectory and map without System::RefineMap
//   bench_scenes ... --more-views-after -1   # two-view initialisation only
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "accuracy_run.h"
#include "m2s/common/logging.h"
#include "m2s/common/scene.h"
#include "m2s/common/scene_io.h"
#include "m2s/common/trajectory.h"
#include "m2s/slam/options.h"
#include "scene_corpus.h"

namespace {

using m2s::bench::RunMetrics;

struct Mode {
  std::string name;
  bool noisy;
  bool occlusion;
};
const std::vector<Mode> kModes = {
    {"noise-free", false, false}, {"noisy", true, false}, {"noisy-occlusion", true, true}};

std::string Mm(double metres) {
  if (metres < 0.0) return "-";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.3f", 1e3 * metres);
  return buffer;
}

void PrintHeader() {
  std::printf(
      "| scene | motion | mode | frames | visible (median) | init | tracked (late) | lost | "
      "few-visible untracked / frames | maps | unmerged | KFs | ATE RMSE (mm) | ATE max (mm) | "
      "ATE online (mm) | map median (mm) | map RMSE (mm) | wall (s) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
}

void PrintRow(const std::string& scene, const std::string& motion, const RunMetrics& m) {
  std::printf(
      "| %s | %s | %s | %d | %.0f | %d | %d (%d) | %d | %d / %d | %d | %lld | %d | %s | %s | %s | "
      "%s | %s | %.1f |\n",
      scene.c_str(), motion.c_str(), m.mode.c_str(), m.frames, m.median_visible, m.init_frames,
      m.tracked, m.late, m.untracked, m.untracked_few_visible, m.few_visible, m.maps,
      static_cast<long long>(m.frames_in_unmerged_maps), m.keyframes, Mm(m.ate_rmse_m).c_str(),
      Mm(m.ate_max_m).c_str(), Mm(m.ate_online_rmse_m).c_str(), Mm(m.map_median_m).c_str(),
      Mm(m.map_rmse_m).c_str(), m.wall_s);
  std::fflush(stdout);
}

nlohmann::json ToJson(const std::string& scene, const std::string& motion, const RunMetrics& m) {
  return {{"scene", scene},
          {"motion", motion},
          {"mode", m.mode},
          {"fps", m.fps},
          {"frames", m.frames},
          {"median_visible", m.median_visible},
          {"init_frames", m.init_frames},
          {"tracked", m.tracked},
          {"late", m.late},
          {"lost", m.untracked},
          {"untracked_few_visible", m.untracked_few_visible},
          {"few_visible", m.few_visible},
          {"maps", m.maps},
          {"frames_in_unmerged_maps", m.frames_in_unmerged_maps},
          {"relocalisations", m.relocalisations},
          {"keyframes", m.keyframes},
          {"map_points", m.map_points},
          {"ate_rmse_m", m.ate_rmse_m},
          {"ate_max_m", m.ate_max_m},
          {"ate_online_rmse_m", m.ate_online_rmse_m},
          {"map_median_m", m.map_median_m},
          {"map_rmse_m", m.map_rmse_m},
          {"scale", m.scale},
          {"wall_s", m.wall_s}};
}

bool Selected(const std::vector<std::string>& wanted, const std::string& name) {
  return wanted.empty() || std::find(wanted.begin(), wanted.end(), name) != wanted.end();
}

// Runs `sequence` through `scene` in every selected mode, printing (and collecting) the rows.
bool RunModes(const m2s::Scene& scene, const std::string& scene_name, const std::string& motion,
              const m2s::bench::Sequence& sequence, const std::vector<std::string>& modes,
              m2s::bench::RunConfig config, const std::string& dump_dir, nlohmann::json* rows) {
  for (const Mode& mode : kModes) {
    if (!Selected(modes, mode.name)) continue;
    config.noisy = mode.noisy;
    config.occlusion = mode.occlusion;
    if (!dump_dir.empty())
      config.dump_prefix = dump_dir + "/" + scene_name + "_" + motion + "_" + mode.name;
    m2s::Expected<RunMetrics> metrics = m2s::bench::RunAccuracy(scene, sequence, config);
    if (!metrics) {
      std::cerr << "bench_scenes: " << sequence.name << " " << mode.name << ": " << metrics.error()
                << "\n";
      return false;
    }
    metrics->mode = mode.name;
    PrintRow(scene_name, motion, *metrics);
    rows->push_back(ToJson(scene_name, motion, *metrics));
  }
  return true;
}

// --mesh / --trajectory: one scene file with its own trajectory (the motion column shows the
// trajectory's file name without its extension).
int RunSceneFile(const std::string& mesh, const std::string& trajectory_path,
                 const std::string& name, const std::vector<std::string>& modes,
                 const m2s::bench::RunConfig& config, const std::string& dump_dir,
                 nlohmann::json* rows) {
  m2s::Expected<m2s::Scene> scene = m2s::LoadScene(mesh);
  if (!scene) {
    std::cerr << "bench_scenes: " << scene.error() << "\n";
    return 1;
  }
  m2s::Expected<m2s::Trajectory> trajectory = m2s::ReadTum(trajectory_path);
  if (!trajectory) {
    std::cerr << "bench_scenes: " << trajectory.error() << "\n";
    return 1;
  }
  std::string motion = trajectory_path.substr(trajectory_path.find_last_of('/') + 1);
  motion = motion.substr(0, motion.find_last_of('.'));
  const m2s::bench::Sequence sequence{name + "/" + motion, std::move(*trajectory)};
  PrintHeader();
  return RunModes(*scene, name, motion, sequence, modes, config, dump_dir, rows) ? 0 : 1;
}

bool WriteRows(const std::string& path, const nlohmann::json& rows) {
  if (path.empty()) return true;
  std::ofstream out(path);
  out << rows.dump(2) << "\n";
  if (!out) std::cerr << "bench_scenes: cannot write " << path << "\n";
  return static_cast<bool>(out);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Mesh2SLAM scene-diversity benchmark (composed scenes x motions x feature modes)"};
  std::string manifest = "tools/bench_slam/scenes.json";
  std::string mesh_root;
  if (const char* home = std::getenv("HOME")) {
    mesh_root = std::string(home) + "/.cache/m2s-corpus/meshes";
  }
  std::vector<std::string> scenes, motions = m2s::bench::MotionKinds(), modes;
  for (const Mode& mode : kModes) modes.push_back(mode.name);
  double duration_s = 30.0, fps = 30.0;
  uint64_t seed = 1;
  int min_visible = 20;
  bool list = false, motions_only = false;
  std::string json_path, motion_dir;
  app.add_option("--manifest", manifest, "scene manifest (JSON)");
  app.add_option("--mesh-root", mesh_root,
                 "folder the manifest's mesh paths are relative to (make_corpus.sh's meshes/)");
  app.add_option("--scenes", scenes, "scene names (default: all of the manifest)");
  app.add_option("--motions", motions, "head, handheld, drone")
      ->check(CLI::IsMember(m2s::bench::MotionKinds()));
  app.add_option("--modes", modes, "noise-free, noisy, noisy-occlusion")
      ->check(CLI::IsMember({"noise-free", "noisy", "noisy-occlusion"}));
  app.add_option("--duration", duration_s, "seconds of motion per run")->check(CLI::PositiveNumber);
  app.add_option("--fps", fps, "frame rate")->check(CLI::PositiveNumber);
  app.add_option("--seed", seed, "motion seed");
  app.add_option("--min-visible", min_visible,
                 "frames with fewer visible vertices are not counted as lost")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--list", list, "print the scenes and exit");
  app.add_flag("--motions-only", motions_only, "generate (and write) the motions, run nothing");
  app.add_option("--write-motion", motion_dir,
                 "write each generated motion there as TUM (<scene>_<motion>.tum) and each "
                 "composed scene as PLY (<scene>.ply, the same vertex ids)");
  app.add_option("--json", json_path, "also write the rows as JSON to this file");
  std::string mesh, trajectory_path, name = "scene";
  auto* mesh_option = app.add_option(
      "--mesh", mesh, "run this scene file with --trajectory instead of the manifest's scenes");
  app.add_option("--trajectory", trajectory_path, "TUM ground truth for --mesh")
      ->needs(mesh_option);
  mesh_option->needs(app.get_option("--trajectory"));
  app.add_option("--name", name, "the scene column for --mesh");
  std::string dump_dir;
  app.add_option("--dump", dump_dir,
                 "write each run's aligned estimate and ground truth there as TUM "
                 "(<scene>_<motion>_<mode>_estimate.tum, _truth.tum)");
  bool no_refine = false;
  app.add_flag("--no-refine", no_refine,
               "measure the final trajectory and map without System::RefineMap() (the global "
               "bundle adjustment at the end of each run, then every frame re-solved and frames "
               "without a pose solved where the map determines them, then the motion prior)");
  std::optional<double> more_views_after_s;
  app.add_option("--more-views-after", more_views_after_s,
                 "slam::Options::initializer.more_views_after_s in seconds (negative: two-view "
                 "initialisation only; default: the library's)");
  std::optional<double> acceleration_sigma;
  app.add_option("--acceleration-sigma", acceleration_sigma,
                 "slam::Options::refine_acceleration_sigma in map units/s^2: the motion prior of "
                 "RefineMap's last step (0: none; default: the library's)")
      ->check(CLI::NonNegativeNumber);
  bool verbose = false;
  app.add_flag("--verbose", verbose,
               "log the SLAM system's debug messages (initialisation refusals, lost frames)");
  CLI11_PARSE(app, argc, argv);
  if (verbose) m2s::SetMinLogLevel(m2s::LogLevel::kDebug);

  if (!mesh.empty()) {
    m2s::bench::RunConfig config;
    config.fps = fps;
    config.min_visible_for_lost = min_visible;
    config.refine_map = !no_refine;
    config.more_views_after_s = more_views_after_s;
    config.acceleration_sigma = acceleration_sigma;
    config.projector_threads = 0;
    config.send_budget = m2s::slam::Options().feature_budget;  // as m2s_client sends
    nlohmann::json rows = nlohmann::json::array();
    const int rc = RunSceneFile(mesh, trajectory_path, name, modes, config, dump_dir, &rows);
    return rc != 0 ? rc : (WriteRows(json_path, rows) ? 0 : 1);
  }

  m2s::Expected<std::vector<m2s::bench::SceneSpec>> specs = m2s::bench::ReadSceneManifest(manifest);
  if (!specs) {
    std::cerr << "bench_scenes: " << specs.error() << "\n";
    return 2;
  }
  for (const std::string& name : scenes) {
    if (std::none_of(specs->begin(), specs->end(),
                     [&](const m2s::bench::SceneSpec& s) { return s.name == name; })) {
      std::cerr << "bench_scenes: no scene '" << name << "' in " << manifest << "\n";
      return 2;
    }
  }
  nlohmann::json rows = nlohmann::json::array();
  if (!list && !motions_only) PrintHeader();
  for (const m2s::bench::SceneSpec& spec : *specs) {
    if (!Selected(scenes, spec.name)) continue;
    m2s::Expected<m2s::bench::ComposedScene> composed = m2s::bench::ComposeScene(spec, mesh_root);
    if (!composed) {
      std::cerr << "bench_scenes: " << composed.error() << " (run make_corpus.sh?)\n";
      return 1;
    }
    if (list) {
      std::printf("%-20s %8zu vertices %8zu triangles %3zu obstacles %2zu targets\n",
                  spec.name.c_str(), composed->scene.num_vertices(),
                  composed->scene.num_triangles(), composed->layout.obstacles.size(),
                  composed->targets.size());
      // Parts with the same name on one line, in order of first appearance.
      std::vector<std::pair<std::string, std::pair<int, size_t>>> groups;
      for (const m2s::bench::ComposedScene::Part& part : composed->parts) {
        auto it = std::find_if(groups.begin(), groups.end(),
                               [&](const auto& g) { return g.first == part.name; });
        if (it == groups.end()) it = groups.insert(groups.end(), {part.name, {0, 0}});
        ++it->second.first;
        it->second.second += part.num_vertices;
      }
      for (const auto& [name, count] : groups) {
        std::printf("  %-24s x%-3d %8zu vertices\n", name.c_str(), count.first, count.second);
      }
      continue;
    }
    if (!motion_dir.empty()) {
      const std::string path = motion_dir + "/" + spec.name + ".ply";
      if (m2s::Status s = m2s::WriteScenePly(path, composed->scene); !s) {
        std::cerr << "bench_scenes: " << s.message() << "\n";
        return 1;
      }
    }
    for (const std::string& motion : motions) {
      m2s::Expected<m2s::Trajectory> trajectory =
          m2s::bench::MakeMotion(motion, *composed, seed, duration_s);
      if (!trajectory) {
        std::cerr << "bench_scenes: " << spec.name << " " << motion << ": " << trajectory.error()
                  << "\n";
        return 1;
      }
      if (!motion_dir.empty()) {
        const std::string path = motion_dir + "/" + spec.name + "_" + motion + ".tum";
        if (m2s::Status s = m2s::WriteTum(path, *trajectory); !s) {
          std::cerr << "bench_scenes: " << s.message() << "\n";
          return 1;
        }
      }
      if (motions_only) continue;
      const m2s::bench::Sequence sequence{spec.name + "/" + motion, *trajectory};
      m2s::bench::RunConfig config;
      config.fps = fps;
      config.min_visible_for_lost = min_visible;
      config.refine_map = !no_refine;
      config.more_views_after_s = more_views_after_s;
      config.acceleration_sigma = acceleration_sigma;
      if (!RunModes(composed->scene, spec.name, motion, sequence, modes, config, dump_dir, &rows))
        return 1;
    }
  }
  if (!WriteRows(json_path, rows)) return 1;
  return 0;
}
