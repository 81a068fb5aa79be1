// Runs m2s_export as a user does and reads what it writes with readers written here to the
// formats' documentation: TUM RGB-D (rgb.txt / depth.txt / groundtruth.txt: '#' comments, then
// "timestamp filename" or "timestamp tx ty tz qx qy qz qw"; colour PNG 8-bit RGB, depth PNG
// 16-bit grey at 5000 per metre, 0 = no data), EuRoC / ASL (csv with a '#' header, timestamps
// in ns; sensor.yaml; state_groundtruth_estimate0 with p, q (w first), v, biases) and the
// ORB-SLAM settings through cv::FileStorage, as ORB-SLAM reads them. The scene is a box room
// generated here, so its depth is known in closed form.
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "m2s/common/camera.h"
#include "m2s/common/numeric.h"
#include "m2s/common/trajectory.h"
#include "m2s/gpu/gl_context.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;

// The room: the inside of the box [-2, 2] x [-1.5, 1.5] x [0, 2.5].
const Eigen::Vector3d kRoomMin(-2, -1.5, 0), kRoomMax(2, 1.5, 2.5);

struct RunResult {
  int exit_code = -1;
  std::string out, err;
};

std::string Slurp(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

RunResult RunExport(const fs::path& dir, const std::string& args) {
  const fs::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string cmd = std::string(M2S_BINARY_DIR) + "/bin/m2s_export " + args + " >" +
                          out.string() + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, Slurp(out), Slurp(err)};
}

// Non-comment lines split at spaces (TUM) or commas (EuRoC).
std::vector<std::vector<std::string>> ReadTable(const fs::path& path, char separator) {
  std::vector<std::vector<std::string>> rows;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> fields;
    std::stringstream s(line);
    std::string field;
    while (std::getline(s, field, separator)) {
      if (!field.empty()) fields.push_back(field);
    }
    rows.push_back(fields);
  }
  return rows;
}

// A PNG's bit depth and colour type, from its IHDR chunk (PNG specification, 11.2.2).
std::pair<int, int> PngDepthAndColourType(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  char header[26] = {};
  in.read(header, sizeof(header));
  const std::string signature = "\x89PNG\r\n\x1a\n";
  if (!in || std::string(header, 8) != signature || std::string(header + 12, 4) != "IHDR") {
    return {-1, -1};
  }
  return {static_cast<unsigned char>(header[24]), static_cast<unsigned char>(header[25])};
}

// The camera z of the room's wall seen at pixel (i, j): the ray through the pixel centre
// leaves the box at the nearest wall.
double RoomDepth(const Pose3& world_from_camera, const Camera& camera, int i, int j,
                 double* margin) {
  const Eigen::Vector3d ray_camera = camera.Unproject({i + 0.5, j + 0.5}, 1.0);
  const Eigen::Vector3d c = world_from_camera.translation();
  const Eigen::Vector3d d = world_from_camera.rotation() * ray_camera;
  double t = INFINITY;
  int axis = -1;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) continue;
    const double ta = ((d[a] > 0 ? kRoomMax[a] : kRoomMin[a]) - c[a]) / d[a];
    if (ta < t) t = ta, axis = a;
  }
  // How far (in m along the wall) the hit is from the wall's edges: near an edge a pixel may
  // show either wall.
  const Eigen::Vector3d hit = c + t * d;
  *margin = INFINITY;
  for (int a = 0; a < 3; ++a) {
    if (a == axis) continue;
    *margin = std::min({*margin, hit[a] - kRoomMin[a], kRoomMax[a] - hit[a]});
  }
  return t;  // ray_camera has z = 1, so t is the camera z
}

class ExportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("m2s_export_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    // The box room as an OBJ: 8 corners, 12 triangles.
    std::ofstream obj(dir_ / "room.obj");
    for (int k = 0; k < 8; ++k) {
      obj << "v " << (k & 1 ? kRoomMax : kRoomMin).x() << " " << (k & 2 ? kRoomMax : kRoomMin).y()
          << " " << (k & 4 ? kRoomMax : kRoomMin).z() << "\n";
    }
    obj << "f 1 2 4 3\nf 5 6 8 7\nf 1 2 6 5\nf 3 4 8 7\nf 1 3 7 5\nf 2 4 8 6\n";
    camera_.width = 160, camera_.height = 120;
    camera_.fx = camera_.fy = 110, camera_.cx = 80, camera_.cy = 60;
    camera_.near = 0.05, camera_.far = 20;
    std::ofstream(dir_ / "CAMERA.json")
        << "{\"width\": 160, \"height\": 120, \"fx\": " << camera_.fx << ", \"fy\": " << camera_.fy
        << ", \"cx\": " << camera_.cx << ", \"cy\": " << camera_.cy
        << ", \"near\": 0.05, \"far\": 20}\n";
    // Uneven times, a straight walk (constant velocity) while turning.
    std::vector<TimedPose> poses;
    for (int k = 0; k < 6; ++k) {
      const double t = 100.0 + 0.1 * k + (k % 2 ? 0.013 : 0.0);
      const Eigen::Vector3d eye = velocity_ * (t - 100.0) + Eigen::Vector3d(-1.0, -0.5, 1.4);
      poses.push_back(
          {t, LookAt(eye, eye + Eigen::Vector3d(std::cos(0.3 * k), std::sin(0.3 * k), -0.2))});
    }
    trajectory_ = *Trajectory::FromPoses(poses);
    ASSERT_TRUE(WriteTum((dir_ / "gt.tum").string(), trajectory_).ok());
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string CommonArgs(const std::string& format, const fs::path& out) const {
    return "--mesh " + (dir_ / "room.obj").string() + " --trajectory " +
           (dir_ / "gt.tum").string() + " --camera " + (dir_ / "CAMERA.json").string() +
           " --format " + format + " --out " + out.string();
  }

  // Every 16-bit depth pixel away from the room's edges equals the wall's depth to the
  // format's resolution (1/5000 m) plus the renderer's float precision.
  void ExpectDepthImage(const fs::path& png, const Pose3& pose) {
    const cv::Mat depth = cv::imread(png.string(), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(depth.type(), CV_16UC1) << png;
    ASSERT_EQ(depth.cols, camera_.width);
    int checked = 0;
    for (int j = 0; j < depth.rows; ++j) {
      for (int i = 0; i < depth.cols; ++i) {
        double margin = 0;
        const double z = RoomDepth(pose, camera_, i, j, &margin);
        if (margin < 0.02) continue;
        EXPECT_NEAR(depth.at<uint16_t>(j, i) / 5000.0, z, 0.5 / 5000 + 1e-5 * z)
            << png << " pixel " << i << "," << j;
        ++checked;
      }
    }
    EXPECT_GT(checked, depth.total() * 0.8);
  }

  fs::path dir_;
  Camera camera_;
  Trajectory trajectory_;
  Eigen::Vector3d velocity_{0.8, 0.3, 0.1};
};

#define M2S_SKIP_WITHOUT_EGL() \
  if (!GlContext::AnyEglDisplayAvailable()) GTEST_SKIP() << "no EGL display on this machine"

TEST_F(ExportTest, TumRgbdHasOneImagePairPerPoseAndTheInputPoses) {
  M2S_SKIP_WITHOUT_EGL();
  const fs::path out = dir_ / "tum";
  const RunResult r = RunExport(dir_, CommonArgs("tum-rgbd", out));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("6 frames"), std::string::npos) << r.out;

  const auto rgb = ReadTable(out / "rgb.txt", ' '), depth = ReadTable(out / "depth.txt", ' ');
  const auto truth = ReadTable(out / "groundtruth.txt", ' ');
  ASSERT_EQ(rgb.size(), trajectory_.size());
  ASSERT_EQ(depth.size(), trajectory_.size());
  ASSERT_EQ(truth.size(), trajectory_.size());
  for (size_t k = 0; k < trajectory_.size(); ++k) {
    const TimedPose& want = trajectory_[k];
    char stamp[32];
    std::snprintf(stamp, sizeof(stamp), "%.6f", want.timestamp);
    ASSERT_EQ(rgb[k].size(), 2u);
    EXPECT_EQ(rgb[k][0], stamp);
    EXPECT_EQ(rgb[k][1], "rgb/" + std::string(stamp) + ".png");
    EXPECT_EQ(depth[k][0], stamp);
    EXPECT_EQ(depth[k][1], "depth/" + std::string(stamp) + ".png");
    EXPECT_EQ(PngDepthAndColourType(out / rgb[k][1]), std::make_pair(8, 2));     // 8-bit RGB
    EXPECT_EQ(PngDepthAndColourType(out / depth[k][1]), std::make_pair(16, 0));  // 16-bit grey
    // Ground truth: the input pose, to the printed precision (quaternion up to sign).
    ASSERT_EQ(truth[k].size(), 8u);
    EXPECT_EQ(truth[k][0], stamp);
    const Eigen::Vector3d p(std::stod(truth[k][1]), std::stod(truth[k][2]), std::stod(truth[k][3]));
    const Eigen::Quaterniond q(std::stod(truth[k][7]), std::stod(truth[k][4]),
                               std::stod(truth[k][5]), std::stod(truth[k][6]));
    EXPECT_LT((p - want.world_from_camera.translation()).norm(), 1e-8);
    EXPECT_NEAR(std::abs(q.dot(want.world_from_camera.rotation())), 1.0, 1e-8);
    ExpectDepthImage(out / depth[k][1], want.world_from_camera);
  }
  // ORB-SLAM reads its settings with cv::FileStorage; intrinsics in OpenCV's convention.
  cv::FileStorage settings((out / "orbslam_settings.yaml").string(), cv::FileStorage::READ);
  ASSERT_TRUE(settings.isOpened());
  EXPECT_DOUBLE_EQ(static_cast<double>(settings["Camera.fx"]), camera_.fx);
  EXPECT_DOUBLE_EQ(static_cast<double>(settings["Camera.fy"]), camera_.fy);
  EXPECT_DOUBLE_EQ(static_cast<double>(settings["Camera.cx"]), camera_.cx - 0.5);
  EXPECT_DOUBLE_EQ(static_cast<double>(settings["Camera.cy"]), camera_.cy - 0.5);
  EXPECT_EQ(static_cast<int>(settings["Camera.width"]), camera_.width);
  EXPECT_EQ(static_cast<int>(settings["Camera.RGB"]), 1);
  EXPECT_DOUBLE_EQ(static_cast<double>(settings["DepthMapFactor"]), 5000.0);
  EXPECT_EQ(static_cast<int>(settings["ORBextractor.nFeatures"]), 1000);
  for (const char* key : {"Camera.k1", "Camera.k2", "Camera.p1", "Camera.p2"}) {
    EXPECT_EQ(static_cast<double>(settings[key]), 0.0) << key;
  }
}

