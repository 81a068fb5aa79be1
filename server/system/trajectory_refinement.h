// The end-of-session refinement of a session's trajectory records on its refined map
// (System::RefineMap, docs/design/map_refinement.md): tracked frames re-solved, frames without
// a pose solved where the map determines them, loosely determined frames smoothed between the
// well-determined ones around them, and frames whose points fix only their rotation given the
// centre interpolated between those, and then every frame smoothed under a prior on the
// camera's acceleration.
//
//   RefineFramePose(model, map, &record, &previous);            // each tracked frame
//   SolveUnposedFrames(model, map, map_id, kUnposedMinPoints, &records);
//   SmoothedFrames s = SmoothLooseFrames(model, map, map_id, max_points, &records);
//   ApplyMotionPrior(model, map, map_id, max_points, acceleration_sigma, &records);
//
// Pure functions on the records and the map; the caller holds the map's lock.
#pragma once

#include <vector>

#include "m2s/slam/options.h"
#include "map/map_data.h"
#include "system/system_common.h"

namespace m2s::slam {

// SmoothLooseFrames: a frame is loosely determined when its centre's standard deviation is
// above kLooseCentreSigmaFraction of its points' median depth (the worst frames of the
// scene-diversity runs are all above it, docs/design/dense_objects.md), unless its squared
// reprojection errors average below kExactDataVarianceFactor of the model's (2 per point, 6
// for the pose: exact data, whose points' centre stands). Anchors at most
// kSmoothingConsecutiveS apart count as consecutive; a frame is smoothed from anchors at most
// kSmoothingMaxSpanS from it, with the deviation of at least kSmoothingMinSamples anchors
// within kSmoothingWindowS of it.
constexpr double kLooseCentreSigmaFraction = 0.01;
constexpr double kExactDataVarianceFactor = 0.01;
constexpr double kSmoothingConsecutiveS = 0.1;
constexpr double kSmoothingMaxSpanS = 1.0;
constexpr double kSmoothingWindowS = 1.0;
constexpr int kSmoothingMinSamples = 5;
// System::RefineMap: iterations of the global bundle adjustment over every keyframe and point.
constexpr int kFinalBaIterations = 20;
// RefineMap: the map points a frame without a pose is solved on, at least. SmoothLooseFrames
// gives a frame without a pose whose points fix its rotation but not its centre (at least
// tracking's kMinRotationOnlyInliers of them) the interpolated centre when the
// interpolation's deviation is within kUnposedPriorSigmaFraction of the points' depth (the
// scanned-objects drone with occlusion: its frames at 2.0-2.2 % end 2-7 mm off; of the two
// at 4.0-4.2 %, one would be 37 mm off; docs/design/map_refinement.md).
constexpr int kUnposedMinPoints = 20;
constexpr double kUnposedPriorSigmaFraction = 0.025;
// ApplyMotionPrior: a frame joins the smoothing with at least this many map points within
// tracking's bound (its centre held by the prior, two bearings fix its rotation; the third
// one checks them).
constexpr int kMotionPriorMinPoints = 3;

// Re-solves the pose of a tracked frame against `map` (after a global bundle adjustment):
// pose-only on the map points it observed, from its current estimate and, when that fails,
// from `fallback_start` (camera_from_world; RefineMap passes the frame before it, as its own
// re-solve left it).
// The record's pose relative to its reference keyframe takes the result when the solve
// converges with at least 75 % of those observations as inliers (tracking's sparse-view
// rule). Returns whether it did.
// A keyframe's record is re-solved only when its keyframe's pose in the map explains fewer
// than 75 % of the record's observations (tracking's chi-square bound): the bundle adjustment
// dropped them as outliers, and a keyframe of a sparse view (8-20 points) left with a few
// observations drifts (the assimp-testmodels drone: such keyframes 40-75 mm off).
bool RefineFramePose(const MeasurementModel& model, const MapData& map, TrajectoryRecord* record,
                     const Pose3* fallback_start = nullptr);

// Gives poses on `map` (the map `map_id`, after RefineMap's bundle adjustment) to frames that
// have none (lost, or waiting for a map) and kept their features, between two frames with a
// pose in that map. Each is solved pose-only on the map points among its features twice:
// starting from the nearest frame with a pose before it (a sweep forward in time, each solved
// frame starting the next, as tracking solves from the previous frame) and from the nearest
// after it (a sweep backward). A solve counts when at least `min_points` map points are seen,
// 75 % of them inliers (tracking's sparse-view rule), and they determine the camera's centre
// within 1 % of their median depth, counting each point's own uncertainty (MapPoint::
// uncertainty: a view of points triangulated over small baselines fixes a pose no better than
// they are known), or fit it as exact data (noise-free features: their squared errors below
// kExactDataVarianceFactor of the model's); the frame takes the pose when
// both solves count and agree within 1 % of that depth and 1 degree, or when one counts and
// the other found no inliers at all from its start (a fast turn since the frame it started
// from: no second opinion). A frame with a pose on one side only (before the map's first
// posed frame, after its last) takes its sweep's pose when a solve started from PnP + RANSAC
// on the same points (no start needed) agrees with it the same way, unless the map is young
// (at most kSmallMapKeyframes keyframes). It then counts as tracked, relative to the reference
// keyframe of the posed frame its sweep came from. Returns how many frames got a pose.
int SolveUnposedFrames(const MeasurementModel& model, const MapData& map, int map_id,
                       int min_points, std::vector<TrajectoryRecord>* records);

// Smooths, on `map` (the map `map_id`, after RefineMap's re-solves), the frames whose points
// leave the centre loosely determined (its standard deviation for pixel_sigma noise above
// kLooseCentreSigmaFraction of their median depth): the centre the points
// give is fused, by their covariance, with the one interpolated in time between the nearest
// well-determined frames (or keyframes) on either side, whose deviation is that of anchors
// from their neighbours' interpolation within kSmoothingWindowS, grown with the span; the
// rotation is refitted to the frame's bearings from the fused centre. `max_points`: the
// tracker's (dense views are judged on an even subset, its information scaled up).
// Frames still without a pose that see at least kMinRotationOnlyInliers map points (the
// tracker's bound for a rotation-only pose: the centre given, three degrees of freedom), between
// two well-determined frames at most kSmoothingMaxSpanS from them, take the centre interpolated
// between those two and the rotation their points fit there (most of them within the
// chi-square bound, widened by the centre's deviation), when that deviation is within
// kUnposedPriorSigmaFraction of the points' median depth. The deviation is measured, not
// grown: the RMS distance of the well-determined frames within kSmoothingWindowS from the
// interpolation between frames the same span apart around each (the motion's curvature and
// the poses' noise at that span). They then count as tracked, relative to the nearest posed
// frame's reference keyframe. Returns how many frames it moved and how many it posed.
struct SmoothedFrames {
  int smoothed = 0;  // frames with a pose moved
  int posed = 0;     // frames without one given one
};
SmoothedFrames SmoothLooseFrames(const MeasurementModel& model, const MapData& map, int map_id,
                                 int max_points, std::vector<TrajectoryRecord>* records);

// Smooths every frame with a pose in `map` (the map `map_id`, after the steps above) jointly
// under a prior on the camera's acceleration (OptimizeTrajectory: acceleration_sigma map
// units/s^2 per axis, consecutive frames at most kSmoothingConsecutiveS apart; each frame on
// its map points within tracking's chi-square bound, at least kMotionPriorMinPoints of them;
// `max_points`: the tracker's). Frames whose points leave the centre loosely determined
// (SmoothLooseFrames' rule) are left as SmoothLooseFrames left them. The pixel noise the prior
// is weighed against is the one the observations show (their median squared error); with
// exact data (its variance below kExactDataVarianceFactor of the model's) nothing moves. A
// frame keeps its pose where the smoothed one explains fewer than kSparseViewInlierFraction as
// many of its observations. A keyframe's record at its keyframe (tracking's, and the one
// RefineFramePose leaves) is held: the bundle adjustment's pose. Single views of a few hundred
// bunched points fix the centre to millimetres under 0.5 px noise, independently from frame
// to frame; the prior averages that noise over neighbouring frames.
struct MotionPriorResult {
  double pixel_sigma = 0.0;  // estimated from the residuals (0: too few frames)
  int smoothed = 0;          // frames that took the smoothed pose
  int kept = 0;              // frames the smoothed pose no longer explained
};
MotionPriorResult ApplyMotionPrior(const MeasurementModel& model, const MapData& map, int map_id,
                                   int max_points, double acceleration_sigma,
                                   std::vector<TrajectoryRecord>* records);

}  // namespace m2s::slam
