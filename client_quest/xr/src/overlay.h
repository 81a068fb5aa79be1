// The overlay state of the XR client: what MapRenderer draws besides the mesh, in world
// coordinates. The SLAM map lives in its own frame (first keyframe, median depth 1); the
// Sim3 from that frame to the world is estimated from the camera centres of tracked frames
// against the true head poses (Umeyama), refreshed every few frames.
//
// Thread-safety: render thread only.
#pragma once

#include <optional>
#include <vector>

#include "m2s/client/client_session.h"
#include "m2s/common/geometry.h"
#include "m2s/render/map_renderer.h"

namespace m2s::xr {

class Overlay {
 public:
  // Refreshes the alignment from the session's records (every call) and the map from its
  // replica (when the revision changed); then hands everything to the renderer.
  void Update(const client::ClientSession& session, bool refresh_alignment, bool visible,
              MapRenderer* renderer);
  // Forgets the map and the alignment (a new SLAM session).
  void Reset();
  bool aligned() const { return world_from_slam_.has_value(); }
  size_t num_points() const { return points_.size(); }

 private:
  std::optional<Sim3> world_from_slam_;
  int64_t map_revision_ = -1;
  int64_t map_session_ = 0;
  std::vector<Eigen::Vector3f> points_slam_;
  std::vector<Pose3> keyframes_slam_;
  std::vector<Eigen::Vector3f> points_;
  std::vector<Pose3> keyframes_;
  std::optional<Pose3> estimate_slam_, ground_truth_;
  bool dirty_ = true;
};

}  // namespace m2s::xr