// Reads EuRoC's sensor.yaml by lines ("key: value"; T_BS's data list spans lines).
std::map<std::string, std::string> ReadSensorYaml(const fs::path& path) {
  std::map<std::string, std::string> values;
  std::ifstream in(path);
  std::string line, open_key;
  while (std::getline(in, line)) {
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    if (line.find_first_not_of(' ') == std::string::npos || line[0] == '%') continue;
    if (!open_key.empty()) {
      values[open_key] += line;
    } else if (const size_t colon = line.find(':'); colon != std::string::npos) {
      std::string key = line.substr(0, colon);
      key.erase(0, key.find_first_not_of(' '));
      if (line.find_first_not_of(' ') > 0) key = "T_BS." + key;  // the only nested map
      const size_t value = line.find_first_not_of(' ', colon + 1);
      values[key] = value == std::string::npos ? "" : line.substr(value);
      if (!values[key].empty() && values[key].front() == '[' &&
          values[key].find(']') == std::string::npos) {
        open_key = key;
      }
    }
    if (!open_key.empty() && values[open_key].find(']') != std::string::npos) open_key.clear();
  }
  return values;
}

std::vector<double> Numbers(std::string list) {
  for (char& c : list) {
    if (c == '[' || c == ']' || c == ',') c = ' ';
  }
  std::stringstream s(list);
  std::vector<double> out;
  for (double x; s >> x;) out.push_back(x);
  return out;
}

