#include "dataset_writer.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace m2s::export_tool {
namespace {

namespace fs = std::filesystem;

// TUM's file names and timestamps: seconds with 6 decimals.
std::string TumStamp(double t) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.6f", t);
  return buffer;
}

// EuRoC's: integer nanoseconds.
std::string EurocStamp(double t) { return std::to_string(std::llround(t * 1e9)); }

// A text file written whole; errors name the file.
class TextFile {
 public:
  explicit TextFile(const fs::path& path) : path_(path), file_(std::fopen(path.c_str(), "w")) {}
  ~TextFile() {
    if (file_ != nullptr) std::fclose(file_);
  }
  TextFile(const TextFile&) = delete;
  TextFile& operator=(const TextFile&) = delete;

  template <typename... Args>
  void Print(const char* format, Args... args) {
    if (file_ != nullptr) std::fprintf(file_, format, args...);
  }
  void Print(const std::string& text) {
    if (file_ != nullptr) std::fputs(text.c_str(), file_);
  }
  Status Close() {
    if (file_ == nullptr) return Status::Error("cannot write " + path_.string());
    const bool ok = std::ferror(file_) == 0;
    const bool closed = std::fclose(file_) == 0;
    file_ = nullptr;
    return ok && closed ? Status::Ok() : Status::Error("cannot write " + path_.string());
  }

 private:
  fs::path path_;
  std::FILE* file_;
};

Status MakeDirectories(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::Error("cannot create folder " + dir.string() + ": " + ec.message());
  return Status::Ok();
}

Status WriteTumIndex(const fs::path& dir, const Trajectory& frames) {
  for (const char* sub : {"rgb", "depth"}) {
    if (Status s = MakeDirectories(dir / sub); !s) return s;
  }
  TextFile rgb(dir / "rgb.txt"), depth(dir / "depth.txt"), pairs(dir / "associations.txt"),
      truth(dir / "groundtruth.txt");
  rgb.Print("# color images\n# rendered by m2s_export\n# timestamp filename\n");
  depth.Print("# depth maps\n# rendered by m2s_export\n# timestamp filename\n");
  truth.Print(
      "# ground truth trajectory\n# rendered by m2s_export\n# timestamp tx ty tz qx qy qz qw\n");
  for (const TimedPose& frame : frames) {
    const std::string t = TumStamp(frame.timestamp);
    rgb.Print("%s rgb/%s.png\n", t.c_str(), t.c_str());
    depth.Print("%s depth/%s.png\n", t.c_str(), t.c_str());
    pairs.Print("%s rgb/%s.png %s depth/%s.png\n", t.c_str(), t.c_str(), t.c_str(), t.c_str());
    const Eigen::Vector3d& p = frame.world_from_camera.translation();
    const Eigen::Quaterniond& q = frame.world_from_camera.rotation();
    truth.Print("%s %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", t.c_str(), p.x(), p.y(), p.z(), q.x(),
                q.y(), q.z(), q.w());
  }
  for (TextFile* file : {&rgb, &depth, &pairs, &truth}) {
    if (Status s = file->Close(); !s) return s;
  }
  return Status::Ok();
}

// Velocity of the camera centre at frame k by finite differences (central inside, one-sided
// at the ends; zero for a single frame).
Eigen::Vector3d Velocity(const Trajectory& frames, size_t k) {
  if (frames.size() < 2) return Eigen::Vector3d::Zero();
  const size_t a = k == 0 ? 0 : k - 1, b = k + 1 == frames.size() ? k : k + 1;
  return (frames[b].world_from_camera.translation() - frames[a].world_from_camera.translation()) /
         (frames[b].timestamp - frames[a].timestamp);
}

