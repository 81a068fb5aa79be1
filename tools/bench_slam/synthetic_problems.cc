#include "synthetic_problems.h"

#include <cmath>
#include <random>

#include <Eigen/Geometry>

#include "m2s/common/numeric.h"

namespace m2s::bench {
namespace {

Camera BenchCamera() { return Camera::FromHorizontalFov(640, 480, 90.0); }

Pose3 Perturb(const Pose3& pose, double angle_rad, double shift, std::mt19937* rng) {
  std::normal_distribution<double> normal;
  const Eigen::Vector3d axis(normal(*rng), normal(*rng), normal(*rng));
  const Eigen::Vector3d dir(normal(*rng), normal(*rng), normal(*rng));
  return Pose3(
      Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, axis.normalized())) * pose.rotation(),
      pose.translation() + shift * dir.normalized());
}

}  // namespace

PoseOnlyProblem MakePoseOnlyProblem(int num_features, double noise_px, double wrong_fraction,
                                    unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, noise_px);
  PoseOnlyProblem out;
  out.camera = BenchCamera();
  out.truth = LookAt({3.0, 0.5, 0.3}, Eigen::Vector3d::Zero()).Inverse();
  while (static_cast<int>(out.points.size()) < num_features) {
    const Eigen::Vector3d p = 2.0 * Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
    const Eigen::Vector3d pc = out.truth * p;
    if (pc.z() < out.camera.near) continue;
    const Eigen::Vector2d uv = out.camera.Project(pc);
    if (!out.camera.InImage(uv.x(), uv.y())) continue;
    out.points.push_back(p);
    out.uv.push_back(
        uv + (noise_px > 0 ? Eigen::Vector2d(noise(rng), noise(rng)) : Eigen::Vector2d::Zero()));
  }
  std::uniform_int_distribution<int> pick(0, num_features - 1);
  const int wrong = static_cast<int>(std::lround(wrong_fraction * num_features));
  for (int n = 0; n < wrong; ++n) out.uv[pick(rng)] = out.uv[pick(rng)];
  out.prediction = Perturb(out.truth, 0.5 * M_PI / 180.0, 0.01, &rng);
  return out;
}

LocalBaWindow MakeLocalBaWindow(int num_keyframes, int features_per_keyframe, double noise_px,
                                unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, noise_px);
  std::normal_distribution<double> point_error(0.0, 0.005);
  LocalBaWindow out;
  out.camera = BenchCamera();
  // Points in a 4 m box; keyframes 0.1 m apart on an arc at 3 m, looking at the box centre
  // (a walking head makes a keyframe every ~10 cm).
  const int num_points = features_per_keyframe * 3;
  std::vector<Eigen::Vector3d> truth(num_points);
  for (Eigen::Vector3d& p : truth)
    p = 2.0 * Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
  for (int k = 0; k < num_keyframes; ++k) {
    const double angle = 0.1 / 3.0 * k;
    const Pose3 camera_from_world =
        LookAt({3.0 * std::cos(angle), 3.0 * std::sin(angle), 0.3}, Eigen::Vector3d::Zero())
            .Inverse();
    out.problem.keyframes.push_back({static_cast<KeyframeId>(k), camera_from_world, k < 2});
  }
  for (int p = 0; p < num_points; ++p) {
    out.problem.points.push_back({static_cast<VertexId>(p), truth[p], false});
  }
  // Each keyframe observes a random subset of the visible points (the feature budget).
  const double keep = 1.0 / 3.0;
  std::bernoulli_distribution take(keep);
  for (int k = 0; k < num_keyframes; ++k) {
    const Pose3& pose = out.problem.keyframes[k].camera_from_world;
    for (int p = 0; p < num_points; ++p) {
      const Eigen::Vector3d pc = pose * truth[p];
      const Eigen::Vector2d uv = out.camera.Project(pc);
      if (pc.z() < out.camera.near || !out.camera.InImage(uv.x(), uv.y()) || !take(rng)) continue;
      out.problem.observations.push_back(
          {k, p,
           uv +
               (noise_px > 0 ? Eigen::Vector2d(noise(rng), noise(rng)) : Eigen::Vector2d::Zero())});
    }
  }
  for (int k = 2; k < num_keyframes; ++k) {
    {
      slam::BaKeyframe& keyframe = out.problem.keyframes[k];
      keyframe.camera_from_world =
          Perturb(keyframe.camera_from_world, 0.1 * M_PI / 180.0, 0.003, &rng);
    }
  }
  for (slam::BaPoint& point : out.problem.points) {
    point.position_world += Eigen::Vector3d(point_error(rng), point_error(rng), point_error(rng));
  }
  return out;
}

}  // namespace m2s::bench
