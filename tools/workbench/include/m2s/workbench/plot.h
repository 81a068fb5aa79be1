// A line plot drawn with OpenCV (imgproc) and written as PNG (imgcodecs): axes with ticks at
// round values, one coloured polyline with markers per series, a legend. Enough for the
// workbench's figures without a plotting dependency.
//
//   LinePlot plot{.title = "ATE vs noise", .x_label = "noise (px)", .y_label = "ATE (mm)"};
//   plot.series.push_back({"vertex 30 fps", {0, 0.5, 1}, {0.01, 0.9, 1.8}});
//   Status s = WritePlotPng("ate.png", plot);
#pragma once

#include <string>
#include <vector>

#include "m2s/common/status.h"

namespace m2s::workbench {

struct PlotSeries {
  std::string name;
  std::vector<double> x;
  std::vector<double> y;  // same length as x; non-finite points are left out
};

struct LinePlot {
  std::string title;
  std::string x_label;
  std::string y_label;
  std::vector<PlotSeries> series;
  bool markers = true;  // a dot on every point (off for dense series)
  int width = 900;
  int height = 600;
};

// The axes' range: [lo, hi] widened to round tick values; `ticks` gets the tick positions.
void NiceRange(double lo, double hi, double* nice_lo, double* nice_hi, std::vector<double>* ticks);

// Fails when the plot has no finite point, the size is below 200 x 150, or the file cannot be
// written.
Status WritePlotPng(const std::string& path, const LinePlot& plot);

}  // namespace m2s::workbench
