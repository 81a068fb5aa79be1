// Synthetic SLAM sequences for the server tests: the default scene seen along generated head
// motion through the CPU projector (exact ground truth), optionally degraded, and a Sim3
// aligned ATE computed independently of the library (Umeyama on camera centres).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/alignment.h"
#include "m2s/common/cpu_projector.h"
#include "m2s/common/feature_noise.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"
#include "m2s/slam/system.h"

namespace m2s::slam::testing {

struct SimOptions {
  double duration_s = 20.0;
  double fps = 30.0;
  uint64_t seed = 1;
  int budget = 1000;  // features per frame (the balanced selection); 0: all visible vertices
  double pixel_noise_sigma = 0.0;
  double wrong_id_fraction = 0.0;
  bool occlusion = true;
};

struct SimSequence {
  Camera camera;
  Trajectory ground_truth;
  std::vector<Frame> frames;
  Scene scene;
};

// A light scene for fast tests: points on the walls, floor and ceiling of the default room
// (6 x 5 x 3 m, z up, floor at 0) and in a few boxes standing in it. No triangles: project
// without occlusion.
inline Scene MakePointRoom(int num_points = 6000, uint64_t seed = 3) {
  Scene scene;
  scene.name = "point_room";
  uint64_t state = seed * 0x9E3779B97F4A7C15ull + 1;
  auto uniform = [&state](double lo, double hi) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return lo + (hi - lo) * static_cast<double>(state >> 11) / static_cast<double>(1ull << 53);
  };
  for (int i = 0; i < num_points; ++i) {
    const int face = i % 8;
    Eigen::Vector3d p;
    switch (face) {
      case 0:
        p = {-3.0, uniform(-2.5, 2.5), uniform(0, 3)};
        break;
      case 1:
        p = {3.0, uniform(-2.5, 2.5), uniform(0, 3)};
        break;
      case 2:
        p = {uniform(-3, 3), -2.5, uniform(0, 3)};
        break;
      case 3:
        p = {uniform(-3, 3), 2.5, uniform(0, 3)};
        break;
      case 4:
        p = {uniform(-3, 3), uniform(-2.5, 2.5), 0.0};
        break;
      case 5:
        p = {uniform(-3, 3), uniform(-2.5, 2.5), 3.0};
        break;
      default:
        p = {uniform(-2.8, 2.8), uniform(-2.3, 2.3), uniform(0.0, 2.5)};
        break;
    }
    scene.positions.push_back(p.cast<float>());
  }
  return scene;
}

inline const Scene& DefaultScene() {
  static const Scene scene = MakeDefaultScene();
  return scene;
}

// Projects `scene` from every pose of `trajectory` (poses at their own timestamps).
inline std::vector<Frame> ProjectFrames(const Scene& scene, const Trajectory& trajectory,
                                        const Camera& camera, const SimOptions& options) {
  ProjectorOptions popts;
  popts.occlusion = options.occlusion;
  popts.num_threads = 1;
  auto projector = CpuProjector::Create(scene, popts);
  EXPECT_TRUE(projector.ok()) << projector.error();
  FeatureNoiseOptions noise;
  noise.pixel_noise_sigma = options.pixel_noise_sigma;
  noise.wrong_id_fraction = options.wrong_id_fraction;
  const FeatureGrid grid = FeatureGrid::ForImage(camera.width, camera.height);
  noise.seed = options.seed;
  std::vector<Frame> frames;
  std::vector<ProjectedVertex> projected;
  for (size_t i = 0; i < trajectory.size(); ++i) {
    const Pose3& pose = trajectory[i].world_from_camera;
    EXPECT_TRUE((*projector)->Project(pose, camera, &projected).ok());
    if (noise.Enabled()) {
      ApplyFeatureNoise(noise, camera, static_cast<uint32_t>(scene.num_vertices()), i, &projected);
    }
    Frame f;
    f.seq = static_cast<int64_t>(i);
    f.timestamp = trajectory[i].timestamp;
    f.ground_truth_world_from_camera = pose;
    f.features.reserve(projected.size());
    for (const ProjectedVertex& v : projected)
      f.features.push_back({v.id, Eigen::Vector2f(v.u, v.v)});
    KeepBalanced(options.budget, grid, &f.features);
    frames.push_back(std::move(f));
  }
  return frames;
}

