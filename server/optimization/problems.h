// Optimisation problems of the SLAM back-end, on plain data (no map types), so they are
// testable alone and callable from any thread. Implemented on Ceres (server/optimization/*.cc).
//
// Conventions: poses are camera_from_world here (the form the reprojection residual wants);
// callers convert from world_from_camera. Pixel observations follow camera.h.
//
//   PoseOnlyResult r = OptimizePose(camera, options, points_world, observations_uv, &pose);
//   BundleAdjustmentResult b = BundleAdjust(camera, ba_options, &problem);
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/numeric.h"
#include "m2s/common/types.h"

namespace m2s::slam {

// ---------- Pose-only optimisation (tracking) ----------
struct PoseOnlyOptions {
  double huber_delta_px = 2.0;            // robust loss scale (pixels)
  double chi2_threshold = kChi2TwoDof95;  // on residual^2 / sigma^2
  double pixel_sigma = 1.0;               // assumed feature noise (pixels)
  int rounds = 4;                         // optimise / classify outliers rounds (ORB-SLAM2 style)
  int max_iterations_per_round = 10;
  // false: hand-written Levenberg-Marquardt on the 6-dof pose with analytic Jacobians (fast,
  // no allocation per iteration); true: the same problem on Ceres (reference, ~10x slower).
  bool use_ceres = false;

  Status Check() const;
};

struct PoseOnlyResult {
  bool converged = false;
  int num_inliers = 0;
  std::vector<bool> inlier;    // parallel to the input observations
  double final_rmse_px = 0.0;  // over inliers
};

// Refines camera_from_world from 3-D points (world) and their pixel observations.
PoseOnlyResult OptimizePose(const Camera& camera, const PoseOnlyOptions& options,
                            const std::vector<Eigen::Vector3d>& points_world,
                            const std::vector<Eigen::Vector2d>& observations_uv,
                            Pose3* camera_from_world);

// ---------- Bundle adjustment (initialisation, local and global BA) ----------
struct BaKeyframe {
  KeyframeId id = 0;
  Pose3 camera_from_world;  // in/out
  bool fixed = false;
};
struct BaPoint {
  VertexId id = 0;
  Eigen::Vector3d position_world = Eigen::Vector3d::Zero();  // in/out
  bool fixed = false;
};
struct BaObservation {
  int keyframe_index = 0;  // index into BaProblem::keyframes
  int point_index = 0;     // index into BaProblem::points
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();
};
struct BaProblem {
  std::vector<BaKeyframe> keyframes;
  std::vector<BaPoint> points;
  std::vector<BaObservation> observations;
};

struct BundleAdjustmentOptions {
  double huber_delta_px = 2.0;
  double chi2_threshold = kChi2TwoDof95;
  double pixel_sigma = 1.0;
  int max_iterations = 20;
  int num_threads = 1;
  // After the first solve, drop chi-square outliers and solve again (ORB-SLAM2's two passes).
  bool second_pass_without_outliers = true;
  // With no fixed keyframe, the first one is held fixed to remove the gauge freedom.
  Status Check() const;
};

struct BundleAdjustmentResult {
  bool success = false;
  double initial_rmse_px = 0.0;
  double final_rmse_px = 0.0;
  int iterations = 0;
  std::vector<bool> outlier;  // parallel to BaProblem::observations, after the last pass
  double solve_ms = 0.0;
};

// Schur-based (SPARSE_SCHUR / DENSE_SCHUR) BA with a robust loss; poses on an SE3 manifold.
BundleAdjustmentResult BundleAdjust(const Camera& camera, const BundleAdjustmentOptions& options,
                                    BaProblem* problem);

// ---------- Sim3 pose graph (drift correction) ----------
struct PoseGraphNode {
  KeyframeId id = 0;
  Sim3 world_from_camera;  // in/out (scale 1 on input for SE3 keyframe poses)
  bool fixed = false;
};
struct PoseGraphEdge {
  int from_index = 0;  // indices into nodes
  int to_index = 0;
  Sim3 from_from_to;  // measured relative transform: from_node^-1 * to_node
  double weight = 1.0;
};
struct PoseGraphOptions {
  int max_iterations = 50;
  Status Check() const;
};
struct PoseGraphResult {
  bool success = false;
  double initial_cost = 0.0;
  double final_cost = 0.0;
};

// Optimises Sim3 keyframe poses so relative transforms match the edges (loop edges included).
PoseGraphResult OptimizePoseGraph(const PoseGraphOptions& options,
                                  std::vector<PoseGraphNode>* nodes,
                                  const std::vector<PoseGraphEdge>& edges);

// ---------- Trajectory with a motion prior (end-of-session refinement) ----------
// A sequence of camera poses, each observing fixed map points, smoothed jointly: every pose
// fits its observations (robust, whitened by pixel_sigma) and the camera's centre, between
// three consecutive frames at most max_gap_s apart, accelerates by acceleration_sigma (the
// points' units per s^2, per axis, robust beyond the chi-square bound with 3 degrees of
// freedom) at 1 sigma. The prior's second difference at frame interval dt is
// acceleration_sigma * dt^2 (30 fps, 5: 0.0056 units), so it moves frames whose observations
// fix their centre worse than that
// and leaves well-determined ones where they are.
struct TrajectoryFrame {
  double t = 0.0;                             // seconds, increasing along the sequence
  Pose3 camera_from_world;                    // in/out
  std::vector<Eigen::Vector3d> points_world;  // held fixed
  std::vector<Eigen::Vector2d> observations_uv;
  bool fixed = false;  // held where it is (needs no observations): an anchor for the prior
};
struct TrajectoryOptions {
  double pixel_sigma = 1.0;
  double acceleration_sigma = 5.0;
  double max_gap_s = 0.1;
  int max_iterations = 20;
  Status Check() const;
};
struct TrajectoryResult {
  bool success = false;
  int priors = 0;  // acceleration terms (triples of consecutive frames)
  double initial_cost = 0.0;
  double final_cost = 0.0;
};

// Optimises every frame's camera_from_world under the observations and the motion prior.
// A frame neither fixed nor observing a point, or times out of order: success false, nothing
// changed.
TrajectoryResult OptimizeTrajectory(const Camera& camera, const TrajectoryOptions& options,
                                    std::vector<TrajectoryFrame>* frames);

// Closed-form point-set alignment (Umeyama) is m2s::AlignPoints in common/alignment.h.

}  // namespace m2s::slam
