// Tables, plots and the reading of a run's folder, checked by reading the files back
// independently (a CSV splitter, nlohmann::json, OpenCV's PNG decoder).
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "m2s/common/trajectory.h"
#include "m2s/workbench/plot.h"
#include "m2s/workbench/results.h"
#include "temp_dir.h"

namespace m2s::workbench {
namespace {

namespace fs = std::filesystem;

// RFC 4180 fields of one line (quotes doubled inside quoted fields).
std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted && c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
      fields.back() += '"';
      ++i;
    } else if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      fields.emplace_back();
    } else {
      fields.back() += c;
    }
  }
  return fields;
}

SweepConfig TwoByTwo() {
  SweepConfig config;
  config.methods.resize(2);
  config.methods[0].name = "vertex";
  config.methods[1].name = "pnp";
  config.methods[1].plugin = "pnp_odometry";
  config.scenes.resize(1);
  config.scenes[0].name = "room";
  config.noise_px = {0.0, 1.0};
  return config;
}

std::vector<CellResult> Rows() {
  std::vector<CellResult> rows(4);
  for (int i = 0; i < 4; ++i) {
    rows[i].cell = {static_cast<size_t>(i / 2), 0, 30.0, (i % 2) * 1.0, 0.0};
    rows[i].frames_total = 100;
    rows[i].frames_tracked = 90 - i;
    rows[i].frames_lost = i;
    rows[i].ate_rmse = 0.001 * (i + 1);  // 1, 2, 3, 4 mm
    rows[i].ate_max = 0.002 * (i + 1);
    rows[i].error_time_s = {0.0, 1.0, 2.0};
    rows[i].error_m = {0.001, 0.002, 0.001 * (i + 1)};
  }
  rows[3].status = "failed";
  rows[3].message = "exit 2: bad, \"quoted\" option";
  rows[3].ate_rmse = -1;
  return rows;
}

TEST(WorkbenchTables, CsvJsonAndMarkdownHoldEveryRow) {
  const fs::path dir = TempDir("tables");
  ASSERT_TRUE(WriteTables(dir.string(), TwoByTwo(), Rows()));

  std::ifstream csv(dir / "results.csv");
  std::string line;
  std::getline(csv, line);
  const std::vector<std::string> header = SplitCsv(line);
  const auto column = [&header](const std::string& name) {
    return static_cast<size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  };
  ASSERT_LT(column("ate_rmse_m"), header.size());
  ASSERT_LT(column("message"), header.size());
  std::vector<std::vector<std::string>> lines;
  while (std::getline(csv, line)) lines.push_back(SplitCsv(line));
  ASSERT_EQ(lines.size(), 4u);
  for (const auto& fields : lines) EXPECT_EQ(fields.size(), header.size());
  EXPECT_EQ(lines[1][column("method")], "vertex");
  EXPECT_DOUBLE_EQ(std::stod(lines[1][column("noise_px")]), 1.0);
  EXPECT_NEAR(std::stod(lines[1][column("ate_rmse_m")]), 0.002, 1e-12);
  EXPECT_EQ(lines[3][column("status")], "failed");
  EXPECT_EQ(lines[3][column("message")], "exit 2: bad, \"quoted\" option");
  EXPECT_EQ(lines[3][column("ate_rmse_m")], "");

  std::ifstream json_file(dir / "results.json");
  const nlohmann::json json = nlohmann::json::parse(json_file);
  ASSERT_EQ(json.at("results").size(), 4u);
  EXPECT_EQ(json["results"][2]["method"], "pnp");
  EXPECT_EQ(json["results"][2]["frames_lost"], 2);
  EXPECT_TRUE(json["results"][3]["ate_rmse_m"].is_null());

  std::ifstream md(dir / "results.md");
  std::stringstream text;
  text << md.rdbuf();
  int table_rows = 0;
  std::istringstream md_lines(text.str());
  while (std::getline(md_lines, line))
    table_rows += line.rfind("| vertex", 0) == 0 || line.rfind("| pnp", 0) == 0;
  EXPECT_EQ(table_rows, 4);
  EXPECT_NE(text.str().find("| 2.000 |"), std::string::npos);  // 2 mm in millimetres
  fs::remove_all(dir);
}

TEST(WorkbenchPlots, NiceRangeCoversTheDataWithRoundTicks) {
  double lo = 0, hi = 0;
  std::vector<double> ticks;
  NiceRange(0.0, 1.1, &lo, &hi, &ticks);
  EXPECT_DOUBLE_EQ(lo, 0.0);
  EXPECT_NEAR(hi, 1.25, 1e-12);
  ASSERT_EQ(ticks.size(), 6u);
  EXPECT_NEAR(ticks[1], 0.25, 1e-12);
  NiceRange(3.0, 3.0, &lo, &hi, &ticks);  // one value: a range around it
  EXPECT_LT(lo, 3.0);
  EXPECT_GT(hi, 3.0);
}

