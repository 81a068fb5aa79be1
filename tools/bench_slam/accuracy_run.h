// One accuracy run of the SLAM system: a sequence at a frame rate, with or without feature
// noise, either frame by frame (deterministic mode: mapping inline) or in real time (frames
// submitted at the frame rate by the wall clock into the latest-wins queue, mapping threaded).
//
//   RunConfig config{.fps = 60, .noisy = true};
//   Expected<RunMetrics> m = RunAccuracy(scene, sequence, config);
#pragma once

#include <optional>
#include <string>

#include "m2s/common/scene.h"
#include "m2s/common/status.h"
#include "sequence.h"

namespace m2s::bench {

struct RunConfig {
  double fps = 30.0;
  bool noisy = false;       // 0.5 px Gaussian noise + 1% wrong ids
  bool realtime = false;    // wall-clock pacing into Submit(), threaded mapping
  int feature_budget = -1;  // slam::Options::feature_budget, the balanced selection of every
                            // visible vertex (-1: the library's default, 0: all)
  double init_min_parallax_deg = -1.0;  // Options::initializer.min_parallax_deg (-1: default)
  // Options::initializer.more_views_after_s (nullopt: the library's default).
  std::optional<double> more_views_after_s;
  // Options::refine_acceleration_sigma (nullopt: the library's default).
  std::optional<double> acceleration_sigma;
  double max_point_uncertainty = -1.0;  // Options::mapper.max_point_uncertainty (-1: default)
  int min_constrained_points = -1;      // Options::tracker.min_constrained_points (-1: default)
  int vertex_stride = 1;                // use only vertices with id % vertex_stride == 0
  double noise_px = 0.5;
  double wrong_id_fraction = 0.01;
  uint64_t noise_seed = 1;
  bool occlusion = true;      // hide vertices behind the scene's triangles (projector.h)
  int projector_threads = 1;  // the CPU projector's workers (0: one per core)
  int send_budget = 0;        // FrameSourceOptions::send_budget (0: every visible vertex)
  // Frames without a pose after initialisation count as untracked only when at least this many
  // vertices are visible; the others are counted apart (RunMetrics::untracked_few_visible).
  int min_visible_for_lost = 0;
  // System::RefineMap() once every frame is tracked: the final trajectory and the map error
  // are measured after it (the online ATE, on the poses Track() returned, is not affected).
  bool refine_map = true;
  // When set, the Sim3-aligned final trajectory and the ground truth of the tracked frames are
  // written there as TUM files (<prefix>_estimate.tum, <prefix>_truth.tum).
  std::string dump_prefix;
};

struct RunMetrics {
  std::string sequence;
  std::string mode;  // "noise-free", "noisy", "realtime-noise-free", "realtime-noisy"
  double fps = 0.0;
  int frames = 0;  // frames of the sequence at this rate
  // Counted on the final trajectory (System::Trajectory), which gives poses to frames that had
  // none when tracked (the frames between a map's two initial views): `late` counts those.
  int tracked = 0;      // frames with a pose (kOk or kRelocalized)
  int late = 0;         // of them, frames without a pose from Track()
  int init_frames = 0;  // frames before the first tracked one
  int lost = 0;         // frames reported kLost after initialisation and never given a pose
  // Frames after initialisation without a pose (any state) and with at least
  // RunConfig::min_visible_for_lost visible vertices; those with fewer are untracked_few_visible.
  int untracked = 0;
  int untracked_few_visible = 0;
  int few_visible = 0;  // frames with fewer than min_visible_for_lost visible vertices
  int rejected = 0;
  int skipped = 0;  // dropped by the latest-wins queue (real-time mode)
  int relocalisations = 0;
  int maps = 0;  // SLAM maps started (1: tracking never stayed lost)
  int loop_corrections = 0;
  int keyframes = 0;
  int map_points = 0;
  // Tracked frames in maps never merged into the final one (SystemStats): not in the ATE.
  int64_t frames_in_unmerged_maps = 0;
  int shown_points = 0;  // well-constrained map points: what clients receive and map error uses
  double mean_features = 0.0;
  double median_visible = 0.0;  // visible vertices per frame (before the feature budget)
  double ate_rmse_m = -1.0;     // final trajectory (after BA / drift correction), Sim3 aligned
  double ate_max_m = -1.0;
  double ate_online_rmse_m = -1.0;  // poses as returned by Track(), Sim3 aligned
  double map_rmse_m = -1.0;         // map points vs true vertices, with the trajectory's alignment
  double map_median_m = -1.0;
  double map_p90_m = -1.0;
  double map_p95_m = -1.0;
  double map_far_fraction = -1.0;  // fraction of map points more than 5 cm off
  double scale = 0.0;              // Sim3 scale world_true_from_estimate
  double track_median_ms = 0.0;    // Track() wall time on non-keyframe frames
  double track_p90_ms = 0.0;
  double keyframe_median_ms = 0.0;  // Track() wall time on keyframe frames (deterministic:
                                    // includes the inline local mapping and local BA)
  double wall_s = 0.0;
};

Expected<RunMetrics> RunAccuracy(const Scene& scene, const Sequence& sequence,
                                 const RunConfig& config);

}  // namespace m2s::bench