TEST_F(ExportTest, EurocResamplesAtTheRateAndWritesItsLayout) {
  M2S_SKIP_WITHOUT_EGL();
  const fs::path out = dir_ / "euroc";
  const RunResult r = RunExport(dir_, CommonArgs("euroc", out) + " --fps 20 --max-frames 9");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Frames at t0 + k / 20 within the trajectory (100.0 .. 100.513), at most 9.
  std::vector<double> times;
  for (int k = 0; k < 9 && 100.0 + k / 20.0 <= trajectory_.end_time(); ++k) {
    times.push_back(100.0 + k / 20.0);
  }
  ASSERT_EQ(times.size(), 9u);
  const auto cam = ReadTable(out / "mav0" / "cam0" / "data.csv", ',');
  const auto truth = ReadTable(out / "mav0" / "state_groundtruth_estimate0" / "data.csv", ',');
  ASSERT_EQ(cam.size(), times.size());
  ASSERT_EQ(truth.size(), times.size());
  for (size_t k = 0; k < times.size(); ++k) {
    const std::string ns = std::to_string(std::llround(times[k] * 1e9));
    ASSERT_EQ(cam[k].size(), 2u);
    EXPECT_EQ(cam[k][0], ns);
    EXPECT_EQ(cam[k][1], ns + ".png");
    const fs::path png = out / "mav0" / "cam0" / "data" / cam[k][1];
    EXPECT_EQ(PngDepthAndColourType(png), std::make_pair(8, 0));  // 8-bit grey, as EuRoC
    ASSERT_EQ(truth[k].size(), 17u);
    EXPECT_EQ(truth[k][0], ns);
    const Pose3 want = *trajectory_.Interpolate(times[k]);
    const Eigen::Vector3d p(std::stod(truth[k][1]), std::stod(truth[k][2]), std::stod(truth[k][3]));
    const Eigen::Quaterniond q(std::stod(truth[k][4]), std::stod(truth[k][5]),
                               std::stod(truth[k][6]), std::stod(truth[k][7]));
    EXPECT_LT((p - want.translation()).norm(), 1e-8);
    EXPECT_NEAR(std::abs(q.dot(want.rotation())), 1.0, 1e-8);
    // The walk is straight at constant speed: finite differences give the velocity.
    const Eigen::Vector3d v(std::stod(truth[k][8]), std::stod(truth[k][9]),
                            std::stod(truth[k][10]));
    EXPECT_LT((v - velocity_).norm(), 1e-6) << "frame " << k;
    for (int c = 11; c < 17; ++c) EXPECT_EQ(std::stod(truth[k][c]), 0.0);
    ExpectDepthImage(out / "mav0" / "depth0" / "data" / cam[k][1], want);
  }
  auto yaml = ReadSensorYaml(out / "mav0" / "cam0" / "sensor.yaml");
  EXPECT_EQ(yaml["sensor_type"], "camera");
  EXPECT_EQ(yaml["camera_model"], "pinhole");
  EXPECT_EQ(yaml["distortion_model"], "radial-tangential");
  EXPECT_EQ(Numbers(yaml["rate_hz"]), std::vector<double>{20});
  EXPECT_EQ(Numbers(yaml["resolution"]), (std::vector<double>{160, 120}));
  EXPECT_EQ(Numbers(yaml["intrinsics"]),
            (std::vector<double>{camera_.fx, camera_.fy, camera_.cx - 0.5, camera_.cy - 0.5}));
  EXPECT_EQ(Numbers(yaml["distortion_coefficients"]), (std::vector<double>{0, 0, 0, 0}));
  EXPECT_EQ(Numbers(yaml["T_BS.data"]),
            (std::vector<double>{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}));
  EXPECT_EQ(yaml["T_BS.rows"], "4");
}

TEST_F(ExportTest, BadInputsGiveOneLineAndExitTwo) {
  fs::create_directories(dir_ / "empty");
  std::ofstream(dir_ / "empty.tum") << "# nothing here\n";
  const std::string traj = " --trajectory " + (dir_ / "gt.tum").string();
  const std::pair<std::string, std::string> cases[] = {
      {"--mesh " + (dir_ / "missing.obj").string() + traj + " --format tum-rgbd --out " +
           (dir_ / "o1").string(),
       "missing.obj"},
      {"--mesh " + (dir_ / "room.obj").string() + traj + " --format kitti --out " +
           (dir_ / "o2").string(),
       "kitti"},
      {"--mesh " + (dir_ / "room.obj").string() + " --trajectory " + (dir_ / "empty.tum").string() +
           " --format euroc --out " + (dir_ / "o3").string(),
       "no poses"},
      {"--format euroc", "--out"},
  };
  for (const auto& [args, needle] : cases) {
    const RunResult r = RunExport(dir_, args);
    EXPECT_EQ(r.exit_code, 2) << args << ": " << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << args << ": " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("m2s_export: ", 0), 0u) << r.err;
  }
}

}  // namespace
}  // namespace m2s
