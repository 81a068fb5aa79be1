// Frame-to-map tracking after initialisation: constant-velocity prediction, association to
// map points by vertex id (exact), pose-only optimisation with outlier rejection, the tracking
// state machine (ok / lost / relocalised: PnP + RANSAC against every map point seen, accepted
// only when most associated points agree with the pose), and the keyframe decision. With
// TrackerOptions::min_constrained_points, poses are solved on the well-constrained map points
// (MapPoint::constrained) when there are enough; every associated point is classified, so a poorly
// constrained one that fits still becomes an observation of the next keyframe and gains its
// baseline. When too few map points remain in view and the camera has only turned since the
// reference keyframe (a head looking around while standing still: new features have no parallax, so
// the map cannot grow), the pose's rotation is fitted to the bearings the frame shares with the
// keyframe by id (tracking/rotation_only.h) and its centre is the last measured one, or that one
// carried on at the measured velocity where the few map points in view say so.
//
// Relocalisation's PnP runs behind an OpenCV boundary: an exception OpenCV throws (degenerate
// input) is a failed relocalisation, and the frame is lost; Track() never throws it.
//
// Thread-safety: one tracker per tracking thread; it only reads the map (and reserves keyframe
// ids), so it runs concurrently with mapping.
//
//   Tracker tracker(options.measurement(), options.tracker, options.drift, &map);
//   tracker.Start(initial_map_keyframe, ...);
//   TrackerOutput out = tracker.Track(seq, timestamp, features, /*mapping_busy=*/false);
#pragma once

#include <deque>
#include <optional>
#include <unordered_map>
#include <vector>

#include "m2s/slam/system.h"
#include "map/map.h"
#include "optimization/problems.h"
#include "tracking/frame_validation.h"

namespace m2s::slam {

// A new keyframe, as tracking hands it to mapping.
struct KeyframeCandidate {
  KeyframeId id = 0;
  int64_t seq = 0;
  double timestamp = 0.0;
  Pose3 world_from_camera;
  SortedFeatures features;
  std::vector<VertexId> tracked_points;  // map points that were pose inliers
  std::vector<VertexId> dormant_points;  // map points re-observed after a long gap
  // Map points that were pose outliers in every one of the last kMovedPointFrames tracked
  // frames: their vertex moved (a part of the scene moved), so the mapper maps them anew.
  std::vector<VertexId> moved_points;
  // Map::correction().epoch the pose is expressed in (a drift correction published while the
  // candidate waits in the mapping queue moves the world under it).
  uint64_t correction_epoch = 0;
};

struct TrackerOutput {
  TrackingState state = TrackingState::kLost;
  Pose3 world_from_camera;
  int num_inliers = 0;
  // The keyframe the pose is relative to, for trajectory refinement (absent when none).
  std::optional<KeyframeId> reference_keyframe;
  Pose3 reference_from_camera;
  // The map points the pose was solved on (an even subset of at most TrackerOptions::max_points
  // of the associated ones; empty for a rotation-only pose, and unless SetReportObservations):
  // what re-solving the frame against a refined map needs.
  std::vector<VertexId> observed_ids;
  std::vector<Eigen::Vector2d> observed_uvs;
  std::optional<KeyframeCandidate> keyframe;
};

// Pose-only optimisation from a motion prior, guarded by the inlier count. Badly
// triangulated points (or points mapped from a keyframe whose pose was off) can pull the
// first robust round off a good prior, and the chi-square classification then locks the wrong
// inliers in: the result has fewer inliers than the prior had. Then the solve is repeated with
// more classification rounds, and once more on the prior's own inliers, and the candidate with
// the most inliers (over all the given points) wins. Returns that count and writes the pose;
// -1 when no candidate is finite.
int SolvePoseFromPrior(const Camera& camera, const PoseOnlyOptions& options,
                       const std::vector<Eigen::Vector3d>& points_world,
                       const std::vector<Eigen::Vector2d>& uvs,
                       const Pose3& prior_camera_from_world, Pose3* camera_from_world);

class Tracker {
 public:
  // `drift`: which re-observed points are dormant (min_keyframe_gap) and when they make a
  // keyframe for the drift check (enabled, min_points).
  Tracker(const MeasurementModel& model, const TrackerOptions& options, const DriftOptions& drift,
          Map* map);

  // Starts tracking after initialisation from the newest keyframe.
  void Start(KeyframeId keyframe, const Pose3& world_from_camera, int num_points, double timestamp,
             double median_depth);
  // Starts in the lost state (after loading a map): the next frame relocalises.
  void StartLost();
  void Reset();
  // Localisation only: never proposes keyframes.
  void SetLocalizationOnly(bool on) { localization_only_ = on; }
  // Fill TrackerOutput::observed_ids/uvs (off: a caller that keeps no frame observations
  // spends nothing on them).
  void SetReportObservations(bool on) { report_observations_ = on; }

  TrackerOutput Track(int64_t seq, double timestamp, const SortedFeatures& features,
                      bool mapping_busy);

