// Monocular initialisation from two frames with enough parallax (ORB-SLAM2's scheme on
// OpenCV solvers): essential matrix and homography by RANSAC, model selection by score ratio
// (planar scenes pick the homography), triangulation of the candidate motions with cheirality,
// reprojection and parallax checks, a unique best motion required, then a full bundle
// adjustment of the two views and the scale fixed by median depth 1 in the first camera.
// Pure rotation or too little parallax: no map (keep waiting, never a broken map). The views
// must also determine the motion, not merely fit it (docs/design/two_view_initialisation.md):
// the chosen motion must explain nearly all shared features (association is by id); no distinct
// motion of the other model may fit about as well (a plane's twin), nor, for a loosely determined
// rotation, a motion of two other estimators (a valley of motions); and the motion's standard
// deviations for pixel_sigma noise (TwoViewMotionUncertainty) must be within
// InitializerOptions' bounds, before and after the bundle adjustment. Bunched or distant points
// fail that with exact data too (TwoViewRefusal::Kind::kWeakGeometry), and the initialiser
// waits for more baseline.
// Views that keep refusing for weak geometry (InitializerOptions::more_views_after_s) are
// given to more views: kept frames between the two decide among the motions the refusal
// proposes, the motion gated over every view (FromMoreViews).
// Once the map exists, the frames between its two views are solved on it too (InitialMap::
// inbetween): they get poses instead of staying without one.
// A refused attempt costs milliseconds (two RANSACs): after one, the next attempt waits until the
// parallax, growing with the time since the reference frame, should be near the bound (at most
// kMaxInitRetryDelayS later), so waiting frames stay cheap.
//
// OpenCV's solvers run behind one boundary: an exception they throw (degenerate input) is a
// refused attempt with the reason, never an exception out of the initialiser.
//
// Not thread-safe (one per tracking thread).
//
//   Initializer init(options.measurement(), options.initializer, options.mapper.num_ba_threads);
//   if (auto map = init.Process(seq, timestamp, features)) { /* two keyframes + points */ }
#pragma once

#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "m2s/slam/system.h"
#include "tracking/frame_validation.h"
#include "tracking/two_view.h"

namespace m2s::slam {

struct InitialFrame {
  int64_t seq = 0;
  double timestamp = 0.0;
  SortedFeatures features;
  Pose3 world_from_camera;
};

// A frame between the two views of an initial map, solved on the initial map: the features
// whose ids are map points and whose pose the solve explains.
struct InitialInbetween {
  int64_t seq = 0;
  Pose3 world_from_camera;
  std::vector<VertexId> observed_ids;
  std::vector<Eigen::Vector2d> observed_uvs;
};

struct InitialMap {
  InitialFrame first;  // world_from_camera = identity
  InitialFrame second;
  std::vector<VertexId> point_ids;
  std::vector<Eigen::Vector3d> points;  // world; median depth in the first camera is 1
  bool used_homography = false;
  // The frames between first and second that the initial map explains (pose-only solve from
  // the pose interpolated in time, converged with tracking's sparse-view rule), in order.
  // Frames it does not explain are left out.
  std::vector<InitialInbetween> inbetween;
  // With Initializer::DeferInbetween, those frames still to solve instead (InbetweenSolver), in
  // order; `inbetween` is then empty.
  std::vector<InitialFrame> unsolved;
};

// Solves the frames between an initial map's two views on its points, one at a time
// (InitialMap::inbetween): each pose-only from the pose interpolated in time between the two
// views, on at least InitializerOptions::min_points of the map's points (a view of a few points
// at its edge, turning from a bare wall, fits a wrong pose under noise), kept when tracking's
// sparse-view rule holds. Holds copies of what it needs: the map may go.
//
//   InbetweenSolver solver(model, options.min_points, map, std::move(map.unsolved));
//   while (!solver.done()) if (auto f = solver.SolveNext()) { /* f->seq has a pose */ }
class InbetweenSolver {
 public:
  InbetweenSolver(const MeasurementModel& model, int min_points, const InitialMap& map,
                  std::vector<InitialFrame> frames);
  bool done() const { return next_ == frames_.size(); }
  size_t size() const { return frames_.size(); }
  // Solves the next frame: nullopt when the map's points do not determine its pose.
  std::optional<InitialInbetween> SolveNext();

