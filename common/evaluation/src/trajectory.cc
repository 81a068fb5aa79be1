#include "m2s/common/trajectory.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>

#include <Eigen/SVD>

namespace m2s {
namespace {

// Splits a line on spaces, tabs and commas.
std::vector<std::string_view> Fields(std::string_view line) {
  std::vector<std::string_view> fields;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() &&
           (line[i] == ' ' || line[i] == '\t' || line[i] == ',' || line[i] == '\r')) {
      ++i;
    }
    const size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != ',' &&
           line[i] != '\r') {
      ++i;
    }
    if (i > start) fields.push_back(line.substr(start, i - start));
  }
  return fields;
}

bool ParseDouble(std::string_view s, double* out) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && end == s.data() + s.size() && std::isfinite(*out);
}

// Reads the non-comment, non-blank lines of a file with their 1-based line numbers.
struct Line {
  int number;
  std::string text;
};
Expected<std::vector<Line>> ReadLines(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Expected<std::vector<Line>>::Error("'" + path + "': cannot open file");
  std::vector<Line> lines;
  std::string text;
  for (int number = 1; std::getline(in, text); ++number) {
    const size_t first = text.find_first_not_of(" \t\r");
    if (first == std::string::npos || text[first] == '#') continue;
    lines.push_back({number, text});
  }
  if (in.bad()) return Expected<std::vector<Line>>::Error("'" + path + "': read error");
  if (lines.empty()) return Expected<std::vector<Line>>::Error("'" + path + "': no poses in file");
  return lines;
}

std::string At(const std::string& path, int line) {
  return "'" + path + "' line " + std::to_string(line) + ": ";
}

// Parses `count` numbers from the first fields of a line (extra fields allowed or not).
Status ParseNumbers(const std::string& path, const Line& line, size_t count, bool allow_extra,
                    std::vector<double>* out) {
  const std::vector<std::string_view> fields = Fields(line.text);
  if (fields.size() < count || (!allow_extra && fields.size() != count)) {
    return Status::Error(At(path, line.number) + "expected " + std::to_string(count) +
                         " numbers, found " + std::to_string(fields.size()) + " fields");
  }
  out->resize(count);
  for (size_t i = 0; i < count; ++i) {
    if (!ParseDouble(fields[i], &(*out)[i])) {
      return Status::Error(At(path, line.number) + "field " + std::to_string(i + 1) + " '" +
                           std::string(fields[i]) + "' is not a finite number");
    }
  }
  return Status::Ok();
}

Expected<Eigen::Quaterniond> MakeRotation(const std::string& path, int line, double w, double x,
                                          double y, double z) {
  const Eigen::Quaterniond q(w, x, y, z);
  if (!(q.norm() > 1e-6)) {
    return Expected<Eigen::Quaterniond>::Error(At(path, line) + "quaternion has zero norm");
  }
  return q.normalized();
}

Expected<Trajectory> Finish(const std::string& path, std::vector<TimedPose> poses) {
  Expected<Trajectory> trajectory = Trajectory::FromPoses(std::move(poses));
  if (!trajectory) return Expected<Trajectory>::Error("'" + path + "': " + trajectory.error());
  return trajectory;
}

}  // namespace

Expected<Trajectory> Trajectory::FromPoses(std::vector<TimedPose> poses) {
  for (const TimedPose& p : poses) {
    if (!std::isfinite(p.timestamp) || !p.world_from_camera.AllFinite()) {
      return Expected<Trajectory>::Error("non-finite pose or timestamp");
    }
  }
  std::stable_sort(poses.begin(), poses.end(), [](const TimedPose& a, const TimedPose& b) {
    return a.timestamp < b.timestamp;
  });
  for (size_t i = 1; i < poses.size(); ++i) {
    if (poses[i].timestamp == poses[i - 1].timestamp) {
      std::ostringstream os;
      os << "duplicate timestamp " << std::setprecision(17) << poses[i].timestamp;
      return Expected<Trajectory>::Error(os.str());
    }
  }
  Trajectory trajectory;
  trajectory.poses_ = std::move(poses);
  return trajectory;
}

Expected<Pose3> Trajectory::Interpolate(double t) const {
  if (poses_.empty()) return Expected<Pose3>::Error("cannot interpolate an empty trajectory");
  if (!(t >= start_time() && t <= end_time())) {
    std::ostringstream os;
    os << std::setprecision(17) << "time " << t << " is outside the trajectory [" << start_time()
       << ", " << end_time() << "]";
    return Expected<Pose3>::Error(os.str());
  }
  const auto after = std::upper_bound(poses_.begin(), poses_.end(), t,
                                      [](double v, const TimedPose& p) { return v < p.timestamp; });
  const TimedPose& a = *(after - 1);
  if (a.timestamp == t || after == poses_.end()) return a.world_from_camera;
  const double alpha = (t - a.timestamp) / (after->timestamp - a.timestamp);
  return m2s::Interpolate(a.world_from_camera, after->world_from_camera, alpha);
}

Expected<Trajectory> Trajectory::SampleAt(const std::vector<double>& timestamps) const {
  std::vector<TimedPose> poses;
  poses.reserve(timestamps.size());
  for (double t : timestamps) {
    Expected<Pose3> pose = Interpolate(t);
    if (!pose) return Expected<Trajectory>::Error(pose.error());
    poses.push_back({t, *pose});
  }
  return FromPoses(std::move(poses));
}

