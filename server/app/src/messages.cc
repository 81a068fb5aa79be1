#include "m2s/server_app/messages.h"

#include <cmath>

namespace m2s::server_app {

slam::Frame ToSlamFrame(const wire::FeatureFrame& frame) {
  slam::Frame out;
  out.seq = frame.seq;
  out.timestamp = static_cast<double>(frame.capture_time_us) * 1e-6;
  out.features = frame.features;
  out.ground_truth_world_from_camera = frame.ground_truth_world_from_camera;
  return out;
}

int8_t ToWireState(slam::TrackingState state) {
  switch (state) {
    case slam::TrackingState::kNotInitialized:
      return pose_estimate_t::STATE_NOT_INITIALIZED;
    case slam::TrackingState::kOk:
      return pose_estimate_t::STATE_OK;
    case slam::TrackingState::kLost:
      return pose_estimate_t::STATE_LOST;
    case slam::TrackingState::kRelocalized:
      return pose_estimate_t::STATE_RELOCALIZED;
    case slam::TrackingState::kRejected:
      return pose_estimate_t::STATE_REJECTED;
  }
  return pose_estimate_t::STATE_REJECTED;
}

pose_estimate_t ToPoseMessage(const slam::TrackResult& result, const wire::FeatureFrame& frame,
                              int64_t server_instance, int64_t map_revision) {
  pose_estimate_t m;
  m.version = pose_estimate_t::VERSION;
  m.session_id = frame.session_id;
  m.server_instance = server_instance;
  m.seq = frame.seq;
  m.capture_time_us = frame.capture_time_us;
  m.frame_send_wall_us = frame.send_wall_us;
  m.state = ToWireState(result.state);
  const bool has_pose = (result.state == slam::TrackingState::kOk ||
                         result.state == slam::TrackingState::kRelocalized) &&
                        result.world_from_camera.AllFinite();
  m.world_from_camera = wire::ToMessage(has_pose ? result.world_from_camera : Pose3());
  m.num_features = result.num_features;
  m.num_inliers = result.num_inliers;
  m.keyframe_created = result.keyframe_created;
  m.tracking_ms = static_cast<float>(result.tracking_ms);
  m.map_revision = map_revision;
  m.map_id = result.map_id;
  return m;
}

map_delta_t ToMapMessage(const slam::MapDelta& delta, int64_t session_id, int64_t server_instance,
                         int64_t base_revision, int64_t revision) {
  map_delta_t m;
  m.version = map_delta_t::VERSION;
  m.session_id = session_id;
  m.server_instance = server_instance;
  m.base_revision = base_revision;
  m.revision = revision;
  m.full = delta.full;
  m.keyframes.reserve(delta.keyframes.size());
  for (const slam::KeyframeState& kf : delta.keyframes) {
    if (!kf.world_from_camera.AllFinite()) continue;
    keyframe_t k;
    k.id = static_cast<int32_t>(kf.id);
    k.capture_time_us = std::llround(kf.timestamp * 1e6);
    k.world_from_camera = wire::ToMessage(kf.world_from_camera);
    k.own = kf.own;
    m.keyframes.push_back(k);
  }
  m.num_keyframes = static_cast<int32_t>(m.keyframes.size());
  m.removed_keyframes.assign(delta.removed_keyframes.begin(), delta.removed_keyframes.end());
  m.num_removed_keyframes = static_cast<int32_t>(m.removed_keyframes.size());
  const size_t n = std::min(delta.point_ids.size(), delta.point_positions.size());
  m.point_ids.reserve(n);
  m.point_xyz.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f& p = delta.point_positions[i];
    if (!p.allFinite()) continue;
    m.point_ids.push_back(static_cast<int32_t>(delta.point_ids[i]));
    m.point_xyz.push_back({p.x(), p.y(), p.z()});
  }
  m.num_points = static_cast<int32_t>(m.point_ids.size());
  m.removed_points.assign(delta.removed_points.begin(), delta.removed_points.end());
  m.num_removed_points = static_cast<int32_t>(m.removed_points.size());
  return m;
}

session_control_t MakeSessionMessage(int8_t type, int64_t session_id, int64_t server_instance) {
  session_control_t m{};
  m.version = session_control_t::VERSION;
  m.type = type;
  m.session_id = session_id;
  m.server_instance = server_instance;
  m.wall_us = wire::WallClockMicros();
  m.last_revision = 0;
  m.camera = wire::ToMessage(Camera());
  m.flags = 0;
  return m;
}

}  // namespace m2s::server_app