TEST(WorkbenchPlots, PngShowsEachSeriesInItsColour) {
  const fs::path dir = TempDir("plot");
  LinePlot plot;
  plot.title = "test";
  plot.series = {{"a", {0, 1, 2}, {0, 1, 2}}, {"b", {0, 1, 2}, {2, 2, NAN}}};
  const std::string path = (dir / "p.png").string();
  ASSERT_TRUE(WritePlotPng(path, plot));
  const cv::Mat image = cv::imread(path, cv::IMREAD_COLOR);
  ASSERT_EQ(image.cols, plot.width);
  ASSERT_EQ(image.rows, plot.height);
  // The first two palette colours (BGR), exactly as drawn (anti-aliasing keeps line centres).
  int a = 0, b = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3b p = image.at<cv::Vec3b>(y, x);
      a += p == cv::Vec3b(180, 119, 31);
      b += p == cv::Vec3b(14, 127, 255);
    }
  EXPECT_GT(a, 500);  // a diagonal across the plot plus markers
  EXPECT_GT(b, 200);  // one horizontal segment (the NaN point left out)

  LinePlot empty;
  empty.series = {{"none", {}, {}}};
  EXPECT_FALSE(WritePlotPng((dir / "e.png").string(), empty));
  fs::remove_all(dir);
}

TEST(WorkbenchResults, ReadsARunFolderAndEvaluatesItsTrajectory) {
  const fs::path dir = TempDir("run");
  // Ground truth: a curve; estimate: the same poses in another frame and scale (a known Sim3),
  // so every aligned error is zero up to rounding.
  std::vector<TimedPose> truth, estimate;
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  for (int i = 0; i < 30; ++i) {
    const double t = 10.0 + i / 30.0;
    const Eigen::Vector3d p(std::cos(i * 0.1), std::sin(i * 0.1), 0.05 * i);
    const Eigen::Quaterniond r(Eigen::AngleAxisd(0.05 * i, Eigen::Vector3d::UnitZ()));
    truth.push_back({t, Pose3(r, p)});
    estimate.push_back(
        {t, Pose3(q.inverse() * r, 0.5 * (q.inverse() * (p - Eigen::Vector3d(1, 0, 0))))});
  }
  ASSERT_TRUE(WriteTum((dir / "groundtruth.tum").string(), *Trajectory::FromPoses(truth)));
  ASSERT_TRUE(WriteTum((dir / "trajectory.tum").string(), *Trajectory::FromPoses(estimate)));
  std::ofstream(dir / "metrics.json") << R"({"frames_total": 40, "frames_tracked": 30,
      "frames_lost": 4, "frames_in_unmerged_maps": 1, "ate_rmse": 0.5, "tracking_ms_p50": 2.0,
      "tracking_ms_p95": 3.0, "front_end_ms_p50": 5.0, "time_per_frame_ms_p50": 7.5,
      "time_per_frame_ms_p95": 9.0, "map_median": 0.001, "map_p95": null,
      "keyframes": 7, "wall_s": 1.5})";
  const Cell cell{0, 0, 30, 0, 0};
  Expected<CellResult> row = ReadCellResult(cell, dir.string());
  ASSERT_TRUE(row) << row.error();
  EXPECT_EQ(row->frames_total, 40);
  EXPECT_EQ(row->frames_lost, 4);
  EXPECT_EQ(row->frames_in_unmerged_maps, 1);
  EXPECT_DOUBLE_EQ(row->time_ms_p50, 7.5);  // front end + back end, per frame
  EXPECT_DOUBLE_EQ(row->time_ms_p95, 9.0);
  EXPECT_DOUBLE_EQ(row->front_end_ms_p50, 5.0);
  EXPECT_DOUBLE_EQ(row->map_p95, -1.0);  // null: no value
  EXPECT_EQ(row->keyframes, 7);
  // Recomputed from the trajectories (written with full precision), not metrics.json's 0.5:
  EXPECT_LT(row->ate_rmse, 1e-9);
  EXPECT_LT(row->ate_max, 1e-9);
  ASSERT_EQ(row->error_m.size(), 30u);
  EXPECT_NEAR(row->error_time_s.front(), 0.0, 1e-9);
  EXPECT_NEAR(row->error_time_s.back(), 29.0 / 30.0, 1e-6);

  fs::remove(dir / "metrics.json");
  Expected<CellResult> missing = ReadCellResult(cell, dir.string());
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().find(dir.string()), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace m2s::workbench
