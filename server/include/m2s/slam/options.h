// Options of the SLAM library (m2s::slam): slam::Options holds the System's own settings (input,
// queues, threads) and the measurement model every stage shares at the top level, and one
// struct per stage (initialiser, tracker, mapper, drift corrector) as members. Each stage takes
// only its own struct (and the shared MeasurementModel); every struct checks itself, and
// Options::Check checks them all. Defaults are tuned on the default scene
// (docs/results/slam_core.md).
//
// Thread-safety: plain values.
//
//   slam::Options options;
//   options.camera = camera;
//   options.tracker.min_inliers = 40;
//   if (Status valid = options.Check(); !valid) { /* report valid.message() */ }
#pragma once

#include <string>

#include "m2s/common/camera.h"

namespace m2s::slam {

// What every stage measures with: the camera, the assumed feature noise (it scales every
// chi-square test) and the angle between rays a triangulated point needs.
struct MeasurementModel {
  Camera camera;
  double pixel_sigma = 1.0;
  double min_triangulation_parallax_deg = 1.0;
};

// Monocular initialisation (tracking/initializer.h).
struct InitializerOptions {
  // Shared features, median ray parallax, and the age (in frames) after which the reference
  // frame is replaced. At 1 degree, 0.5 px of noise leaves the initial map's depths a few
  // percent off, and the frames tracked on it before the first global BAs keep that (room-s2,
  // 60 / 75 fps: ATE 5.6 / 6.2 mm at 1 degree, 1.5 / 1.2 mm at 1.5;
  // docs/results/slam_realtime.md).
  int min_points = 60;
  double min_parallax_deg = 1.5;
  int max_reference_age = 120;
  // The views must determine the relative motion, not merely fit it: its standard deviations
  // for pixel_sigma noise (rotation; direction of the translation) at most these. Points
  // bunched in a small or distant part of the image fit a valley of wrong motions within the
  // noise, exact data too (docs/design/two_view_initialisation.md). The default room's
  // initialisations have at most 0.07 and 1.3 degrees.
  double max_rotation_sigma_deg = 0.5;
  double max_direction_sigma_deg = 5.0;
  // When two-view attempts have been refused for this long (seconds of capture time since the
  // last map or reset) for weak geometry (twin motions, an undetermined motion), kept frames
  // between the two views may decide, the same bounds applied to the motion over every view
  // (docs/design/two_view_initialisation.md, item 7). Sooner, they also make maps from weaker
  // views that two views would have made a little later (scanned objects, 1 s: 3 -> 14 frames
  // lost in the noisy head run). Negative: never.
  double more_views_after_s = 3.0;

  Status Check() const;
};

// Frame-to-map tracking and the keyframe decision (tracking/tracker.h).
struct TrackerOptions {
  // Pose-only optimisation uses at most this many associated points (evenly spread over the
  // frame's ids; 0: all). Bounded tracking time on dense frames.
  int max_points = 600;
  // A frame with fewer pose inliers than this is lost (and relocalisation needs as many); in
  // a sparse view with fewer associated points, 75 % of them and at least 8 suffice (at
  // least 12 for a rotation-only pose).
  int min_inliers = 30;
  // Keyframe when the tracked points fall below this fraction of the reference keyframe's,
  double keyframe_tracked_ratio = 0.9;
  // or when this many features have no map point yet (and are seen by a keyframe),
  int keyframe_min_new_points = 50;
  // or when the camera moved this fraction of the median scene depth since the last one,
  double keyframe_baseline_ratio = 0.1;
  // or after this long (seconds).
  double keyframe_max_interval_s = 1.0;
  // Poses are solved on the well-constrained map points alone (MapperOptions::
  // max_point_uncertainty) when at least this many are associated, on every associated point
  // otherwise (right after initialisation none is well constrained); 0: always on every
  // associated point, the default (measured on five noisy sequences, 100 moves ATE by -0.8 to
  // +0.7 mm per sequence and not on average: docs/design/point_uncertainty.md).
  int min_constrained_points = 0;

  Status Check() const;
};

// Local mapping: triangulation, bundle adjustment and culling (mapping/local_mapper.h).
struct MapperOptions {
  // Local bundle adjustment: number of covisible keyframes optimised (others observing the
  // points are held fixed).
  int local_ba_window = 12;
  // At most this many points enter a local BA (evenly spread over ids); the window's other
  // points are re-triangulated from all their observers with the refined poses (0: no cap).
  int local_ba_max_points = 2000;
  // Threads Ceres may use in bundle adjustment (the initial two-view one too).
  int num_ba_threads = 1;
  // A keyframe is redundant when this fraction of its points is seen by at least
  // keyframe_redundancy_observers other keyframes (1.0: only fully redundant ones; with exact
  // association every keyframe adds constraints, and culling at ORB-SLAM2's 0.9 costs
  // accuracy under noise: docs/results/slam_core.md).
  double keyframe_redundancy = 1.0;
  // Each observation of a point under pixel noise narrows it (n observations: sigma / sqrt(n));
  // a keyframe is given up only once its points have this many other observers, where one
  // more changes a point's sigma by a few percent (20: 2.5 %). ORB-SLAM2's 3 discards the
  // keyframes that average the noise of sparse views: docs/design/map_quality.md.
  int keyframe_redundancy_observers = 20;
  // Bound on the map (oldest keyframes are culled beyond it).
  int max_keyframes = 2000;
  // A point is well constrained when the standard deviation of its position along its least
  // constrained direction (feature noise at the model's pixel_sigma, observer poses taken as
  // exact) is at most this fraction of its mean depth and every observation agrees with it:
  // only such points are sent to clients (and, with TrackerOptions::min_constrained_points,
  // solve tracked poses; docs/design/point_uncertainty.md).
  double max_point_uncertainty = 0.01;

