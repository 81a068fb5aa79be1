// Tracker tests' synthetic scenes: points in front of the identity camera, a map with an old
// ("dormant") and a reference keyframe, noisy observations, and poses solved directly with
// OptimizePose as references (tracker_test.cc, tracker_recovery_test.cc).
#pragma once

#include <cmath>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/numeric.h"
#include "optimization/problems.h"
#include "tracking/tracker.h"

namespace m2s::slam::tracker_test {

inline constexpr KeyframeId kOldKeyframe = 0;
inline constexpr KeyframeId kReferenceKeyframe = 40;  // > drift.min_keyframe_gap after kOldKeyframe
inline constexpr VertexId kFirstOldId = 100000;

struct Scene {
  std::vector<VertexId> ids;
  std::vector<Eigen::Vector3d> true_points;  // world
  std::vector<bool> old;                     // observed only by kOldKeyframe (dormant)
};

// A point in front of the identity camera, projecting inside [u0, u1] x [v0, v1].
inline Eigen::Vector3d PointInPatch(const Camera& camera, std::mt19937* rng, double u0, double u1,
                                    double v0, double v1) {
  std::uniform_real_distribution<double> u(u0, u1), v(v0, v1), depth(1.5, 3.0);
  return camera.Unproject({u(*rng), v(*rng)}, depth(*rng));
}

// Appends n points (ids from first_id) projecting inside the patch of the identity camera.
inline void AddPoints(const Camera& camera, int n, VertexId first_id, bool old, double u0,
                      double u1, double v0, double v1, std::mt19937* rng, Scene* scene) {
  for (int i = 0; i < n; ++i) {
    scene->ids.push_back(first_id + static_cast<VertexId>(i));
    scene->true_points.push_back(PointInPatch(camera, rng, u0, u1, v0, v1));
    scene->old.push_back(old);
  }
}

// Recent and old points over the whole image, and the map positions with the old part of the
// map shifted by `drift` (a map that drifted before the recent keyframes).
struct DriftedScene {
  Scene scene;
  std::vector<Eigen::Vector3d> mapped;
};
inline DriftedScene RecentAndDriftedOldPoints(const Camera& camera, int recent, int old,
                                              const Eigen::Vector3d& drift, std::mt19937* rng) {
  DriftedScene d;
  AddPoints(camera, recent, 0, false, 10, 630, 10, 470, rng, &d.scene);
  AddPoints(camera, old, kFirstOldId, true, 10, 630, 10, 470, rng, &d.scene);
  d.mapped = d.scene.true_points;
  for (size_t i = 0; i < d.mapped.size(); ++i) {
    if (d.scene.old[i]) d.mapped[i] += drift;
  }
  return d;
}

inline Options TestOptions() {
  Options options;
  options.camera = Camera::FromHorizontalFov(640, 480, 90.0);
  options.pixel_sigma = 0.5;
  return options;
}

// Inserts the scene into the map: old points observed by kOldKeyframe, recent ones by the
// reference keyframe (both at the identity pose), each at `mapped(i)`.
template <typename Mapped>
void InsertScene(const Scene& scene, const Camera& camera, Mapped mapped, Map* map) {
  while (map->NextKeyframeId() < kReferenceKeyframe) {
  }  // reserved: the tracker's own keyframes get later ids
  map->Write([&](MapData& m) {
    for (const KeyframeId kf_id : {kOldKeyframe, kReferenceKeyframe}) {
      Keyframe kf;
      kf.id = kf_id;
      for (size_t i = 0; i < scene.ids.size(); ++i) {
        if (scene.old[i] != (kf_id == kOldKeyframe)) continue;
        kf.ids.push_back(scene.ids[i]);
        kf.uvs.push_back(camera.Project(scene.true_points[i]));
      }
      m.AddKeyframe(std::move(kf));
    }
    for (size_t i = 0; i < scene.ids.size(); ++i) {
      const KeyframeId observer = scene.old[i] ? kOldKeyframe : kReferenceKeyframe;
      m.AddPoint(scene.ids[i], mapped(i), observer);
      m.AddObservation(scene.ids[i], observer);
    }
  });
}

// InsertScene with every point at its true position.
inline void InsertTrueScene(const Scene& scene, const Camera& camera, Map* map) {
  InsertScene(
      scene, camera, [&](size_t i) { return scene.true_points[i]; }, map);
}

// n points in the central part of the identity camera's image (still in view after a small
// motion), mapped at their true positions.
inline void MapCentralPoints(const Camera& camera, int n, std::mt19937* rng, Scene* scene,
                             Map* map) {
  AddPoints(camera, n, 0, false, 80, 560, 80, 400, rng, scene);
  InsertTrueScene(*scene, camera, map);
}

// The frame seen from `world_from_camera` with Gaussian pixel noise (sorted by id).
inline SortedFeatures Observe(const Scene& scene, const Camera& camera,
                              const Pose3& world_from_camera, double noise_px, std::mt19937* rng) {
  std::normal_distribution<double> noise(0.0, noise_px);
  const Pose3 camera_from_world = world_from_camera.Inverse();
  SortedFeatures f;
  for (size_t i = 0; i < scene.ids.size(); ++i) {
    f.ids.push_back(scene.ids[i]);
    f.uvs.push_back(camera.Project(camera_from_world * scene.true_points[i]) +
                    Eigen::Vector2d(noise(*rng), noise(*rng)));
  }
  return f;
}

inline double PositionError(const Pose3& a, const Pose3& b) {
  return (a.translation() - b.translation()).norm();
}

// OptimizePose from the identity on the given points and their observations.
inline Pose3 SolveFromIdentity(const Options& options, const std::vector<Eigen::Vector3d>& points,
                               const std::vector<Eigen::Vector2d>& uvs) {
  PoseOnlyOptions po;
  po.pixel_sigma = options.pixel_sigma;
  po.huber_delta_px = std::sqrt(kChi2TwoDof95) * options.pixel_sigma;
  Pose3 camera_from_world;
  OptimizePose(options.camera, po, points, uvs, &camera_from_world);
  return camera_from_world.Inverse();
}

// SolveFromIdentity on the chosen points (old, recent or both) of the frame.
inline Pose3 SolveOn(const Options& options, const Scene& scene,
                     const std::vector<Eigen::Vector3d>& mapped, const SortedFeatures& frame,
                     bool use_old, bool use_recent) {
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  for (size_t i = 0; i < scene.ids.size(); ++i) {
    if (scene.old[i] ? !use_old : !use_recent) continue;
    points.push_back(mapped[i]);
    uvs.push_back(frame.uvs[i]);
  }
  return SolveFromIdentity(options, points, uvs);
}

// A pose-only problem recorded in a real-time noisy benchmark run (room-s2, 75 fps): the
// tracker's motion prior (camera_from_world, first line: qw qx qy qz tx ty tz), then one
// "x y z u v" line per map point and its observation. Camera 640x480, 90 deg, pixel_sigma 1.
struct RecordedProblem {
  Pose3 prior;
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
};

inline RecordedProblem LoadRecorded(const std::string& name) {
  RecordedProblem p;
  std::ifstream in(std::string(M2S_SOURCE_DIR) + "/tests/data/tracking/" + name);
  EXPECT_TRUE(in.good()) << name;
  double qw, qx, qy, qz, tx, ty, tz;
  in >> qw >> qx >> qy >> qz >> tx >> ty >> tz;
  p.prior = Pose3(Eigen::Quaterniond(qw, qx, qy, qz).normalized(), Eigen::Vector3d(tx, ty, tz));
  double x, y, z, u, v;
  while (in >> x >> y >> z >> u >> v) {
    p.points.emplace_back(x, y, z);
    p.uvs.emplace_back(u, v);
  }
  return p;
}

inline int InliersAt(const Camera& camera, const RecordedProblem& p,
                     const Pose3& camera_from_world) {
  int n = 0;
  for (size_t i = 0; i < p.points.size(); ++i) {
    const Eigen::Vector3d pc = camera_from_world * p.points[i];
    if (pc.z() > 0.0 && (camera.Project(pc) - p.uvs[i]).squaredNorm() <= kChi2TwoDof95) ++n;
  }
  return n;
}

}  // namespace m2s::slam::tracker_test
