// The sweep's figures from its rows (results.h WritePlots).
#include <filesystem>
#include <map>
#include <sstream>

#include "m2s/workbench/plot.h"
#include "m2s/workbench/results.h"

namespace m2s::workbench {
namespace {

namespace fs = std::filesystem;

std::string Short(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

}  // namespace

Expected<std::vector<std::string>> WritePlots(const std::string& out_dir, const SweepConfig& config,
                                              const std::vector<CellResult>& rows) {
  const fs::path dir = fs::path(out_dir) / "plots";
  std::error_code error;
  fs::create_directories(dir, error);
  if (error) return Status::Error("cannot create " + dir.string() + ": " + error.message());
  std::vector<std::string> written;
  auto write = [&written](const fs::path& path, const LinePlot& plot) -> Status {
    // A plot without a single successful run is left out rather than failing the sweep.
    bool any = false;
    for (const PlotSeries& s : plot.series) any = any || !s.x.empty();
    if (!any) return Status::Ok();
    if (Status s = WritePlotPng(path.string(), plot); !s) return s;
    written.push_back(path.string());
    return Status::Ok();
  };

  for (size_t s = 0; s < config.scenes.size(); ++s) {
    const std::string& scene = config.scenes[s].name;
    if (config.noise_px.size() > 1) {
      // ATE against pixel noise: one series per method and frame rate (wrong ids: the first
      // level of the sweep).
      LinePlot plot;
      plot.title = "ATE vs pixel noise: " + scene;
      plot.x_label = "pixel noise sigma (px)";
      plot.y_label = "ATE RMSE (mm)";
      std::map<std::pair<size_t, double>, PlotSeries> series;
      for (const CellResult& r : rows) {
        if (r.cell.scene != s || !r.ok() || r.ate_rmse < 0) continue;
        if (r.cell.outlier_ids != config.outlier_ids.front()) continue;
        PlotSeries& line = series[{r.cell.method, r.cell.fps}];
        line.name = config.methods[r.cell.method].name + " " + Short(r.cell.fps) + " fps";
        line.x.push_back(r.cell.noise_px);
        line.y.push_back(r.ate_rmse * 1e3);
      }
      for (auto& [key, line] : series) plot.series.push_back(std::move(line));
      if (Status st = write(dir / ("ate_vs_noise_" + scene + ".png"), plot); !st) return st;
    }
    for (double fps : config.fps) {
      // Error over time of the noise-free runs, one series per method.
      LinePlot plot;
      plot.title = "Position error over time: " + scene + ", " + Short(fps) + " fps";
      plot.x_label = "time (s)";
      plot.y_label = "error after Sim3 alignment (mm)";
      plot.markers = false;
      for (const CellResult& r : rows) {
        if (r.cell.scene != s || r.cell.fps != fps || !r.ok()) continue;
        if (r.cell.noise_px != config.noise_px.front() ||
            r.cell.outlier_ids != config.outlier_ids.front())
          continue;
        PlotSeries line{.name = config.methods[r.cell.method].name, .x = r.error_time_s, .y = {}};
        for (double e : r.error_m) line.y.push_back(e * 1e3);
        plot.series.push_back(std::move(line));
      }
      const fs::path path = dir / ("error_over_time_" + scene + "_" + Short(fps) + "fps.png");
      if (Status st = write(path, plot); !st) return st;
    }
  }
  return written;
}

}  // namespace m2s::workbench
