// pnp_odometry: a plain frame-to-frame PnP odometry, the baseline a SLAM method is compared
// with. Monocular, so its scale is arbitrary (evaluation aligns with a Sim3).
//
//  1. Initialisation: the first frame is the reference; once the median feature motion since
//     the reference exceeds init_min_flow_px, the essential matrix of the shared ids
//     (cv::findEssentialMat, RANSAC) and cv::recoverPose give the relative pose, the inliers
//     are triangulated (at least init_min_points with min_parallax_deg between their rays) and
//     the scale is set so their median depth in the reference camera is 1. The world frame is
//     the reference camera's.
//  2. Each later frame: cv::solvePnPRansac of the ids that have a 3-D point, started from the
//     previous pose. Fewer than min_inliers inliers: the frame is lost and the next ones try
//     again against the same points (the first success is reported as relocalised).
//  3. New points: an id without a point remembers the tracked frame it was first seen in; once
//     the rays of that sighting and of the current frame differ by min_parallax_deg, it is
//     triangulated (midpoint of the two rays) and kept if it lies in front of both cameras and
//     reprojects within ransac_reprojection_px in both.
// Points never move once made: no bundle adjustment, no loop closure.
//
// Config (JSON object, all optional): min_parallax_deg (3.0), init_min_flow_px (20),
// init_min_points (50), min_inliers (15), ransac_reprojection_px (2.0), ransac_iterations (100),
// sighting_max_age_frames (60). Unknown keys are refused.
#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "m2s/plugin/plugin.h"

namespace {

using m2s::plugin::FrameResult;
using m2s::plugin::TrackState;

constexpr double kDegToRad = M_PI / 180.0;

struct Config {
  double min_parallax_deg = 3.0;
  double init_min_flow_px = 20.0;
  int init_min_points = 50;
  int min_inliers = 15;
  double ransac_reprojection_px = 2.0;
  int ransac_iterations = 100;
  int sighting_max_age_frames = 60;
};

Config ParseConfig(const std::string& text) {
  Config c;
  const nlohmann::json j = nlohmann::json::parse(text);
  if (!j.is_object()) throw std::invalid_argument("config: not a JSON object");
  for (const auto& [key, value] : j.items()) {
    if (key == "min_parallax_deg") {
      c.min_parallax_deg = value.get<double>();
    } else if (key == "init_min_flow_px") {
      c.init_min_flow_px = value.get<double>();
    } else if (key == "init_min_points") {
      c.init_min_points = value.get<int>();
    } else if (key == "min_inliers") {
      c.min_inliers = value.get<int>();
    } else if (key == "ransac_reprojection_px") {
      c.ransac_reprojection_px = value.get<double>();
    } else if (key == "ransac_iterations") {
      c.ransac_iterations = value.get<int>();
    } else if (key == "sighting_max_age_frames") {
      c.sighting_max_age_frames = value.get<int>();
    } else {
      throw std::invalid_argument("config: unknown key \"" + key + "\"");
    }
  }
  if (!(c.min_parallax_deg > 0) || !(c.init_min_flow_px > 0) || c.init_min_points < 8 ||
      c.min_inliers < 6 || !(c.ransac_reprojection_px > 0) || c.ransac_iterations < 1 ||
      c.sighting_max_age_frames < 1) {
    throw std::invalid_argument("config: a value is out of range");
  }
  return c;
}

// camera_from_world: x_camera = R x_world + t (OpenCV's rvec / tvec).
struct CameraPose {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t{0, 0, 0};
  cv::Vec3d Center() const { return -(R.t() * t); }
};

m2s_pose ToWorldFromCamera(const CameraPose& p) {
  const cv::Matx33d R = p.R.t();  // world_from_camera rotation
  const cv::Vec3d c = p.Center();
  // Rotation matrix to unit quaternion (Shepperd's method).
  std::array<double, 4> q;  // w, x, y, z
  const double trace = R(0, 0) + R(1, 1) + R(2, 2);
  if (trace > 0) {
    const double s = 2.0 * std::sqrt(1.0 + trace);
    q = {0.25 * s, (R(2, 1) - R(1, 2)) / s, (R(0, 2) - R(2, 0)) / s, (R(1, 0) - R(0, 1)) / s};
  } else if (R(0, 0) > R(1, 1) && R(0, 0) > R(2, 2)) {
    const double s = 2.0 * std::sqrt(1.0 + R(0, 0) - R(1, 1) - R(2, 2));
    q = {(R(2, 1) - R(1, 2)) / s, 0.25 * s, (R(0, 1) + R(1, 0)) / s, (R(0, 2) + R(2, 0)) / s};
  } else if (R(1, 1) > R(2, 2)) {
    const double s = 2.0 * std::sqrt(1.0 + R(1, 1) - R(0, 0) - R(2, 2));
    q = {(R(0, 2) - R(2, 0)) / s, (R(0, 1) + R(1, 0)) / s, 0.25 * s, (R(1, 2) + R(2, 1)) / s};
  } else {
    const double s = 2.0 * std::sqrt(1.0 + R(2, 2) - R(0, 0) - R(1, 1));
    q = {(R(1, 0) - R(0, 1)) / s, (R(0, 2) + R(2, 0)) / s, (R(1, 2) + R(2, 1)) / s, 0.25 * s};
  }
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  return {{q[0] / n, q[1] / n, q[2] / n, q[3] / n}, {c[0], c[1], c[2]}};
}

// Where an id was first seen in a tracked frame.
struct Sighting {
  cv::Point2d uv;
  CameraPose pose;
  int64_t frame_index = 0;
};

class PnpOdometry final : public m2s::plugin::Method {
 public:
  PnpOdometry(const m2s_camera& camera, const std::string& config_json)
      : camera_(camera), config_(ParseConfig(config_json)) {
    if (!(camera.fx > 0 && camera.fy > 0)) throw std::invalid_argument("camera: bad focal length");
    K_ = cv::Matx33d(camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1);
  }

