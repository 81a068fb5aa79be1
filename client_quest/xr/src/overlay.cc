#include "overlay.h"

#include "m2s/common/alignment.h"

namespace m2s::xr {

KeyframeGroups GroupKeyframes(const std::vector<client::ReplicaKeyframe>& keyframes,
                              bool show_others) {
  KeyframeGroups groups;
  for (const client::ReplicaKeyframe& k : keyframes) {
    if (k.own) {
      groups.own.push_back(k.world_from_camera);
    } else if (show_others) {
      groups.others.push_back(k.world_from_camera);
    }
  }
  return groups;
}

void Overlay::Reset() {
  world_from_slam_.reset();
  map_revision_ = -1;
  points_slam_.clear();
  keyframes_slam_.clear();
  estimate_slam_.reset();
  ground_truth_.reset();
  dirty_ = true;
}

void Overlay::Update(const client::ClientSession& session, bool refresh_alignment, bool visible,
                     bool show_other_keyframes, MapRenderer* renderer) {
  if (show_other_keyframes != show_other_keyframes_) {
    show_other_keyframes_ = show_other_keyframes;
    dirty_ = true;
  }
  const client::MapReplica& replica = session.replica();
  if (replica.revision() != map_revision_ || replica.session_id() != map_session_) {
    const client::MapSnapshot map = replica.Snapshot();
    map_revision_ = map.revision;
    map_session_ = map.session_id;
    points_slam_ = map.points;
    keyframes_slam_ = map.keyframes;
    dirty_ = true;
  }
  if (refresh_alignment) {
    const int64_t session_id = session.session_id();
    std::vector<Eigen::Vector3d> slam_centres, true_centres;
    estimate_slam_.reset();
    for (const client::FrameRecord& r : session.Records()) {
      const bool tracked = r.answered && (r.state == pose_estimate_t::STATE_OK ||
                                          r.state == pose_estimate_t::STATE_RELOCALIZED);
      if (!tracked || r.session_id != session_id || !r.ground_truth_world_from_camera) continue;
      slam_centres.push_back(r.world_from_camera.translation());
      true_centres.push_back(r.ground_truth_world_from_camera->translation());
      estimate_slam_ = r.world_from_camera;
      ground_truth_ = *r.ground_truth_world_from_camera;
    }
    world_from_slam_ = AlignPoints(slam_centres, true_centres, /*with_scale=*/true);
    dirty_ = true;
  }
  if (!dirty_) return;
  dirty_ = false;
  points_.clear();
  keyframes_ = {};
  std::optional<Pose3> estimate;
  if (visible && world_from_slam_) {
    const Sim3& s = *world_from_slam_;
    points_.reserve(points_slam_.size());
    for (const Eigen::Vector3f& p : points_slam_) {
      points_.push_back((s * p.cast<double>()).cast<float>());
    }
    keyframes_ = GroupKeyframes(keyframes_slam_, show_other_keyframes_);
    for (Pose3& k : keyframes_.own) k = s.TransformPose(k);
    for (Pose3& k : keyframes_.others) k = s.TransformPose(k);
    if (estimate_slam_) estimate = s.TransformPose(*estimate_slam_);
  }
  renderer->SetMapPoints(points_);
  renderer->SetKeyframes(keyframes_.own);
  renderer->SetOtherKeyframes(keyframes_.others);
  renderer->SetEstimatedPose(estimate);
  renderer->SetGroundTruthPose(visible ? ground_truth_ : std::nullopt);
}

}  // namespace m2s::xr
