// Tracking through pure camera rotation. A monocular map cannot grow while the camera turns
// about a fixed centre (a head looking around while standing still): new features have no
// parallax and are never triangulated, so the map points in view run out although the view
// is full of vertices. The rotation is still observable: every feature a keyframe shares with
// the frame (by vertex id) gives a pair of bearings, and under the hypothesis that the centre
// did not move since the keyframe, the frame's pose is the keyframe's centre with the rotation
// that maps the keyframe's bearings onto the frame's (Wahba's problem, closed form by SVD).
// A frame that moved is refused: its bearings only fit a rotation within the pixel bound when
// the translation is below what the measurements can see.
//
// Thread-safety: pure functions.
//
//   std::optional<RotationOnlyPose> r = SolveRotationOnly(camera, 2.45, keyframe_pose,
//                                                         kf_ids, kf_uvs, features);
//   if (r && r->inliers >= needed) pose = r->camera_from_world;
#pragma once

#include <optional>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/types.h"
#include "tracking/frame_validation.h"

namespace m2s::slam {

struct RotationOnlyPose {
  Pose3 camera_from_world;  // centre at the keyframe's, rotation fitted
  int shared = 0;           // features the keyframe and the frame share by id
  int inliers = 0;          // shared features within the pixel bound at that pose
};

// The pose of `features` at the keyframe's camera centre, rotated to fit the features the
// keyframe (`keyframe_ids`, sorted, with `keyframe_uvs`) shares with the frame: a
// deterministic two-bearing RANSAC, then a least-squares refit on the inliers (reprojection
// error at most `max_error_px`). nullopt when fewer than 3 features are shared.
std::optional<RotationOnlyPose> SolveRotationOnly(const Camera& camera, double max_error_px,
                                                  const Pose3& keyframe_world_from_camera,
                                                  const std::vector<VertexId>& keyframe_ids,
                                                  const std::vector<Eigen::Vector2d>& keyframe_uvs,
                                                  const SortedFeatures& features);

// The pose of a camera at `centre` whose rotation best maps the directions from there to
// `points_world` onto the bearings of their projections `uvs` (the same closed form). At least
// 2 points not on one ray; nullopt otherwise.
std::optional<Pose3> PoseAtCentre(const Camera& camera, const Eigen::Vector3d& centre,
                                  const std::vector<Eigen::Vector3d>& points_world,
                                  const std::vector<Eigen::Vector2d>& uvs);

}  // namespace m2s::slam
