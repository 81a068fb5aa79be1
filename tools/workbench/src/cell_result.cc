#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "m2s/common/evaluation.h"
#include "m2s/common/trajectory.h"
#include "m2s/workbench/results.h"

namespace m2s::workbench {
namespace {

namespace fs = std::filesystem;

template <typename T>
T Value(const nlohmann::json& json, const char* key, T fallback) {
  if (!json.contains(key) || json.at(key).is_null()) return fallback;
  try {
    return json.at(key).get<T>();
  } catch (const nlohmann::json::exception&) {
    return fallback;
  }
}

}  // namespace

Expected<CellResult> ReadCellResult(const Cell& cell, const std::string& run_dir) {
  const fs::path dir(run_dir);
  std::ifstream in(dir / "metrics.json");
  if (!in) return Status::Error("no metrics.json in " + run_dir + " (the run failed; see log.txt)");
  const nlohmann::json metrics = nlohmann::json::parse(in, nullptr, false);
  if (metrics.is_discarded() || !metrics.is_object())
    return Status::Error((dir / "metrics.json").string() + " is not a JSON object");

  CellResult row;
  row.cell = cell;
  row.frames_total = Value<int64_t>(metrics, "frames_total", 0);
  row.frames_tracked = Value<int64_t>(metrics, "frames_tracked", 0);
  row.frames_lost = Value<int64_t>(metrics, "frames_lost", 0);
  row.frames_in_unmerged_maps = Value<int64_t>(metrics, "frames_in_unmerged_maps", 0);
  row.front_end_ms_p50 = Value<double>(metrics, "front_end_ms_p50", 0.0);
  // The time per frame: the front end's and the back end's of each frame (their percentiles
  // added would overstate it); runs of a client without it give the back end's alone.
  row.time_ms_p50 = Value<double>(metrics, "time_per_frame_ms_p50",
                                  Value<double>(metrics, "tracking_ms_p50", 0.0));
  row.time_ms_p95 = Value<double>(metrics, "time_per_frame_ms_p95",
                                  Value<double>(metrics, "tracking_ms_p95", 0.0));
  row.map_median = Value<double>(metrics, "map_median", -1.0);
  row.map_p95 = Value<double>(metrics, "map_p95", -1.0);
  row.map_rmse = Value<double>(metrics, "map_rmse", -1.0);
  row.keyframes = Value<int64_t>(metrics, "keyframes", 0);
  row.wall_s = Value<double>(metrics, "wall_s", 0.0);
  row.ate_rmse = Value<double>(metrics, "ate_rmse", -1.0);

  // Per-frame errors, the maximum and the RPE from the trajectories the run wrote (the
  // ground truth is sampled at the frame times, so the association is exact).
  const Expected<Trajectory> truth = ReadTum((dir / "groundtruth.tum").string());
  const Expected<Trajectory> estimate = ReadTum((dir / "trajectory.tum").string());
  if (truth && estimate && estimate->size() >= 3) {
    const Expected<TrajectoryEvaluation> evaluation = EvaluateTrajectory(*truth, *estimate);
    if (evaluation) {
      row.ate_rmse = evaluation->ate.rmse;
      row.ate_max = evaluation->ate.max;
      row.rpe_rmse = evaluation->rpe.rmse;
      const double t0 = truth->poses().front().timestamp;
      for (size_t i = 0; i < evaluation->matches.size(); ++i) {
        row.error_time_s.push_back(truth->poses()[evaluation->matches[i].reference].timestamp - t0);
        row.error_m.push_back(evaluation->ate_errors[i]);
      }
    }
  }
  return row;
}

}  // namespace m2s::workbench