Status WriteEurocIndex(const fs::path& dir, const Trajectory& frames, const Camera& camera,
                       double rate_hz) {
  const fs::path mav = dir / "mav0";
  for (const fs::path& sub :
       {mav / "cam0" / "data", mav / "depth0" / "data", mav / "state_groundtruth_estimate0"}) {
    if (Status s = MakeDirectories(sub); !s) return s;
  }
  TextFile cam(mav / "cam0" / "data.csv"), depth(mav / "depth0" / "data.csv"),
      truth(mav / "state_groundtruth_estimate0" / "data.csv"), times(dir / "timestamps.txt");
  cam.Print("#timestamp [ns],filename\n");
  depth.Print("#timestamp [ns],filename\n");
  truth.Print(
      "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], "
      "q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], "
      "b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], "
      "b_a_RS_S_z [m s^-2]\n");
  for (size_t k = 0; k < frames.size(); ++k) {
    const std::string ns = EurocStamp(frames[k].timestamp);
    cam.Print("%s,%s.png\n", ns.c_str(), ns.c_str());
    depth.Print("%s,%s.png\n", ns.c_str(), ns.c_str());
    times.Print("%s\n", ns.c_str());
    const Eigen::Vector3d& p = frames[k].world_from_camera.translation();
    const Eigen::Quaterniond& q = frames[k].world_from_camera.rotation();
    const Eigen::Vector3d v = Velocity(frames, k);
    truth.Print("%s,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,0,0,0,0,0,0\n", ns.c_str(),
                p.x(), p.y(), p.z(), q.w(), q.x(), q.y(), q.z(), v.x(), v.y(), v.z());
  }
  // sensor.yaml as EuRoC writes it; the camera is the body (T_BS identity).
  for (const char* sensor : {"cam0", "depth0"}) {
    TextFile yaml(mav / sensor / "sensor.yaml");
    yaml.Print("%%YAML:1.0\n# General sensor definitions.\nsensor_type: camera\n");
    yaml.Print("comment: m2s_export %s\n\n", std::string(sensor) == "cam0"
                                                 ? "rendered grey images"
                                                 : "rendered depth, 16-bit PNG, 5000 per metre");
    yaml.Print(
        "# Sensor extrinsics wrt. the body-frame.\nT_BS:\n  cols: 4\n  rows: 4\n"
        "  data: [1.0, 0.0, 0.0, 0.0,\n         0.0, 1.0, 0.0, 0.0,\n"
        "         0.0, 0.0, 1.0, 0.0,\n         0.0, 0.0, 0.0, 1.0]\n\n");
    yaml.Print("# Camera specific definitions.\nrate_hz: %.9g\nresolution: [%d, %d]\n", rate_hz,
               camera.width, camera.height);
    yaml.Print("camera_model: pinhole\nintrinsics: [%.9g, %.9g, %.9g, %.9g] #fu, fv, cu, cv\n",
               camera.fx, camera.fy, camera.cx - 0.5, camera.cy - 0.5);
    yaml.Print(
        "distortion_model: radial-tangential\ndistortion_coefficients: [0.0, 0.0, 0.0, 0.0]\n");
    if (Status s = yaml.Close(); !s) return s;
  }
  for (TextFile* file : {&cam, &depth, &truth, &times}) {
    if (Status s = file->Close(); !s) return s;
  }
  return Status::Ok();
}

// ORB-SLAM2 / ORB-SLAM3 (pre-1.0 keys, which both read) settings for these images.
Status WriteOrbSlamSettings(const fs::path& path, DatasetFormat format, const Camera& camera,
                            double rate_hz) {
  TextFile yaml(path);
  yaml.Print(
      "%%YAML:1.0\n\n# Camera parameters of images rendered by m2s_export (pinhole, no "
      "distortion;\n# cx, cy in OpenCV's pixel-centre convention).\n");
  yaml.Print("Camera.type: \"PinHole\"\n");
  yaml.Print("Camera.fx: %.9f\nCamera.fy: %.9f\nCamera.cx: %.9f\nCamera.cy: %.9f\n\n", camera.fx,
             camera.fy, camera.cx - 0.5, camera.cy - 0.5);
  yaml.Print("Camera.k1: 0.0\nCamera.k2: 0.0\nCamera.p1: 0.0\nCamera.p2: 0.0\nCamera.k3: 0.0\n\n");
  yaml.Print("Camera.width: %d\nCamera.height: %d\n\n", camera.width, camera.height);
  yaml.Print("# Camera frames per second\nCamera.fps: %.9g\n\n", rate_hz);
  yaml.Print(
      "# IR projector baseline times fx (aprox.), for the RGB-D examples\nCamera.bf: %.9f\n\n",
      0.08 * camera.fx);
  yaml.Print(
      "# Color order of the images (0: BGR, 1: RGB. It is ignored if images are "
      "grayscale)\nCamera.RGB: 1\n\n");
  yaml.Print("# Close/Far threshold. Baseline times.\nThDepth: 40.0\n\n");
  if (format == DatasetFormat::kTumRgbd) {
    yaml.Print("# Depthmap values factor\nDepthMapFactor: %.1f\n\n", kDepthUnitsPerMetre);
  }
  yaml.Print(
      "# ORB Extractor: Number of features per image\nORBextractor.nFeatures: 1000\n"
      "ORBextractor.scaleFactor: 1.2\nORBextractor.nLevels: 8\nORBextractor.iniThFAST: 20\n"
      "ORBextractor.minThFAST: 7\n\n");
  yaml.Print(
      "# Viewer Parameters\nViewer.KeyFrameSize: 0.05\nViewer.KeyFrameLineWidth: 1.0\n"
      "Viewer.GraphLineWidth: 0.9\nViewer.PointSize: 2.0\nViewer.CameraSize: 0.08\n"
      "Viewer.CameraLineWidth: 3.0\nViewer.ViewpointX: 0.0\nViewer.ViewpointY: -0.7\n"
      "Viewer.ViewpointZ: -1.8\nViewer.ViewpointF: 500.0\n");
  return yaml.Close();
}