  bool started() const { return started_; }
  // Map::correction().epoch of the world the last returned pose is expressed in.
  uint64_t correction_epoch() const { return correction_epoch_; }
  bool lost() const { return lost_; }

 private:
  struct Association {
    std::vector<VertexId> ids;
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> uvs;
    std::vector<bool> dormant;
    int num_dormant = 0;
    std::vector<bool> constrained;    // MapPoint::constrained
    std::vector<double> uncertainty;  // MapPoint::uncertainty (negative: not known)
    int num_new_triangulable = 0;     // unmapped features already seen by a keyframe
    std::optional<Pose3> reference_pose;
    int reference_points = -1;
  };
  void Associate(const SortedFeatures& features, Association* a) const;
  // The associated points a pose is solved on (indices into `a`): the well-constrained ones
  // when there are at least TrackerOptions::min_constrained_points (> 0) of them, else all;
  // dormant ones left out when `skip_dormant`.
  std::vector<size_t> PoseSolvingPoints(const Association& a, bool skip_dormant) const;
  bool TrackWithModel(const Association& a, Pose3* camera_from_world, std::vector<bool>* inlier);
  bool Relocalise(const Association& a, Pose3* camera_from_world, std::vector<bool>* inlier);
  // Pure rotation since the reference keyframe (tracking/rotation_only.h), tried when the map
  // points in view are too few. The rotation is fitted as if the camera had kept the
  // keyframe's centre, so it is refused once the camera may be further from it than
  // kRotationOnlyMaxShift of the keyframe's median depth (the last measured centre's distance
  // from it, plus the last measured speed times the time since). The pose's centre is the
  // last measured one (a head turning in place) or that one moved on at the last measured
  // velocity (a drone yawing in flight), whichever the map points in view fit better; without
  // any, the last measured one. Sets `*keyframe` when the frame shares less than half of the
  // keyframe's features.
  bool TrackRotationOnly(double timestamp, const SortedFeatures& features, const Association& a,
                         Pose3* camera_from_world, std::vector<bool>* inlier, bool* keyframe);
  // Adds a measured camera centre and updates measured_velocity_.
  void RecordMeasuredCentre(double timestamp, const Eigen::Vector3d& centre);
  // Whether the inliers determine the pose's centre (its standard deviation for pixel_sigma
  // noise within kMaxCentreSigmaFraction of their median depth; tracker_internal.h).
  bool PoseDetermined(const Association& a, const std::vector<bool>& inlier,
                      const Pose3& camera_from_world) const;
  // Inliers a pose classified on `num_points` associated points needs:
  // TrackerOptions::min_inliers, or in a sparse view (fewer points) 75 % of them and at least
  // `floor` (tracker_internal.h says which floor serves which pose).
  int RequiredInliers(int num_points, int floor) const;
  // Marks the points reprojecting within the chi-square bound; returns their number.
  int Classify(const Association& a, const Pose3& camera_from_world, bool skip_dormant,
               std::vector<bool>* inlier) const;
  // Sum over the recent (not dormant) points of the squared reprojection error in units of
  // pixel_sigma^2, each capped at the 2-dof chi-square bound; counts those under it.
  double RecentPointsCost(const Association& a, const Pose3& camera_from_world,
                          int* num_inliers) const;
  bool NeedKeyframe(const Association& a, int num_inliers, const Pose3& world_from_camera,
                    double timestamp, bool loop_candidate) const;

  MeasurementModel model_;
  TrackerOptions options_;
  DriftOptions drift_;
  Map* map_;
  bool localization_only_ = false;
  bool report_observations_ = false;
  bool started_ = false;
  bool lost_ = false;
  Pose3 last_camera_from_world_;
  Pose3 velocity_;  // camera_from_world(t) * camera_from_world(t-1)^-1
  uint64_t correction_epoch_ = 0;
  // Reference keyframe: the newest one created by this tracker (or loaded).
  std::optional<KeyframeId> reference_kf_;
  Pose3 reference_world_from_camera_;
  int reference_points_ = 0;
  double last_keyframe_time_ = 0.0;
  double last_keyframe_median_depth_ = 1.0;
  // Camera centres of the last consecutive frames measured from map points (not
  // rotation-only), over kSpeedWindowS: their displacement gives the speed rotation-only
  // tracking is judged by (over one frame, pose noise would pass for motion).
  struct MeasuredCentre {
    double timestamp;
    Eigen::Vector3d centre;
  };
  std::deque<MeasuredCentre> measured_;
  Eigen::Vector3d measured_velocity_ = Eigen::Vector3d::Zero();  // m/s, 0 while not known
  bool measured_gap_ = false;  // rotation-only frames since the last measured one
  // The reference keyframe's features, for rotation-only tracking while it waits for mapping.
  SortedFeatures reference_features_;
  // Consecutive tracked frames in which each associated map point was a pose outlier.
  std::unordered_map<VertexId, int> outlier_streak_;
};

}  // namespace m2s::slam