  Status Check() const;
};

// Drift correction (mapping/drift_corrector.h): triggered when a keyframe re-observes at least
// min_points points unseen for min_keyframe_gap keyframes, and their positions disagree with
// the current estimate by more than min_error (fraction of the median depth).
struct DriftOptions {
  bool enabled = true;
  int min_points = 30;
  int min_keyframe_gap = 15;
  double min_error = 0.01;

  Status Check() const;
};

// Never staying lost (system/slam_system.h): a map that stays lost is set aside and a new one
// starts at once; a set-aside map merges into the current one as soon as they share enough
// points (vertex ids: exact correspondences, so the merge is a Sim3 from the shared points).
struct MultiMapOptions {
  bool enabled = true;
  // Lost for this long (frame time) with at least min_features features in each lost frame
  // (frames that see almost nothing do not count: they cannot relocalise anywhere).
  double new_map_after_lost_s = 0.5;
  int min_features = 20;
  // A merge needs this many shared points, of which this fraction fit one Sim3.
  int merge_min_shared_points = 30;
  double merge_min_inlier_fraction = 0.8;

  Status Check() const;
};

struct Options {
  // ---- The measurement model, shared by every stage (see MeasurementModel) ----
  Camera camera;
  // Assumed feature noise in pixels; scales every chi-square test.
  double pixel_sigma = 1.0;
  // New points need this angle between their rays.
  double min_triangulation_parallax_deg = 1.0;

  // ---- The System: input, queues, threads ----
  // Frames with more features than this are rejected (bounded work and memory).
  int max_features_per_frame = 200000;
  // Features may lie this far outside the image (noise) before the frame is rejected.
  double image_margin_px = 16.0;
  // SLAM uses at most this many features of a frame, spread over the image by the balanced
  // selection (common/feature_rank.h: a grid, the id rank deciding within each cell), so the
  // same vertices stay selected from view to view (0: all).
  // Tracking and mapping cost scale with it; accuracy barely does (docs/RESULTS.md).
  int feature_budget = 2000;
  // Each tracked frame keeps at most this many of the map points its pose was solved on (an
  // even subset of at most tracker.max_points, 12 bytes each: 7 KB a frame), so that
  // System::RefineMap() re-solves it on the refined map; a frame without a pose keeps as many
  // of its features, so that RefineMap() may solve it. 0: none (bounded memory for sessions
  // that never call RefineMap), and RefineMap() moves frames with their keyframes only. With
  // 100, the noisy scene-diversity runs end 0.2-3.2 mm worse (docs/design/map_refinement.md).
  int frame_observations_kept = 600;
  // System::RefineMap() smooths the frames it refined under a prior on the camera's
  // acceleration: this many map units per s^2 per axis at 1 sigma (a monocular map's unit is
  // the median depth of its initial points, 0.9-4.7 m in the scene-diversity runs: 5 is
  // 4-23 m/s^2; a person's head or hand or a drone accelerates by a few m/s^2), weighed
  // against the pixel noise the frames' residuals show (docs/design/map_refinement.md). 0: no
  // motion prior (each frame on its own points, as ORB-SLAM's visual-only trajectories).
  double refine_acceleration_sigma = 5.0;
  // Capacity of the latest-wins input queue used by Submit().
  int input_queue_capacity = 2;
  // Capacity of the keyframe queue in front of mapping.
  int mapping_queue_capacity = 4;
  // Run mapping and drift correction inline (bit-identical results) instead of in threads.
  bool deterministic = false;
  // Localisation only: track against a loaded map, never change it.
  bool localization_only = false;
  // Niceness added to the mapping thread (Linux; 0 keeps the caller's): tracking is the
  // latency-critical stage, mapping takes the CPU that tracking leaves.
  int mapping_nice = 5;

  // ---- The stages ----
  InitializerOptions initializer;
  TrackerOptions tracker;
  MapperOptions mapper;
  DriftOptions drift;
  MultiMapOptions multi_map;

  MeasurementModel measurement() const {
    return {camera, pixel_sigma, min_triangulation_parallax_deg};
  }
  Status Check() const;
};

}  // namespace m2s::slam
