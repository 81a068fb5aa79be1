#include "m2s/workbench/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace m2s::workbench {
namespace {

// Distinguishable colours (BGR), cycled.
const cv::Scalar kColours[] = {{180, 119, 31},  {14, 127, 255}, {44, 160, 44},   {40, 39, 214},
                               {189, 103, 148}, {75, 86, 140},  {194, 119, 227}, {127, 127, 127},
                               {34, 189, 188},  {207, 190, 23}};
constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;

std::string TickLabel(double value, double step) {
  int decimals = 0;  // the fewest that show the step exactly (0.25 -> 2)
  while (decimals < 6 && std::abs(step * std::pow(10.0, decimals) -
                                  std::round(step * std::pow(10.0, decimals))) > 1e-6)
    ++decimals;
  char text[32];
  std::snprintf(text, sizeof(text), "%.*f", decimals, value);
  return text;
}

}  // namespace

void NiceRange(double lo, double hi, double* nice_lo, double* nice_hi, std::vector<double>* ticks) {
  if (!(hi > lo)) {  // one value (or none): a unit-wide range around it
    const double pad = lo != 0 ? std::abs(lo) * 0.5 : 1.0;
    lo -= pad;
    hi += pad;
  }
  const double raw_step = (hi - lo) / 5.0;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw_step)));
  double step = magnitude;
  for (double m : {1.0, 2.0, 2.5, 5.0, 10.0}) {
    step = m * magnitude;
    if (step >= raw_step) break;
  }
  *nice_lo = std::floor(lo / step) * step;
  *nice_hi = std::ceil(hi / step) * step;
  ticks->clear();
  for (double t = *nice_lo; t <= *nice_hi + step * 1e-9; t += step)
    ticks->push_back(std::abs(t) < step * 1e-9 ? 0.0 : t);
}

Status WritePlotPng(const std::string& path, const LinePlot& plot) {
  if (plot.width < 200 || plot.height < 150) return Status::Error("plot smaller than 200 x 150");
  double x_lo = std::numeric_limits<double>::infinity(), x_hi = -x_lo;
  double y_lo = x_lo, y_hi = -x_lo;
  for (const PlotSeries& s : plot.series) {
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      x_lo = std::min(x_lo, s.x[i]);
      x_hi = std::max(x_hi, s.x[i]);
      y_lo = std::min(y_lo, s.y[i]);
      y_hi = std::max(y_hi, s.y[i]);
    }
  }
  if (!std::isfinite(x_lo)) return Status::Error("plot \"" + plot.title + "\" has no point");
  y_lo = std::min(y_lo, 0.0);  // errors and times: the axis starts at 0
  std::vector<double> x_ticks, y_ticks;
  NiceRange(x_lo, x_hi, &x_lo, &x_hi, &x_ticks);
  NiceRange(y_lo, y_hi, &y_lo, &y_hi, &y_ticks);

  cv::Mat image(plot.height, plot.width, CV_8UC3, cv::Scalar(255, 255, 255));
  const int left = 80, right = plot.width - 20, top = 50, bottom = plot.height - 60;
  auto to_pixel = [&](double x, double y) {
    return cv::Point(
        static_cast<int>(std::lround(left + (x - x_lo) / (x_hi - x_lo) * (right - left))),
        static_cast<int>(std::lround(bottom - (y - y_lo) / (y_hi - y_lo) * (bottom - top))));
  };
  const cv::Scalar grid(225, 225, 225), ink(0, 0, 0);
  const double x_step = x_ticks.size() > 1 ? x_ticks[1] - x_ticks[0] : 1.0;
  const double y_step = y_ticks.size() > 1 ? y_ticks[1] - y_ticks[0] : 1.0;
  for (double t : x_ticks) {
    const cv::Point p = to_pixel(t, y_lo);
    cv::line(image, {p.x, top}, {p.x, bottom}, grid, 1);
    cv::putText(image, TickLabel(t, x_step), {p.x - 15, bottom + 20}, kFont, 0.45, ink, 1,
                cv::LINE_AA);
  }
  for (double t : y_ticks) {
    const cv::Point p = to_pixel(x_lo, t);
    cv::line(image, {left, p.y}, {right, p.y}, grid, 1);
    cv::putText(image, TickLabel(t, y_step), {5, p.y + 5}, kFont, 0.45, ink, 1, cv::LINE_AA);
  }
  cv::rectangle(image, {left, top}, {right, bottom}, ink, 1);
  cv::putText(image, plot.title, {left, 22}, kFont, 0.6, ink, 1, cv::LINE_AA);
  cv::putText(image, plot.x_label, {(left + right) / 2 - 40, plot.height - 20}, kFont, 0.5, ink, 1,
              cv::LINE_AA);
  cv::putText(image, plot.y_label, {5, top - 8}, kFont, 0.5, ink, 1, cv::LINE_AA);

  for (size_t k = 0; k < plot.series.size(); ++k) {
    const PlotSeries& s = plot.series[k];
    const cv::Scalar colour = kColours[k % std::size(kColours)];
    std::vector<cv::Point> points;
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (std::isfinite(s.x[i]) && std::isfinite(s.y[i]))
        points.push_back(to_pixel(s.x[i], s.y[i]));
    }
    if (points.size() > 1) cv::polylines(image, points, false, colour, 2, cv::LINE_AA);
    if (plot.markers)
      for (const cv::Point& p : points) cv::circle(image, p, 4, colour, cv::FILLED, cv::LINE_AA);
    const int y = top + 18 + 20 * static_cast<int>(k);
    cv::line(image, {right - 190, y - 4}, {right - 165, y - 4}, colour, 3);
    cv::putText(image, s.name, {right - 160, y}, kFont, 0.45, ink, 1, cv::LINE_AA);
  }
  try {
    if (!cv::imwrite(path, image)) return Status::Error("cannot write " + path);
  } catch (const cv::Exception& e) {
    return Status::Error("cannot write " + path + ": " + e.what());
  }
  return Status::Ok();
}

}  // namespace m2s::workbench