  FrameResult ProcessFrame(const m2s_frame& frame) override {
    ++frame_index_;
    std::unordered_map<uint32_t, cv::Point2d> observed;
    observed.reserve(frame.num_features);
    for (uint32_t i = 0; i < frame.num_features; ++i) {
      const m2s_feature& f = frame.features[i];
      observed[f.id] = cv::Point2d(f.u, f.v);
    }
    if (!initialized_) return Initialize(observed);
    return Track(observed);
  }

  std::optional<m2s_pose> CurrentPose() const override {
    if (!has_pose_) return std::nullopt;
    return ToWorldFromCamera(pose_);
  }

  std::vector<m2s_map_point> MapPoints() const override {
    std::vector<m2s_map_point> out;
    out.reserve(points_.size());
    for (const auto& [id, p] : points_) {
      out.push_back(
          {id, static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z)});
    }
    return out;
  }

  void Relocalise() override { lost_ = true; }

 private:
  FrameResult Initialize(const std::unordered_map<uint32_t, cv::Point2d>& observed) {
    FrameResult result;  // kNotInitialized
    std::vector<uint32_t> ids;
    std::vector<cv::Point2d> p_ref, p_cur;
    std::vector<double> flow;
    for (const auto& [id, uv] : observed) {
      auto it = reference_.find(id);
      if (it == reference_.end()) continue;
      ids.push_back(id);
      p_ref.push_back(it->second);
      p_cur.push_back(uv);
      flow.push_back(cv::norm(uv - it->second));
    }
    // A reference that shares too little with the view is replaced by the current frame.
    if (static_cast<int>(ids.size()) < config_.init_min_points ||
        ids.size() * 2 < reference_.size()) {
      reference_ = observed;
      return result;
    }
    std::nth_element(flow.begin(), flow.begin() + flow.size() / 2, flow.end());
    if (flow[flow.size() / 2] < config_.init_min_flow_px) return result;

    cv::Mat inlier_mask;
    const cv::Mat E = cv::findEssentialMat(p_ref, p_cur, cv::Mat(K_), cv::RANSAC, 0.999,
                                           config_.ransac_reprojection_px / 2.0, inlier_mask);
    if (E.rows != 3 || E.cols != 3) return result;
    cv::Mat R, t;
    cv::recoverPose(E, p_ref, p_cur, cv::Mat(K_), R, t, inlier_mask);
    CameraPose second;  // current camera from reference camera
    second.R = cv::Matx33d(R);
    second.t = cv::Vec3d(t);
    const CameraPose first;  // the reference camera is the world
    std::vector<std::pair<uint32_t, cv::Point3d>> made;
    for (size_t i = 0; i < ids.size(); ++i) {
      if (!inlier_mask.at<uchar>(static_cast<int>(i))) continue;
      if (auto p = Triangulate(first, p_ref[i], second, p_cur[i])) made.emplace_back(ids[i], *p);
    }
    if (static_cast<int>(made.size()) < config_.init_min_points) return result;
    // Scale: median depth 1 in the reference camera.
    std::vector<double> depths;
    for (const auto& [id, p] : made) depths.push_back(p.z);
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    const double scale = 1.0 / depths[depths.size() / 2];
    for (auto& [id, p] : made) points_[id] = p * scale;
    second.t *= scale;
    // Every other id of both frames waits for parallax from its sighting.
    for (const auto& [id, uv] : reference_) {
      if (!points_.count(id)) sightings_[id] = {uv, first, frame_index_ - 1};
    }
    initialized_ = true;
    SetPose(second, observed);
    result.state = TrackState::kOk;
    result.world_from_camera = ToWorldFromCamera(second);
    result.num_inliers = static_cast<int>(made.size());
    result.keyframe_created = true;
    return result;
  }

