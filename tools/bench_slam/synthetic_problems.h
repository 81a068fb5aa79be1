// Synthetic optimisation problems for the back-end micro-benchmarks: a pose-only problem with
// a given number of features and a local-BA window of keyframes on an arc around a point cloud,
// both with exact ground truth and a realistic prediction error.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "optimization/problems.h"

namespace m2s::bench {

struct PoseOnlyProblem {
  Camera camera;
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uv;
  Pose3 truth;       // camera_from_world
  Pose3 prediction;  // truth perturbed by ~0.5 degree and ~1 cm (constant-velocity error)
};

// `num_features` points seen by one camera; `noise_px` Gaussian pixel noise and a fraction of
// wrong correspondences (pixels of other points), deterministic for a seed.
PoseOnlyProblem MakePoseOnlyProblem(int num_features, double noise_px, double wrong_fraction,
                                    unsigned seed);

struct LocalBaWindow {
  Camera camera;
  slam::BaProblem problem;  // keyframes perturbed, the first two fixed at the truth
};

// `num_keyframes` keyframes on an arc, each seeing about `features_per_keyframe` of the points.
LocalBaWindow MakeLocalBaWindow(int num_keyframes, int features_per_keyframe, double noise_px,
                                unsigned seed);

}  // namespace m2s::bench
