// m2s_slam: the built-in SLAM (slam::System) behind the plug-in interface, the reference a
// plug-in is compared with through the same host path. trajectory() gives the refined
// trajectory (every frame's pose through its keyframe, after bundle adjustment).
//
// Config (JSON object, all optional; defaults are slam::Options'): deterministic (bool: mapping
// inline, bit-identical runs), feature_budget, pixel_sigma, num_ba_threads, max_keyframes,
// drift_correction (bool), mapping_nice. Unknown keys are refused.
#include <stdexcept>
#include <string>

#include <nlohmann/json.hpp>

#include "m2s/plugin/plugin.h"
#include "m2s/slam/system.h"

namespace {

using m2s::plugin::FrameResult;
using m2s::plugin::TrackState;

m2s::slam::Options ParseOptions(const m2s_camera& camera, const std::string& config_json) {
  m2s::slam::Options o;
  o.camera.width = camera.width;
  o.camera.height = camera.height;
  o.camera.fx = camera.fx;
  o.camera.fy = camera.fy;
  o.camera.cx = camera.cx;
  o.camera.cy = camera.cy;
  o.camera.near = camera.near_m;
  o.camera.far = camera.far_m;
  const nlohmann::json j = nlohmann::json::parse(config_json);
  if (!j.is_object()) throw std::invalid_argument("config: not a JSON object");
  for (const auto& [key, value] : j.items()) {
    if (key == "deterministic") {
      o.deterministic = value.get<bool>();
    } else if (key == "feature_budget") {
      o.feature_budget = value.get<int>();
    } else if (key == "pixel_sigma") {
      o.pixel_sigma = value.get<double>();
    } else if (key == "num_ba_threads") {
      o.mapper.num_ba_threads = value.get<int>();
    } else if (key == "max_keyframes") {
      o.mapper.max_keyframes = value.get<int>();
    } else if (key == "drift_correction") {
      o.drift.enabled = value.get<bool>();
    } else if (key == "mapping_nice") {
      o.mapping_nice = value.get<int>();
    } else {
      throw std::invalid_argument("config: unknown key \"" + key + "\"");
    }
  }
  if (m2s::Status valid = o.Check(); !valid) throw std::invalid_argument(valid.message());
  return o;
}

m2s_pose ToC(const m2s::Pose3& p) {
  const Eigen::Quaterniond& q = p.rotation();
  const Eigen::Vector3d& t = p.translation();
  return {{q.w(), q.x(), q.y(), q.z()}, {t.x(), t.y(), t.z()}};
}

class SlamMethod final : public m2s::plugin::Method {
 public:
  static constexpr bool kHasTrajectory = true;

  SlamMethod(const m2s_camera& camera, const std::string& config_json) {
    auto system = m2s::slam::System::Create(ParseOptions(camera, config_json));
    if (!system) throw std::runtime_error(system.error());
    system_ = std::move(*system);
  }

  FrameResult ProcessFrame(const m2s_frame& frame) override {
    m2s::slam::Frame f;
    f.seq = frame.seq;
    f.timestamp = frame.timestamp;
    f.features.resize(frame.num_features);
    for (uint32_t i = 0; i < frame.num_features; ++i) {
      f.features[i].id = frame.features[i].id;
      f.features[i].uv = Eigen::Vector2f(frame.features[i].u, frame.features[i].v);
    }
    const m2s::slam::TrackResult r = system_->Track(f);
    if (r.state == m2s::slam::TrackingState::kRejected) {
      throw std::runtime_error("frame rejected: " + r.reject_reason);
    }
    FrameResult out;
    out.state = static_cast<TrackState>(static_cast<int>(r.state));
    out.world_from_camera = ToC(r.world_from_camera);
    out.num_inliers = r.num_inliers;
    out.keyframe_created = r.keyframe_created;
    if (r.state == m2s::slam::TrackingState::kOk ||
        r.state == m2s::slam::TrackingState::kRelocalized) {
      current_ = out.world_from_camera;
    }
    return out;
  }

  std::optional<m2s_pose> CurrentPose() const override { return current_; }

  std::vector<m2s_map_point> MapPoints() const override {
    const m2s::slam::MapDelta map = system_->FullMap();
    std::vector<m2s_map_point> out(map.point_ids.size());
    for (size_t i = 0; i < out.size(); ++i) {
      const Eigen::Vector3f& p = map.point_positions[i];
      out[i] = {map.point_ids[i], p.x(), p.y(), p.z()};
    }
    return out;
  }

  std::vector<m2s_trajectory_entry> Trajectory() const override {
    std::vector<m2s_trajectory_entry> out;
    for (const m2s::slam::TrajectoryEntry& e : system_->Trajectory()) {
      out.push_back({e.seq, e.timestamp, static_cast<int32_t>(e.state), ToC(e.world_from_camera)});
    }
    return out;
  }

  bool Reset() override {
    system_->Reset();
    current_.reset();
    return true;
  }

 private:
  std::unique_ptr<m2s::slam::System> system_;
  std::optional<m2s_pose> current_;
};

std::unique_ptr<SlamMethod> MakeSlamMethod(const m2s_camera& camera,
                                           const std::string& config_json) {
  return std::make_unique<SlamMethod>(camera, config_json);
}

}  // namespace

M2S_DEFINE_PLUGIN("m2s_slam",
                  "the built-in vertex-feature SLAM (ORB-SLAM2-style, local BA, drift "
                  "correction) behind the plug-in interface",
                  MakeSlamMethod)