// `scene` null: the default scene.
inline SimSequence MakeSequence(const SimOptions& options, const Scene* scene = nullptr) {
  SimSequence s;
  s.camera = Camera();
  HeadMotionOptions motion = DefaultHeadMotionOptions();
  motion.duration_s = options.duration_s;
  motion.rate_hz = options.fps;
  motion.seed = options.seed;
  auto trajectory = GenerateHeadMotion(motion);
  EXPECT_TRUE(trajectory.ok()) << trajectory.error();
  s.ground_truth = *trajectory;
  s.frames = ProjectFrames(scene ? *scene : DefaultScene(), s.ground_truth, s.camera, options);
  return s;
}

struct AteResult {
  double rmse = INFINITY;
  size_t num_poses = 0;
  Sim3 truth_from_estimate;
};

// Sim3-aligned ATE over the tracked entries (kOk / kRelocalized) that carry ground truth.
inline AteResult ComputeAte(const std::vector<TrajectoryEntry>& trajectory) {
  std::vector<Eigen::Vector3d> est, truth;
  for (const TrajectoryEntry& e : trajectory) {
    if ((e.state != TrackingState::kOk && e.state != TrackingState::kRelocalized) ||
        !e.ground_truth_world_from_camera) {
      continue;
    }
    est.push_back(e.world_from_camera.translation());
    truth.push_back(e.ground_truth_world_from_camera->translation());
  }
  AteResult r;
  r.num_poses = est.size();
  const auto s = AlignPoints(est, truth, /*with_scale=*/true);
  if (!s) return r;
  double sse = 0.0;
  for (size_t i = 0; i < est.size(); ++i) sse += ((*s) * est[i] - truth[i]).squaredNorm();
  r.rmse = std::sqrt(sse / static_cast<double>(est.size()));
  r.truth_from_estimate = *s;
  return r;
}

// A map's tracked entries (kOk / kRelocalized, with ground truth) and their centres' errors
// after the similarity that aligns the estimate with the truth over those before
// `align_before_seq` (a stretch whose poses are trusted): an independent look at the frames
// after it. `aligned_on` is 0 when fewer than 3 entries came before it.
struct ErrorsAfter {
  std::vector<TrajectoryEntry> entries;
  std::vector<double> errors;  // metres, one per entry
  size_t aligned_on = 0;
  double worst() const {
    double w = 0.0;
    for (const double e : errors) w = std::max(w, e);
    return w;
  }
};
inline ErrorsAfter ErrorsAlignedBefore(const std::vector<TrajectoryEntry>& trajectory, int map_id,
                                       int64_t align_before_seq) {
  ErrorsAfter out;
  std::vector<Eigen::Vector3d> est, truth;
  for (const TrajectoryEntry& e : trajectory) {
    if (e.map_id != map_id ||
        (e.state != TrackingState::kOk && e.state != TrackingState::kRelocalized) ||
        !e.ground_truth_world_from_camera) {
      continue;
    }
    out.entries.push_back(e);
    if (e.seq >= align_before_seq) continue;
    est.push_back(e.world_from_camera.translation());
    truth.push_back(e.ground_truth_world_from_camera->translation());
  }
  const auto s = est.size() >= 3 ? AlignPoints(est, truth, /*with_scale=*/true) : std::nullopt;
  if (!s) return out;
  out.aligned_on = est.size();
  for (const TrajectoryEntry& e : out.entries) {
    out.errors.push_back(
        ((*s) * e.world_from_camera.translation() - e.ground_truth_world_from_camera->translation())
            .norm());
  }
  return out;
}

inline Options DefaultOptions(const Camera& camera) {
  Options o;
  o.camera = camera;
  o.deterministic = true;
  return o;
}

}  // namespace m2s::slam::testing