// DSO's calibration file: pinhole in pixels (its pixel-centre convention is OpenCV's), no
// rectification.
Status WriteDsoCamera(const fs::path& path, const Camera& camera) {
  TextFile file(path);
  file.Print("Pinhole %.9g %.9g %.9g %.9g 0\n%d %d\nnone\n%d %d\n", camera.fx, camera.fy,
             camera.cx - 0.5, camera.cy - 0.5, camera.width, camera.height, camera.width,
             camera.height);
  return file.Close();
}

Status WriteCameraJson(const fs::path& path, const Camera& camera) {
  const nlohmann::json json = {{"width", camera.width}, {"height", camera.height},
                               {"fx", camera.fx},       {"fy", camera.fy},
                               {"cx", camera.cx},       {"cy", camera.cy},
                               {"near", camera.near},   {"far", camera.far}};
  TextFile file(path);
  file.Print(json.dump(2) + "\n");
  return file.Close();
}

Status WritePng(const fs::path& path, const cv::Mat& image) {
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), image);
  } catch (const cv::Exception& e) {
    ok = false;
  }
  return ok ? Status::Ok() : Status::Error("cannot write " + path.string());
}

}  // namespace

Expected<DatasetFormat> ParseDatasetFormat(const std::string& name) {
  if (name == "tum-rgbd") return DatasetFormat::kTumRgbd;
  if (name == "euroc") return DatasetFormat::kEuroc;
  return Expected<DatasetFormat>::Error("unknown format '" + name + "' (choose tum-rgbd or euroc)");
}

Status WriteDatasetIndex(DatasetFormat format, const std::string& dir, const Trajectory& frames,
                         const Camera& camera, double rate_hz) {
  if (frames.empty()) return Status::Error("no frames to export");
  std::set<std::string> names;
  for (const TimedPose& frame : frames) {
    if (format == DatasetFormat::kEuroc && frame.timestamp < 0) {
      return Status::Error("EuRoC needs timestamps >= 0 (got " + TumStamp(frame.timestamp) + ")");
    }
    const std::string name =
        format == DatasetFormat::kTumRgbd ? TumStamp(frame.timestamp) : EurocStamp(frame.timestamp);
    if (!names.insert(name).second) {
      return Status::Error("two frames share the file name " + name +
                           " (timestamps closer than the format's resolution)");
    }
  }
  if (Status s = MakeDirectories(dir); !s) return s;
  const fs::path root(dir);
  if (Status s = format == DatasetFormat::kTumRgbd ? WriteTumIndex(root, frames)
                                                   : WriteEurocIndex(root, frames, camera, rate_hz);
      !s) {
    return s;
  }
  if (Status s = WriteOrbSlamSettings(root / "orbslam_settings.yaml", format, camera, rate_hz); !s)
    return s;
  if (Status s = WriteDsoCamera(root / "dso_camera.txt", camera); !s) return s;
  return WriteCameraJson(root / "CAMERA.json", camera);
}

Status WriteDatasetFrame(DatasetFormat format, const std::string& dir, double timestamp,
                         const RenderedFrame& frame) {
  const size_t n = static_cast<size_t>(frame.width) * frame.height;
  if (frame.width <= 0 || frame.height <= 0 || frame.rgb.size() != 3 * n ||
      frame.depth.size() != n) {
    return Status::Error("rendered frame has inconsistent sizes");
  }
  const cv::Mat rgb(frame.height, frame.width, CV_8UC3, const_cast<uint8_t*>(frame.rgb.data()));
  cv::Mat depth(frame.height, frame.width, CV_16UC1);
  for (int y = 0; y < frame.height; ++y) {
    for (int x = 0; x < frame.width; ++x) {
      const double units =
          std::round(frame.depth[static_cast<size_t>(y) * frame.width + x] * kDepthUnitsPerMetre);
      depth.at<uint16_t>(y, x) = units > 0 && units <= 65535 ? static_cast<uint16_t>(units) : 0;
    }
  }
  const fs::path root(dir);
  cv::Mat converted;
  if (format == DatasetFormat::kTumRgbd) {
    const std::string name = TumStamp(timestamp) + ".png";
    cv::cvtColor(rgb, converted, cv::COLOR_RGB2BGR);  // imwrite takes BGR
    if (Status s = WritePng(root / "rgb" / name, converted); !s) return s;
    return WritePng(root / "depth" / name, depth);
  }
  const std::string name = EurocStamp(timestamp) + ".png";
  cv::cvtColor(rgb, converted, cv::COLOR_RGB2GRAY);
  if (Status s = WritePng(root / "mav0" / "cam0" / "data" / name, converted); !s) return s;
  return WritePng(root / "mav0" / "depth0" / "data" / name, depth);
}

}  // namespace m2s::export_tool
