// The overlay state of the XR client: what MapRenderer draws besides the mesh, in world
// coordinates. The SLAM map lives in its own frame (first keyframe, median depth 1); the
// Sim3 from that frame to the world is estimated from the camera centres of tracked frames
// against the true head poses (Umeyama), refreshed every few frames.
//
// Keyframes are drawn in two colours: this agent's, and those other agents of its map group
// made (ReplicaKeyframe::own false), which can be hidden.
//
// Thread-safety: render thread only.
#pragma once

#include <optional>
#include <vector>

#include "m2s/client/client_session.h"
#include "m2s/common/geometry.h"
#include "m2s/render/map_renderer.h"

namespace m2s::xr {

// The keyframes the overlay draws, by colour: `own` in MapRendererOptions::keyframe_color,
// `others` in other_keyframe_color.
struct KeyframeGroups {
  std::vector<Pose3> own;
  std::vector<Pose3> others;
};
// Splits keyframes by the agent that made them; other agents' are left out unless shown.
KeyframeGroups GroupKeyframes(const std::vector<client::ReplicaKeyframe>& keyframes,
                              bool show_others);

class Overlay {
 public:
  // Refreshes the alignment from the session's records (every call) and the map from its
  // replica (when the revision changed); then hands everything to the renderer.
  void Update(const client::ClientSession& session, bool refresh_alignment, bool visible,
              bool show_other_keyframes, MapRenderer* renderer);
  // Forgets the map and the alignment (a new SLAM session).
  void Reset();
  bool aligned() const { return world_from_slam_.has_value(); }
  size_t num_points() const { return points_.size(); }

 private:
  std::optional<Sim3> world_from_slam_;
  int64_t map_revision_ = -1;
  int64_t map_session_ = 0;
  std::vector<Eigen::Vector3f> points_slam_;
  std::vector<client::ReplicaKeyframe> keyframes_slam_;
  bool show_other_keyframes_ = true;
  std::vector<Eigen::Vector3f> points_;
  KeyframeGroups keyframes_;
  std::optional<Pose3> estimate_slam_, ground_truth_;
  bool dirty_ = true;
};

}  // namespace m2s::xr
