// The results of a sweep: one row per cell, read back from the run's folder (metrics.json,
// trajectory.tum, groundtruth.tum), tables in Markdown / CSV / JSON, and plots.
//
//   Expected<CellResult> row = ReadCellResult(config, cell,
//   "out/runs/vertex__room__30fps__n0__o0"); Status s = WriteTables("out", config, rows);   //
//   results.md, results.csv, results.json
#pragma once

#include <string>
#include <vector>

#include "m2s/common/status.h"
#include "m2s/workbench/sweep.h"

namespace m2s::workbench {

struct CellResult {
  Cell cell;
  std::string status = "ok";  // ok, failed, timeout, skipped
  std::string message;        // why, when not ok
  int64_t frames_total = 0;
  int64_t frames_tracked = 0;  // with a pose (OK or relocalised)
  int64_t frames_lost = 0;     // processed and lost (frames before initialisation are neither)
  int64_t frames_in_unmerged_maps = 0;
  // Metres; Sim3-aligned to the ground truth at the frame times (the evaluation of m2s_eval);
  // -1 when not available (fewer than 3 tracked frames).
  double ate_rmse = -1, ate_max = -1, rpe_rmse = -1;
  // Tracking time per frame (ms): the back end's, plus the image front end's when there is one.
  double time_ms_p50 = 0, time_ms_p95 = 0;
  double front_end_ms_p50 = 0;                          // 0 for vertex features
  double map_median = -1, map_p95 = -1, map_rmse = -1;  // metres; -1 when no map
  int64_t keyframes = 0;
  double wall_s = 0;
  // Translation error (m) of each tracked frame after the alignment, against its time (s from
  // the first frame): the error-over-time plot.
  std::vector<double> error_time_s;
  std::vector<double> error_m;

  bool ok() const { return status == "ok"; }
  double tracked_percent() const {
    return frames_total > 0 ? 100.0 * static_cast<double>(frames_tracked) / frames_total : 0.0;
  }
  double lost_percent() const {
    return frames_total > 0 ? 100.0 * static_cast<double>(frames_lost) / frames_total : 0.0;
  }
};

// Reads a finished run. A folder without metrics.json is an error naming the folder.
Expected<CellResult> ReadCellResult(const Cell& cell, const std::string& run_dir);

// results.md (one table per scene), results.csv and results.json in out_dir.
Status WriteTables(const std::string& out_dir, const SweepConfig& config,
                   const std::vector<CellResult>& rows);

// plots/ate_vs_noise_<scene>.png (one line per method and frame rate) when the sweep has
// several noise levels, and plots/error_over_time_<scene>_<fps>fps.png (one line per method,
// noise-free cells) for every scene and frame rate. Returns the files written.
Expected<std::vector<std::string>> WritePlots(const std::string& out_dir, const SweepConfig& config,
                                              const std::vector<CellResult>& rows);

}  // namespace m2s::workbench
