// Dataset layouts written by m2s_export: TUM RGB-D and EuRoC MAV (ASL), with an ORB-SLAM
// settings file and the CAMERA.json of the images. See docs/design/export.md for every file.
//
// Intrinsics in the dataset files (sensor.yaml, orbslam_settings.yaml, dso_camera.txt) are in
// the convention of those tools, OpenCV's: the centre of pixel (0, 0) is at (0, 0), so they
// carry cx - 0.5 and cy - 0.5 of this project's Camera (whose pixel (0, 0) spans [0, 1)).
// CAMERA.json keeps this project's values.
//
// Usage: WriteDatasetIndex() once with every frame's time and pose (the text files), then
// WriteDatasetFrame() per rendered frame (the images). Not thread-safe; no state.
#pragma once

#include <string>

#include "m2s/common/camera.h"
#include "m2s/common/status.h"
#include "m2s/common/trajectory.h"
#include "m2s/render/scene_renderer.h"

namespace m2s::export_tool {

enum class DatasetFormat { kTumRgbd, kEuroc };

// "tum-rgbd" or "euroc"; a one-line error naming the choices otherwise.
Expected<DatasetFormat> ParseDatasetFormat(const std::string& name);

// TUM depth PNGs and EuRoC depth0: 16-bit, this many units per metre (TUM's convention).
constexpr double kDepthUnitsPerMetre = 5000.0;

// Checks the frame times for the format (distinct file names at TUM's 6 decimals or EuRoC's
// nanoseconds; EuRoC times >= 0) and writes the folders and every text file: for TUM RGB-D
// rgb.txt, depth.txt, associations.txt, groundtruth.txt; for EuRoC mav0/cam0/data.csv,
// mav0/cam0/sensor.yaml, mav0/depth0/data.csv, mav0/state_groundtruth_estimate0/data.csv and
// timestamps.txt; for both orbslam_settings.yaml, dso_camera.txt and CAMERA.json. `rate_hz` is
// the nominal frame rate written to the settings.
Status WriteDatasetIndex(DatasetFormat format, const std::string& dir, const Trajectory& frames,
                         const Camera& camera, double rate_hz);

// Writes the images of one frame at `timestamp` (one of the frames given to the index): TUM
// rgb/<t>.png (8-bit colour) and depth/<t>.png; EuRoC mav0/cam0/data/<ns>.png (8-bit grey) and
// mav0/depth0/data/<ns>.png. Depth: round(5000 Z), 0 for no surface or Z > 65535 / 5000 m.
Status WriteDatasetFrame(DatasetFormat format, const std::string& dir, double timestamp,
                         const RenderedFrame& frame);

}  // namespace m2s::export_tool