  FrameResult Track(const std::unordered_map<uint32_t, cv::Point2d>& observed) {
    FrameResult result;
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    for (const auto& [id, uv] : observed) {
      auto it = points_.find(id);
      if (it == points_.end()) continue;
      object.push_back(it->second);
      image.push_back(uv);
    }
    result.state = TrackState::kLost;
    if (static_cast<int>(object.size()) < config_.min_inliers) return Lost(result);
    cv::Mat rvec, tvec(pose_.t);
    cv::Rodrigues(cv::Mat(pose_.R), rvec);
    std::vector<int> inliers;
    const bool solved = cv::solvePnPRansac(object, image, cv::Mat(K_), cv::noArray(), rvec, tvec,
                                           /*useExtrinsicGuess=*/true, config_.ransac_iterations,
                                           static_cast<float>(config_.ransac_reprojection_px), 0.99,
                                           inliers, cv::SOLVEPNP_ITERATIVE);
    if (!solved || static_cast<int>(inliers.size()) < config_.min_inliers) return Lost(result);
    CameraPose pose;
    cv::Mat R;
    cv::Rodrigues(rvec, R);
    pose.R = cv::Matx33d(R);
    pose.t = cv::Vec3d(tvec);
    result.state = lost_ ? TrackState::kRelocalized : TrackState::kOk;
    lost_ = false;
    result.world_from_camera = ToWorldFromCamera(pose);
    result.num_inliers = static_cast<int>(inliers.size());
    SetPose(pose, observed);
    return result;
  }

  FrameResult Lost(FrameResult result) {
    lost_ = true;
    return result;
  }

  // The frame is tracked at `pose`: new points from the ids first seen earlier, sightings of
  // the new ids, old sightings dropped.
  void SetPose(const CameraPose& pose, const std::unordered_map<uint32_t, cv::Point2d>& observed) {
    pose_ = pose;
    has_pose_ = true;
    for (const auto& [id, uv] : observed) {
      if (points_.count(id)) continue;
      auto it = sightings_.find(id);
      if (it == sightings_.end()) {
        sightings_[id] = {uv, pose, frame_index_};
        continue;
      }
      if (auto p = Triangulate(it->second.pose, it->second.uv, pose, uv)) {
        points_[id] = *p;
        sightings_.erase(it);
      }
    }
    for (auto it = sightings_.begin(); it != sightings_.end();) {
      if (frame_index_ - it->second.frame_index > config_.sighting_max_age_frames) {
        it = sightings_.erase(it);
      } else {
        ++it;
      }
    }
  }

  cv::Vec3d Ray(const CameraPose& pose, const cv::Point2d& uv) const {
    const cv::Vec3d ray_camera((uv.x - camera_.cx) / camera_.fx, (uv.y - camera_.cy) / camera_.fy,
                               1.0);
    return cv::normalize(pose.R.t() * ray_camera);
  }

  double ReprojectionError(const CameraPose& pose, const cv::Point2d& uv,
                           const cv::Vec3d& p) const {
    const cv::Vec3d pc = pose.R * p + pose.t;
    if (pc[2] <= 0) return INFINITY;
    const double u = camera_.fx * pc[0] / pc[2] + camera_.cx;
    const double v = camera_.fy * pc[1] / pc[2] + camera_.cy;
    return std::hypot(u - uv.x, v - uv.y);
  }

  // The midpoint of the two rays, when they differ by min_parallax_deg and the point is in
  // front of both cameras and reprojects well in both.
  std::optional<cv::Point3d> Triangulate(const CameraPose& a, const cv::Point2d& uv_a,
                                         const CameraPose& b, const cv::Point2d& uv_b) const {
    const cv::Vec3d da = Ray(a, uv_a), db = Ray(b, uv_b);
    const double cos_parallax = da.dot(db);
    if (cos_parallax > std::cos(config_.min_parallax_deg * kDegToRad)) return std::nullopt;
    // Closest points ca + s da and cb + u db.
    const cv::Vec3d ca = a.Center(), cb = b.Center(), w = ca - cb;
    const double d = 1.0 - cos_parallax * cos_parallax;
    const double s = (cos_parallax * db.dot(w) - da.dot(w)) / d;
    const double u = (db.dot(w) - cos_parallax * da.dot(w)) / d;
    if (s <= 0 || u <= 0) return std::nullopt;
    const cv::Vec3d p = 0.5 * ((ca + s * da) + (cb + u * db));
    if (ReprojectionError(a, uv_a, p) > config_.ransac_reprojection_px ||
        ReprojectionError(b, uv_b, p) > config_.ransac_reprojection_px) {
      return std::nullopt;
    }
    return cv::Point3d(p[0], p[1], p[2]);
  }

  const m2s_camera camera_;
  const Config config_;
  cv::Matx33d K_;
  int64_t frame_index_ = 0;
  bool initialized_ = false;
  bool lost_ = false;
  bool has_pose_ = false;
  CameraPose pose_;
  std::unordered_map<uint32_t, cv::Point2d> reference_;  // before initialisation
  std::unordered_map<uint32_t, cv::Point3d> points_;
  std::unordered_map<uint32_t, Sighting> sightings_;
};

std::unique_ptr<PnpOdometry> MakePnpOdometry(const m2s_camera& camera,
                                             const std::string& config_json) {
  return std::make_unique<PnpOdometry>(camera, config_json);
}

}  // namespace

M2S_DEFINE_PLUGIN("pnp_odometry",
                  "frame-to-frame PnP odometry (OpenCV calib3d): essential-matrix "
                  "initialisation, PnP RANSAC, two-view triangulation; no BA, no loop closure",
                  MakePnpOdometry)
