#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "m2s/workbench/results.h"

namespace m2s::workbench {
namespace {

namespace fs = std::filesystem;

// Millimetres with 3 decimals, or "-" for a missing value (negative).
std::string Mm(double metres) {
  if (metres < 0) return "-";
  char text[32];
  std::snprintf(text, sizeof(text), "%.3f", metres * 1e3);
  return text;
}

std::string Fixed(double value, int decimals) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.*f", decimals, value);
  return text;
}

// A CSV field: quoted when it holds a comma, a quote or a line break.
std::string CsvField(const std::string& text) {
  if (text.find_first_of(",\"\n") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) quoted += (c == '"') ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}

// -1 (missing) as JSON null.
nlohmann::json OrNull(double value) {
  return value < 0 ? nlohmann::json(nullptr) : nlohmann::json(value);
}

Status WriteFile(const fs::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  out.close();
  if (!out) return Status::Error("cannot write " + path.string());
  return Status::Ok();
}

std::string Markdown(const SweepConfig& config, const std::vector<CellResult>& rows) {
  std::string md;
  for (size_t s = 0; s < config.scenes.size(); ++s) {
    const SceneSpec& scene = config.scenes[s];
    md +=
        "### " + scene.name + " (" + (scene.mesh.empty() ? "default scene" : scene.mesh) + ")\n\n";
    md +=
        "| method | fps | noise px | wrong ids | frames | tracked % | lost % | unmerged | ATE mm | "
        "ATE max mm | RPE mm | ms/frame p50 | ms/frame p95 | map median mm | map p95 mm | "
        "keyframes | status |\n";
    md += "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n";
    for (const CellResult& r : rows) {
      if (r.cell.scene != s) continue;
      md += "| " + config.methods[r.cell.method].name + " | " + Fixed(r.cell.fps, 0) + " | " +
            Fixed(r.cell.noise_px, 2) + " | " + Fixed(r.cell.outlier_ids, 3) + " | ";
      if (!r.ok()) {
        md += "- | - | - | - | - | - | - | - | - | - | - | - | " + r.status + ": " + r.message +
              " |\n";
        continue;
      }
      md += std::to_string(r.frames_total) + " | " + Fixed(r.tracked_percent(), 1) + " | " +
            Fixed(r.lost_percent(), 1) + " | " + std::to_string(r.frames_in_unmerged_maps) + " | " +
            Mm(r.ate_rmse) + " | " + Mm(r.ate_max) + " | " + Mm(r.rpe_rmse) + " | " +
            Fixed(r.time_ms_p50, 2) + " | " + Fixed(r.time_ms_p95, 2) + " | " + Mm(r.map_median) +
            " | " + Mm(r.map_p95) + " | " + std::to_string(r.keyframes) + " | ok |\n";
    }
    md += "\n";
  }
  return md;
}

std::string Csv(const SweepConfig& config, const std::vector<CellResult>& rows) {
  std::string csv =
      "method,scene,fps,noise_px,outlier_ids,status,message,frames_total,frames_tracked,"
      "frames_lost,frames_in_unmerged_maps,ate_rmse_m,ate_max_m,rpe_rmse_m,time_ms_p50,"
      "time_ms_p95,front_end_ms_p50,map_median_m,map_p95_m,map_rmse_m,keyframes,wall_s\n";
  auto number = [](double v) { return v < 0 ? std::string() : Fixed(v, 9); };
  for (const CellResult& r : rows) {
    csv += CsvField(config.methods[r.cell.method].name) + "," +
           CsvField(config.scenes[r.cell.scene].name) + "," + Fixed(r.cell.fps, 3) + "," +
           Fixed(r.cell.noise_px, 3) + "," + Fixed(r.cell.outlier_ids, 4) + "," + r.status + "," +
           CsvField(r.message) + "," + std::to_string(r.frames_total) + "," +
           std::to_string(r.frames_tracked) + "," + std::to_string(r.frames_lost) + "," +
           std::to_string(r.frames_in_unmerged_maps) + "," + number(r.ate_rmse) + "," +
           number(r.ate_max) + "," + number(r.rpe_rmse) + "," + Fixed(r.time_ms_p50, 4) + "," +
           Fixed(r.time_ms_p95, 4) + "," + Fixed(r.front_end_ms_p50, 4) + "," +
           number(r.map_median) + "," + number(r.map_p95) + "," + number(r.map_rmse) + "," +
           std::to_string(r.keyframes) + "," + Fixed(r.wall_s, 3) + "\n";
  }
  return csv;
}

nlohmann::json Json(const SweepConfig& config, const std::vector<CellResult>& rows) {
  nlohmann::json list = nlohmann::json::array();
  for (const CellResult& r : rows) {
    list.push_back({{"method", config.methods[r.cell.method].name},
                    {"scene", config.scenes[r.cell.scene].name},
                    {"fps", r.cell.fps},
                    {"noise_px", r.cell.noise_px},
                    {"outlier_ids", r.cell.outlier_ids},
                    {"status", r.status},
                    {"message", r.message},
                    {"frames_total", r.frames_total},
                    {"frames_tracked", r.frames_tracked},
                    {"frames_lost", r.frames_lost},
                    {"frames_in_unmerged_maps", r.frames_in_unmerged_maps},
                    {"ate_rmse_m", OrNull(r.ate_rmse)},
                    {"ate_max_m", OrNull(r.ate_max)},
                    {"rpe_rmse_m", OrNull(r.rpe_rmse)},
                    {"time_ms_p50", r.time_ms_p50},
                    {"time_ms_p95", r.time_ms_p95},
                    {"front_end_ms_p50", r.front_end_ms_p50},
                    {"map_median_m", OrNull(r.map_median)},
                    {"map_p95_m", OrNull(r.map_p95)},
                    {"map_rmse_m", OrNull(r.map_rmse)},
                    {"keyframes", r.keyframes},
                    {"wall_s", r.wall_s}});
  }
  return {{"results", list}};
}

}  // namespace

Status WriteTables(const std::string& out_dir, const SweepConfig& config,
                   const std::vector<CellResult>& rows) {
  const fs::path dir(out_dir);
  if (Status s = WriteFile(dir / "results.md", Markdown(config, rows)); !s) return s;
  if (Status s = WriteFile(dir / "results.csv", Csv(config, rows)); !s) return s;
  return WriteFile(dir / "results.json", Json(config, rows).dump(2) + "\n");
}

}  // namespace m2s::workbench