 private:
  MeasurementModel model_;
  int min_points_;
  std::unordered_map<VertexId, size_t> point_index_;
  std::vector<Eigen::Vector3d> points_;
  double first_time_ = 0.0, span_ = 0.0;
  Pose3 world_from_first_, world_from_second_;
  std::vector<InitialFrame> frames_;
  size_t next_ = 0;
};

class Initializer {
 public:
  // `num_ba_threads`: threads of the two-view bundle adjustment.
  Initializer(const MeasurementModel& model, const InitializerOptions& options, int num_ba_threads)
      : model_(model), options_(options), num_ba_threads_(num_ba_threads) {}

  // Feeds one valid frame. Returns the initial map once two frames (the reference and this
  // one) reconstruct; otherwise nullopt (last_failure() says why).
  std::optional<InitialMap> Process(int64_t seq, double timestamp, const SortedFeatures& features);
  void Reset() {
    reference_.reset(), frames_since_reference_ = 0, next_attempt_time_.reset();
    kept_frames_.clear();
    second_opinion_refusals_ = 0;
    refused_since_.reset();
  }
  // Starts over from frames seen before those Process() gets, in capture order, without an
  // attempt (the lost frames before a new map starts): one of them becomes the reference
  // (SeedReference); the others, before it too, are solved once a map exists, as the frames
  // Process() keeps are. Without a frame of min_points features, the same as Reset().
  enum class SeedReference {
    kEarliestFull,  // the earliest with 80 % of the most features: the most parallax
    kLatest,        // the last with min_points features: the freshest view
  };
  void Seed(const std::vector<InitialFrame>& frames, SeedReference which);
  const std::string& last_failure() const { return last_failure_; }
  // With `defer`, a map leaves its kept frames unsolved (InitialMap::unsolved) for the caller
  // to solve when it has time (a real-time system: the solves of a few dozen frames took most
  // of the initialisation's time). Default: solved before Process() returns.
  void DeferInbetween(bool defer) { defer_inbetween_ = defer; }
  // The reference frame's seq, when one is held.
  std::optional<int64_t> reference_seq() const {
    return reference_ ? std::optional<int64_t>(reference_->seq) : std::nullopt;
  }

 private:
  MeasurementModel model_;
  InitializerOptions options_;
  int num_ba_threads_;
  // The initial map from more views than two, when the two views fit several motions (a
  // plane's twins) or leave the motion undetermined (`refused` says which): kept frames between
  // the reference and this frame (`timestamp`, `features`) are posed on the two views'
  // adjustment from each of `starts` and every view adjusted together; the lowest minimum,
  // distinct from the others, and its motion determined by every view
  // (MultiViewMotionUncertainty within InitializerOptions' bounds), makes the map. nullopt
  // otherwise.
  std::optional<InitialMap> FromMoreViews(int64_t seq, double timestamp,
                                          const SortedFeatures& features,
                                          const std::vector<Pose3>& starts,
                                          const std::string& refused);
  // Whether FromMoreViews may be asked at capture time `timestamp`
  // (InitializerOptions::more_views_after_s).
  bool MoreViewsDue(double timestamp) const;
  // The initial map of the reference and this frame from the motion and points (camera 0,
  // any scale): scaled to median depth 1, the kept frames solved on it (or left to the caller:
  // DeferInbetween); logs `how`, resets.
  InitialMap Complete(int64_t seq, double timestamp, const SortedFeatures& features,
                      const Pose3& camera1_from_world, std::vector<VertexId> ids,
                      std::vector<Eigen::Vector3d> points, bool used_homography,
                      const std::string& how);
  void KeepFrame(int64_t seq, double timestamp, const SortedFeatures& features);

  std::optional<InitialFrame> reference_;
  int frames_since_reference_ = 0;
  // The frames after the reference, and the seeded ones before it (at most max_reference_age
  // + 1 in all): solved once a map exists.
  std::vector<InitialFrame> kept_frames_;
  std::optional<double> next_attempt_time_;  // no full attempt before this capture time
  int second_opinion_refusals_ = 0;          // since the last map or Reset
  std::optional<double> refused_since_;      // the first refused attempt's capture time, since
                                             // the last map or Reset
  std::string last_failure_;
  bool defer_inbetween_ = false;
};

}  // namespace m2s::slam
