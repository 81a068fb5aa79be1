#include "accuracy_run.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <optional>
#include <thread>
#include <vector>

#include "m2s/common/alignment.h"
#include "m2s/common/numeric.h"
#include "m2s/slam/system.h"

namespace m2s::bench {
namespace {

constexpr double kFarMapPointM = 0.05;

using Clock = std::chrono::steady_clock;

bool HasPose(slam::TrackingState state) {
  return state == slam::TrackingState::kOk || state == slam::TrackingState::kRelocalized;
}

struct Alignment {
  Sim3 truth_from_estimate;
  double rmse = -1.0;
  double max = -1.0;
};

// Sim3 (Umeyama) alignment of estimated camera centres onto the true ones.
std::optional<Alignment> AlignTrajectory(const std::vector<Eigen::Vector3d>& estimate,
                                         const std::vector<Eigen::Vector3d>& truth) {
  const std::optional<Sim3> sim3 = AlignPoints(estimate, truth, /*with_scale=*/true);
  if (!sim3) return std::nullopt;
  Alignment out{*sim3, 0.0, 0.0};
  double sum = 0.0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    const double e = ((*sim3) * estimate[i] - truth[i]).norm();
    sum += e * e;
    out.max = std::max(out.max, e);
  }
  out.rmse = std::sqrt(sum / estimate.size());
  return out;
}

// Fills the trajectory and map metrics from the system's final state and the online poses.
void Evaluate(const Scene& scene, const Trajectory& ground_truth, slam::System& system,
              const std::vector<slam::TrackResult>& results, const std::string& dump_prefix,
              RunMetrics* m) {
  const slam::SystemStats stats = system.Stats();
  std::vector<Eigen::Vector3d> estimate, truth;
  std::vector<slam::TrajectoryEntry> tracked;
  // Poses in maps never merged into the final one are in other worlds: counted, not evaluated.
  for (const slam::TrajectoryEntry& entry : system.Trajectory()) {
    if (!HasPose(entry.state) || entry.map_id != stats.current_map || entry.seq < 0 ||
        entry.seq >= static_cast<int64_t>(ground_truth.size())) {
      continue;
    }
    estimate.push_back(entry.world_from_camera.translation());
    truth.push_back(ground_truth[entry.seq].world_from_camera.translation());
    tracked.push_back(entry);
  }
  const std::optional<Alignment> final_alignment = AlignTrajectory(estimate, truth);
  if (final_alignment && !dump_prefix.empty()) {
    std::ofstream est(dump_prefix + "_estimate.tum");
    std::ofstream gt(dump_prefix + "_truth.tum");
    est << std::setprecision(17);
    gt << std::setprecision(17);
    for (const slam::TrajectoryEntry& entry : tracked) {
      const Pose3 aligned =
          final_alignment->truth_from_estimate.TransformPose(entry.world_from_camera);
      const Pose3& g = ground_truth[entry.seq].world_from_camera;
      for (auto [out, pose] : {std::pair{&est, aligned}, std::pair{&gt, g}}) {
        const Eigen::Quaterniond& q = pose.rotation();
        *out << entry.timestamp << ' ' << pose.translation().x() << ' ' << pose.translation().y()
             << ' ' << pose.translation().z() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' '
             << q.w() << '\n';
      }
    }
  }
  if (final_alignment) {
    m->ate_rmse_m = final_alignment->rmse;
    m->ate_max_m = final_alignment->max;
    m->scale = final_alignment->truth_from_estimate.scale();
    const slam::MapDelta map = system.FullMap();  // the well-constrained points
    m->shown_points = static_cast<int>(map.point_ids.size());
    std::vector<double> errors;
    for (size_t i = 0; i < map.point_ids.size(); ++i) {
      if (map.point_ids[i] >= scene.num_vertices()) continue;
      const Eigen::Vector3d aligned =
          final_alignment->truth_from_estimate * map.point_positions[i].cast<double>();
      errors.push_back((aligned - scene.positions[map.point_ids[i]].cast<double>()).norm());
    }
    if (!errors.empty()) {
      double sum = 0.0;
      for (double e : errors) sum += e * e;
      m->map_rmse_m = std::sqrt(sum / errors.size());
      m->map_median_m = Percentile(errors, 0.5, PercentileMethod::kFlooredRank);
      m->map_p90_m = Percentile(errors, 0.9, PercentileMethod::kFlooredRank);
      m->map_p95_m = Percentile(errors, 0.95, PercentileMethod::kFlooredRank);
      m->map_far_fraction =
          static_cast<double>(std::count_if(errors.begin(), errors.end(),
                                            [](double e) { return e > kFarMapPointM; })) /
          static_cast<double>(errors.size());
    }
  }
  estimate.clear();
  truth.clear();
  for (const slam::TrackResult& r : results) {
    if (!HasPose(r.state) || r.map_id != stats.current_map || r.seq < 0 ||
        r.seq >= static_cast<int64_t>(ground_truth.size())) {
      continue;
    }
    estimate.push_back(r.world_from_camera.translation());
    truth.push_back(ground_truth[r.seq].world_from_camera.translation());
  }
  if (const std::optional<Alignment> online = AlignTrajectory(estimate, truth)) {
    m->ate_online_rmse_m = online->rmse;
  }
  m->skipped = static_cast<int>(stats.frames_dropped_queue);
  m->maps = stats.maps_created;
  m->frames_in_unmerged_maps = stats.frames_in_unmerged_maps;
  m->rejected = static_cast<int>(stats.frames_rejected);
  m->relocalisations = static_cast<int>(stats.relocalisations);
  m->loop_corrections = static_cast<int>(stats.loop_corrections);
  m->keyframes = stats.keyframes;
  m->map_points = stats.map_points;
}

// Counts tracked / initialisation / lost frames and the Track() times from ordered results.
// `visible[seq]` is the number of vertices in frame seq; frames after initialisation without a
// pose count as untracked, or as untracked_few_visible below `min_visible`. A frame has a pose
// when Track() gave it one or the final trajectory has one (`final_pose`, by seq: late).
void CountResults(const std::vector<slam::TrackResult>& results,
                  const std::vector<double>& times_ms, const std::vector<int>& visible,
                  const std::vector<bool>& final_pose, int min_visible, RunMetrics* m) {
  for (int n : visible) m->few_visible += n < min_visible ? 1 : 0;
  m->median_visible = Percentile(std::vector<double>(visible.begin(), visible.end()), 0.5,
                                 PercentileMethod::kFlooredRank);
  bool initialised = false;
  std::vector<double> track_ms, keyframe_ms;
  double features = 0.0;
  for (size_t i = 0; i < results.size(); ++i) {
    const slam::TrackResult& r = results[i];
    features += r.num_features;
    const bool late = !HasPose(r.state) && r.seq >= 0 &&
                      r.seq < static_cast<int64_t>(final_pose.size()) && final_pose[r.seq];
    if (HasPose(r.state) || late) {
      initialised = true;
      ++m->tracked;
      m->late += late ? 1 : 0;
    } else if (!initialised) {
      ++m->init_frames;
    } else {
      if (r.state == slam::TrackingState::kLost) ++m->lost;
      const bool few = r.seq >= 0 && r.seq < static_cast<int64_t>(visible.size()) &&
                       visible[r.seq] < min_visible;
      ++(few ? m->untracked_few_visible : m->untracked);
    }
    const double ms = i < times_ms.size() ? times_ms[i] : r.tracking_ms;
    if (initialised && HasPose(r.state))
      (r.keyframe_created ? keyframe_ms : track_ms).push_back(ms);
  }
  m->mean_features = results.empty() ? 0.0 : features / results.size();
  m->track_median_ms = Percentile(track_ms, 0.5, PercentileMethod::kFlooredRank);
  m->track_p90_ms = Percentile(track_ms, 0.9, PercentileMethod::kFlooredRank);
  m->keyframe_median_ms = Percentile(keyframe_ms, 0.5, PercentileMethod::kFlooredRank);
}

}  // namespace