Expected<Trajectory> Trajectory::Resample(double rate_hz) const {
  constexpr double kEndTolerance = 1e-9;  // seconds
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) {
    return Expected<Trajectory>::Error("resampling rate must be positive and finite");
  }
  if (poses_.empty()) return Expected<Trajectory>::Error("cannot resample an empty trajectory");
  std::vector<double> times;
  for (int64_t k = 0;; ++k) {
    double t = start_time() + static_cast<double>(k) / rate_hz;
    if (t > end_time() + kEndTolerance) break;
    times.push_back(std::min(t, end_time()));
  }
  return SampleAt(times);
}

Expected<Trajectory> ReadTum(const std::string& path) {
  Expected<std::vector<Line>> lines = ReadLines(path);
  if (!lines) return Expected<Trajectory>::Error(lines.error());
  std::vector<TimedPose> poses;
  std::vector<double> v;
  for (const Line& line : *lines) {
    if (Status s = ParseNumbers(path, line, 8, false, &v); !s) return Expected<Trajectory>(s);
    Expected<Eigen::Quaterniond> q = MakeRotation(path, line.number, v[7], v[4], v[5], v[6]);
    if (!q) return Expected<Trajectory>(q.status());
    poses.push_back({v[0], Pose3(*q, Eigen::Vector3d(v[1], v[2], v[3]))});
  }
  return Finish(path, std::move(poses));
}

Status WriteTum(const std::string& path, const Trajectory& trajectory) {
  std::ofstream out(path);
  if (!out) return Status::Error("'" + path + "': cannot open file for writing");
  out << "# timestamp tx ty tz qx qy qz qw (world_from_camera)\n";
  out << std::setprecision(std::numeric_limits<double>::max_digits10);
  for (const TimedPose& p : trajectory) {
    const Eigen::Vector3d& t = p.world_from_camera.translation();
    const Eigen::Quaterniond& q = p.world_from_camera.rotation();
    out << p.timestamp << ' ' << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << q.x() << ' '
        << q.y() << ' ' << q.z() << ' ' << q.w() << '\n';
  }
  out.flush();
  if (!out) return Status::Error("'" + path + "': write error");
  return Status::Ok();
}

Expected<Trajectory> ReadKitti(const std::string& poses_path, const KittiReadOptions& options) {
  Expected<std::vector<Line>> lines = ReadLines(poses_path);
  if (!lines) return Expected<Trajectory>::Error(lines.error());
  std::vector<double> times;
  if (!options.times_path.empty()) {
    Expected<std::vector<Line>> time_lines = ReadLines(options.times_path);
    if (!time_lines) return Expected<Trajectory>::Error(time_lines.error());
    std::vector<double> v;
    for (const Line& line : *time_lines) {
      if (Status s = ParseNumbers(options.times_path, line, 1, false, &v); !s) {
        return Expected<Trajectory>(s);
      }
      times.push_back(v[0]);
    }
    if (times.size() != lines->size()) {
      return Expected<Trajectory>::Error(
          "'" + options.times_path + "': " + std::to_string(times.size()) + " timestamps for " +
          std::to_string(lines->size()) + " poses in '" + poses_path + "'");
    }
  } else if (!(options.frame_period_s > 0.0) || !std::isfinite(options.frame_period_s) ||
             !std::isfinite(options.start_time_s)) {
    return Expected<Trajectory>::Error("KITTI frame period must be positive and finite");
  }
  std::vector<TimedPose> poses;
  std::vector<double> v;
  for (size_t i = 0; i < lines->size(); ++i) {
    const Line& line = (*lines)[i];
    if (Status s = ParseNumbers(poses_path, line, 12, false, &v); !s)
      return Expected<Trajectory>(s);
    Eigen::Matrix3d r;
    r << v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10];
    if ((r.transpose() * r - Eigen::Matrix3d::Identity()).norm() > 1e-3 || r.determinant() < 0) {
      return Expected<Trajectory>::Error(At(poses_path, line.number) +
                                         "the 3x3 block is not a rotation");
    }
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Matrix3d nearest = svd.matrixU() * svd.matrixV().transpose();
    const double t = times.empty()
                         ? options.start_time_s + static_cast<double>(i) * options.frame_period_s
                         : times[i];
    poses.push_back({t, Pose3(nearest, Eigen::Vector3d(v[3], v[7], v[11]))});
  }
  return Finish(poses_path, std::move(poses));
}

Expected<Trajectory> ReadEuroc(const std::string& path, const EurocReadOptions& options) {
  Expected<std::vector<Line>> lines = ReadLines(path);
  if (!lines) return Expected<Trajectory>::Error(lines.error());
  std::vector<TimedPose> poses;
  std::vector<double> v;
  for (const Line& line : *lines) {
    const std::vector<std::string_view> fields = Fields(line.text);
    if (fields.size() < 8) {
      return Expected<Trajectory>::Error(At(path, line.number) +
                                         "expected at least 8 fields, found " +
                                         std::to_string(fields.size()));
    }
    int64_t ns = 0;
    const auto [end, ec] =
        std::from_chars(fields[0].data(), fields[0].data() + fields[0].size(), ns);
    if (ec != std::errc() || end != fields[0].data() + fields[0].size()) {
      return Expected<Trajectory>::Error(At(path, line.number) + "timestamp '" +
                                         std::string(fields[0]) + "' is not an integer (ns)");
    }
    if (Status s = ParseNumbers(path, line, 8, true, &v); !s) return Expected<Trajectory>(s);
    Expected<Eigen::Quaterniond> q = MakeRotation(path, line.number, v[4], v[5], v[6], v[7]);
    if (!q) return Expected<Trajectory>(q.status());
    const Pose3 world_from_body(*q, Eigen::Vector3d(v[1], v[2], v[3]));
    poses.push_back({static_cast<double>(ns) * 1e-9, world_from_body * options.body_from_camera});
  }
  return Finish(path, std::move(poses));
}

}  // namespace m2s
