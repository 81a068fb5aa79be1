// m2s_bench --config SWEEP.json --out DIR [--jobs N] [--client PATH]
//
// Runs every cell of a sweep (methods x scenes x frame rates x noise levels; the file format
// is in m2s/workbench/sweep.h) as a deterministic on-device m2s_client run, N at a time, and
// writes DIR/results.md, results.csv, results.json and DIR/plots/*.png. Each run keeps its
// outputs (metrics.json, trajectories, log.txt) in DIR/runs/<cell>/.
// Exit code: 0 when every cell ran (or was skipped as not applicable), 1 when a run failed or
// timed out (the tables are written anyway), 2 on bad options or a bad sweep file.
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>

#include "m2s/workbench/results.h"
#include "m2s/workbench/runner.h"
#include "m2s/workbench/sweep.h"

namespace {

// m2s_client next to this executable (both land in build/bin).
std::string DefaultClient() {
  std::error_code error;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
  if (error) return "m2s_client";
  return (self.parent_path() / "m2s_client").string();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Mesh2SLAM workbench: sweeps of localisation methods over scenes, rates, noise"};
  std::string config_path;
  m2s::workbench::RunnerOptions options;
  options.client = DefaultClient();
  options.jobs = std::max(1u, std::thread::hardware_concurrency());
  app.add_option("--config", config_path, "Sweep file (JSON)")->required();
  app.add_option("--out", options.out_dir, "Output folder")->required();
  app.add_option("--jobs", options.jobs, "Runs at once (default: the cores)")
      ->capture_default_str();
  app.add_option("--client", options.client, "The m2s_client executable")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  const auto config = m2s::workbench::ReadSweepConfig(config_path);
  if (!config) {
    std::cerr << "m2s_bench: " << config.error() << "\n";
    return 2;
  }
  if (m2s::Status s = options.Check(); !s) {
    std::cerr << "m2s_bench: " << s.message() << "\n";
    return 2;
  }
  std::error_code error;
  std::filesystem::create_directories(options.out_dir, error);
  if (error) {
    std::cerr << "m2s_bench: cannot create " << options.out_dir << ": " << error.message() << "\n";
    return 2;
  }
  options.on_cell_done = [&config](const m2s::workbench::CellResult& row, size_t done,
                                   size_t total) {
    std::fprintf(stderr, "[%zu/%zu] %s: %s", done, total, row.cell.Name(*config).c_str(),
                 row.status.c_str());
    if (row.ok() && row.ate_rmse >= 0) {
      std::fprintf(stderr, ", ATE %.3f mm, lost %.1f %%, %.2f ms/frame\n", row.ate_rmse * 1e3,
                   row.lost_percent(), row.time_ms_p50);
    } else if (row.ok()) {
      std::fprintf(stderr, ", %lld of %lld frames tracked (no ATE), %.2f ms/frame\n",
                   static_cast<long long>(row.frames_tracked),
                   static_cast<long long>(row.frames_total), row.time_ms_p50);
    } else {
      std::fprintf(stderr, " (%s)\n", row.message.c_str());
    }
  };
  const std::vector<m2s::workbench::CellResult> rows = m2s::workbench::RunSweep(*config, options);

  if (m2s::Status s = m2s::workbench::WriteTables(options.out_dir, *config, rows); !s) {
    std::cerr << "m2s_bench: " << s.message() << "\n";
    return 1;
  }
  const auto plots = m2s::workbench::WritePlots(options.out_dir, *config, rows);
  if (!plots) {
    std::cerr << "m2s_bench: " << plots.error() << "\n";
    return 1;
  }
  int failed = 0;
  for (const auto& row : rows) failed += (row.status == "failed" || row.status == "timeout");
  std::fprintf(stderr, "m2s_bench: %zu runs (%d failed), %zu plots; tables in %s/results.md\n",
               rows.size(), failed, plots->size(), options.out_dir.c_str());
  return failed > 0 ? 1 : 0;
}