Expected<RunMetrics> RunAccuracy(const Scene& scene, const Sequence& sequence,
                                 const RunConfig& config) {
  Expected<Trajectory> ground_truth = sequence.trajectory.Resample(config.fps);
  if (!ground_truth) return Status::Error(ground_truth.error());
  const Camera camera = BenchCamera();
  FrameSourceOptions source_options;
  source_options.vertex_stride = config.vertex_stride;
  source_options.noise.seed = config.noise_seed;
  source_options.occlusion = config.occlusion;
  source_options.projector_threads = config.projector_threads;
  source_options.send_budget = config.send_budget;
  if (config.noisy) {
    source_options.noise.pixel_noise_sigma = config.noise_px;
    source_options.noise.wrong_id_fraction = config.wrong_id_fraction;
  }
  Expected<std::unique_ptr<FrameSource>> source =
      FrameSource::Create(scene, camera, *ground_truth, source_options);
  if (!source) return Status::Error(source.error());

  slam::Options options;
  options.camera = camera;
  options.deterministic = !config.realtime;
  if (config.feature_budget >= 0) options.feature_budget = config.feature_budget;
  if (config.init_min_parallax_deg > 0)
    options.initializer.min_parallax_deg = config.init_min_parallax_deg;
  if (config.more_views_after_s)
    options.initializer.more_views_after_s = *config.more_views_after_s;
  if (config.acceleration_sigma) options.refine_acceleration_sigma = *config.acceleration_sigma;
  if (config.max_point_uncertainty > 0)
    options.mapper.max_point_uncertainty = config.max_point_uncertainty;
  if (config.min_constrained_points >= 0)
    options.tracker.min_constrained_points = config.min_constrained_points;
  Expected<std::unique_ptr<slam::System>> created = slam::System::Create(options);
  if (!created) return Status::Error(created.error());
  slam::System& system = **created;

  RunMetrics m;
  m.sequence = sequence.name;
  m.mode =
      std::string(config.realtime ? "realtime-" : "") + (config.noisy ? "noisy" : "noise-free");
  m.fps = config.fps;
  m.frames = static_cast<int>((*source)->size());
  std::vector<slam::TrackResult> results;
  std::vector<double> times_ms;
  std::vector<int> visible((*source)->size(), 0);
  const auto start = Clock::now();

  if (!config.realtime) {
    slam::Frame frame;
    for (size_t i = 0; i < (*source)->size(); ++i) {
      if (Status s = (*source)->MakeFrame(i, &frame); !s) return Status::Error(s.message());
      visible[i] = static_cast<int>((*source)->last_visible());
      const auto t0 = Clock::now();
      results.push_back(system.Track(frame));
      times_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    }
  } else {
    // Frames are rendered beforehand so the producer only paces and submits.
    std::vector<slam::Frame> frames((*source)->size());
    for (size_t i = 0; i < frames.size(); ++i) {
      if (Status s = (*source)->MakeFrame(i, &frames[i]); !s) return Status::Error(s.message());
      visible[i] = static_cast<int>((*source)->last_visible());
    }
    std::atomic<bool> producer_done{false};
    std::thread consumer([&] {
      slam::TrackResult result;
      while (true) {
        if (system.WaitForResult(&result, 0.5)) {
          results.push_back(result);
        } else if (producer_done.load()) {
          break;
        }
      }
    });
    const auto t0 = Clock::now();
    for (size_t i = 0; i < frames.size(); ++i) {
      std::this_thread::sleep_until(t0 + std::chrono::duration_cast<Clock::duration>(
                                             std::chrono::duration<double>(i / config.fps)));
      system.Submit(std::move(frames[i]));
    }
    producer_done = true;
    consumer.join();
  }
  m.wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  // RefineMap may give poses to frames Track() returned without one (late, like those solved
  // once a new map initialises).
  if (config.refine_map) system.RefineMap();
  std::vector<bool> final_pose(visible.size(), false);
  for (const slam::TrajectoryEntry& e : system.Trajectory()) {
    if (HasPose(e.state) && e.seq >= 0 && e.seq < static_cast<int64_t>(final_pose.size()))
      final_pose[e.seq] = true;
  }
  CountResults(results, times_ms, visible, final_pose, config.min_visible_for_lost, &m);
  Evaluate(scene, *ground_truth, system, results, config.dump_prefix, &m);
  system.Shutdown();
  return m;
}

}  // namespace m2s::bench
