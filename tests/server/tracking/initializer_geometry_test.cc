// Two-view initialisation on hard geometry, checked against the known motion: a planar wall,
// sparse points, a dense cluster with a few sparse points, points bunched in a small distant
// part of the image, a camera orbiting a compact object, a drone over a nearly planar floor
// (disabled: a known defect); exact and noisy projections. The initialiser must either give the
// true motion (up to scale) or refuse. The motion uncertainty it gates on is checked against
// numerics in motion_uncertainty_test.cc.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Dense>

#include "tracking/initializer.h"
#include "tracking/motion_uncertainty.h"

namespace m2s::slam {
namespace {

// Deterministic uniform numbers in [lo, hi) (the same on every platform).
class Uniform {
 public:
  explicit Uniform(uint64_t seed) : state_(seed * 0x9E3779B97F4A7C15ull + 1) {}
  double operator()(double lo, double hi) {
    state_ = state_ * 6364136223846793005ull + 1442695040888963407ull;
    return lo + (hi - lo) * static_cast<double>(state_ >> 11) / static_cast<double>(1ull << 53);
  }
  double Gaussian() {  // Box-Muller
    const double u1 = std::max((*this)(0.0, 1.0), 1e-300), u2 = (*this)(0.0, 1.0);
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }

 private:
  uint64_t state_;
};

enum class Layout {
  kPlanarWall,      // 150 points on a tilted wall
  kSparse,          // 150 points at 2-6 m
  kClusterAndFew,   // 3000 points in a 15 cm blob at 1.8 m, 150 sparse points behind
  kBunched,         // 150 points in a small patch of the image at 3-5 m
  kDistantCluster,  // 3000 points in a 20 cm blob at 3 m, nothing else
};

std::vector<Eigen::Vector3d> MakePoints(Layout layout, Uniform* u) {
  std::vector<Eigen::Vector3d> pts;
  auto blob = [&](int n, const Eigen::Vector3d& centre, double radius) {
    while (n > 0) {
      const Eigen::Vector3d d(u->operator()(-1, 1), (*u)(-1, 1), (*u)(-1, 1));
      if (d.norm() < 1e-3 || d.norm() > 1.0) continue;
      pts.push_back(centre + radius * (1.0 + 0.1 * (*u)(-1, 1)) * d.normalized());
      --n;
    }
  };
  auto sparse = [&](int n, double zmin, double zmax) {
    for (int i = 0; i < n; ++i) {
      const double z = (*u)(zmin, zmax);
      pts.emplace_back(0.6 * (*u)(-1, 1) * z, 0.45 * (*u)(-1, 1) * z, z);
    }
  };
  switch (layout) {
    case Layout::kPlanarWall:
      for (int i = 0; i < 150; ++i) {
        const double x = 2.5 * (*u)(-1, 1), y = 1.8 * (*u)(-1, 1);
        pts.emplace_back(x, y, 3.0 + 0.3 * x);
      }
      break;
    case Layout::kSparse:
      sparse(150, 2.0, 6.0);
      break;
    case Layout::kClusterAndFew:
      sparse(150, 3.0, 6.0);
      blob(3000, Eigen::Vector3d(0.5, 0.3, 1.8), 0.15);
      break;
    case Layout::kBunched:
      for (int i = 0; i < 150; ++i) {
        const double z = (*u)(3.0, 5.0);
        pts.emplace_back((-0.15 + 0.05 * (*u)(-1, 1)) * z, (-0.1 + 0.05 * (*u)(-1, 1)) * z, z);
      }
      break;
    case Layout::kDistantCluster:
      blob(3000, Eigen::Vector3d(0.2, 0.1, 3.0), 0.2);
      break;
  }
  return pts;
}

SortedFeatures Project(const Camera& camera, const Pose3& world_from_camera,
                       const std::vector<Eigen::Vector3d>& points, double noise_px, Uniform* u) {
  SortedFeatures f;
  const Pose3 camera_from_world = world_from_camera.Inverse();
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d pc = camera_from_world * points[i];
    if (pc.z() <= camera.near) continue;
    Eigen::Vector2d uv = camera.Project(pc);
    if (noise_px > 0.0) uv += noise_px * Eigen::Vector2d(u->Gaussian(), u->Gaussian());
    if (!camera.InImage(uv.x(), uv.y())) continue;
    f.ids.push_back(static_cast<VertexId>(i));
    f.uvs.push_back(uv);
  }
  return f;
}

// A random motion: 3-28 cm, mostly sideways, 0-6 degrees of rotation about a random axis.
Pose3 RandomMotion(Uniform* u) {
  const Eigen::Vector3d direction =
      Eigen::Vector3d((*u)(-1, 1), 0.3 * (*u)(-1, 1), 0.3 * (*u)(-1, 1)).normalized();
  const Eigen::Vector3d axis = Eigen::Vector3d((*u)(-1, 1), (*u)(-1, 1), (*u)(-1, 1)).normalized();
  const double angle = (*u)(0.0, 6.0) * M_PI / 180.0;
  return Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(angle, axis)), direction * (*u)(0.03, 0.28));
}

struct MotionError {
  double rotation_deg;
  double direction_deg;
};

MotionError ErrorOf(const Pose3& estimate, const Pose3& truth) {
  const double cos_direction =
      estimate.translation().normalized().dot(truth.translation().normalized());
  return {RotationAngle(estimate.rotation().conjugate() * truth.rotation()) * 180.0 / M_PI,
          std::acos(std::clamp(cos_direction, -1.0, 1.0)) * 180.0 / M_PI};
}

struct Outcome {
  int accepted = 0;
  int refused = 0;
  MotionError worst{0.0, 0.0};
};

// Two views of `layout` per trial, each with its own random motion, through Initializer.
Outcome RunTrials(Layout layout, double noise_px, int trials) {
  Options options;
  options.camera = Camera();
  Outcome out;
  for (int trial = 0; trial < trials; ++trial) {
    Uniform u(100 * static_cast<uint64_t>(layout) + static_cast<uint64_t>(trial));
    const std::vector<Eigen::Vector3d> points = MakePoints(layout, &u);
    const Pose3 truth = RandomMotion(&u);  // world_from_camera1, world = camera 0
    Initializer init(options.measurement(), options.initializer, 1);
    init.Process(0, 0.0, Project(options.camera, Pose3::Identity(), points, noise_px, &u));
    const auto map = init.Process(1, 1.0, Project(options.camera, truth, points, noise_px, &u));
    if (!map) {
      ++out.refused;
      continue;
    }
    ++out.accepted;
    const MotionError e = ErrorOf(map->second.world_from_camera, truth);
    out.worst.direction_deg = std::max(out.worst.direction_deg, e.direction_deg);
  }
  return out;
}

constexpr int kTrials = 12;
const Layout kLayouts[] = {Layout::kPlanarWall, Layout::kSparse, Layout::kClusterAndFew,
                           Layout::kBunched, Layout::kDistantCluster};

// Exact data: a map's motion is the true one, or there is no map. (Without the uncertainty
// gate and the twin-motion check, these trials gave maps 2-21 degrees and up to 178 degrees of
// translation direction off.)
TEST(InitializerGeometry, ExactDataGivesTheTrueMotionOrNone) {
  int accepted = 0;
  for (const Layout layout : kLayouts) {
    const Outcome o = RunTrials(layout, 0.0, kTrials);
    accepted += o.accepted;
    EXPECT_LT(o.worst.rotation_deg, 1e-3) << "layout " << static_cast<int>(layout);
    EXPECT_LT(o.worst.direction_deg, 1e-2) << "layout " << static_cast<int>(layout);
  }
  // Many views still initialise in one attempt (measured: 22 of 60, the planar and sparse ones;
  // the others wait for more baseline).
  EXPECT_GE(accepted, 15);
}

// 0.5 px noise: a map's motion is within three of the gate's standard deviations of the truth
// (max_rotation_sigma_deg, max_direction_sigma_deg are for pixel_sigma = 1 px; measured worst
// 0.29 and 2.3 degrees, 8 of 60 accepted).
TEST(InitializerGeometry, NoisyDataGivesAMotionNearTheTruthOrNone) {
  const InitializerOptions defaults;
  for (const Layout layout : kLayouts) {
    const Outcome o = RunTrials(layout, 0.5, kTrials);
    EXPECT_LT(o.worst.rotation_deg, 3.0 * defaults.max_rotation_sigma_deg)
        << "layout " << static_cast<int>(layout);
    EXPECT_LT(o.worst.direction_deg, 3.0 * defaults.max_direction_sigma_deg)
        << "layout " << static_cast<int>(layout);
  }
}

// Points bunched in a small distant patch fit a valley of motions (rotation traded against
// translation): even the true motion is undetermined by them, and the views are refused,
// exact data too.
TEST(InitializerGeometry, BunchedPointsAreRefused) {
  Options options;
  options.camera = Camera();
  Uniform u(11);
  const std::vector<Eigen::Vector3d> points = MakePoints(Layout::kBunched, &u);
  const Pose3 truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitY())),
                    Eigen::Vector3d(0.25, 0.02, 0.0));
  const auto at_truth =
      TwoViewMotionUncertainty(options.camera, options.pixel_sigma, truth.Inverse(), points);
  ASSERT_TRUE(at_truth.has_value());
  EXPECT_GT(at_truth->rotation_rad * 180.0 / M_PI, options.initializer.max_rotation_sigma_deg);
  TwoViewRefusal refusal;
  const auto two_view =
      ReconstructTwoView(options.measurement(), options.initializer,
                         Project(options.camera, Pose3::Identity(), points, 0.0, &u),
                         Project(options.camera, truth, points, 0.0, &u), &refusal);
  ASSERT_FALSE(two_view.has_value());
  EXPECT_TRUE(refusal.kind == TwoViewRefusal::Kind::kWeakGeometry ||
              refusal.kind == TwoViewRefusal::Kind::kNoModel)
      << refusal.message;
}

// A short sequence: the camera walks sideways past a dense cluster and a few sparse points. The
// first attempts are refused; a later frame (measured: the 7th) initialises with the true
// motion.
TEST(InitializerGeometry, ClusterSequenceInitialisesLaterWithTheTrueMotion) {
  Options options;
  options.camera = Camera();
  Uniform u(5);
  const std::vector<Eigen::Vector3d> points = MakePoints(Layout::kClusterAndFew, &u);
  Initializer init(options.measurement(), options.initializer, 1);
  const double fps = 30.0, speed_mps = 0.3;
  std::optional<InitialMap> map;
  Pose3 truth;
  int frame = 0;
  for (; frame < 90 && !map; ++frame) {
    const double t = frame / fps;
    truth = Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(-0.02 * t, Eigen::Vector3d::UnitY())),
                  Eigen::Vector3d(speed_mps * t, 0.02 * t, 0.0));
    map = init.Process(frame, t, Project(options.camera, truth, points, 0.0, &u));
  }
  ASSERT_TRUE(map.has_value()) << init.last_failure();
  EXPECT_EQ(map->first.seq, 0);
  const MotionError e = ErrorOf(map->second.world_from_camera, truth);
  EXPECT_LT(e.rotation_deg, 1e-3);
  EXPECT_LT(e.direction_deg, 1e-2);
}

struct SequenceOutcome {
  int made = 0;
  int latest = 0;  // the latest second view of a map
  MotionError worst{0.0, 0.0};
};

// A sequence's frames at 30 fps: the features of `frame`, its true world_from_camera in *truth.
using FrameSource = std::function<SortedFeatures(int frame, Pose3* truth)>;

// 20 sequences through the initialiser, the n-th drawn by `start` from Uniform(first_seed + n);
// each runs until it makes a map (at most 90 frames), which is compared with the true motion
// (`on_map` sees each map and its error).
SequenceOutcome RunSequences(
    const Options& options, uint64_t first_seed, const std::function<FrameSource(Uniform*)>& start,
    const std::function<void(const InitialMap&, const MotionError&)>& on_map = {}) {
  SequenceOutcome out;
  for (uint64_t trial = 0; trial < 20; ++trial) {
    Uniform u(first_seed + trial);
    const FrameSource next = start(&u);
    Initializer init(options.measurement(), options.initializer, 1);
    std::optional<InitialMap> map;
    std::vector<Pose3> truths;
    for (int frame = 0; frame < 90 && !map; ++frame) {
      truths.emplace_back();
      const SortedFeatures view = next(frame, &truths.back());
      map = init.Process(frame, frame / 30.0, view);
    }
    if (!map) continue;
    ++out.made;
    out.latest = std::max(out.latest, static_cast<int>(map->second.seq));
    const Pose3 truth = truths[map->first.seq].Inverse() * truths[map->second.seq];
    const MotionError e = ErrorOf(map->second.world_from_camera, truth);
    if (on_map) on_map(*map, e);
    out.worst.rotation_deg = std::max(out.worst.rotation_deg, e.rotation_deg);
    out.worst.direction_deg = std::max(out.worst.direction_deg, e.direction_deg);
  }
  return out;
}

// A hand-held camera circling a compact object keeps it in the middle of the view. Rotation
// and translation trade against each other within the noise, and RANSAC's pick in that valley
// can be degrees off (in a composed room: 6.2 degrees of parallax picked where the truth has
// 1.8, and an initial map that ruins the run). The scene: a 40 cm object 1 m ahead, two smaller
// ones further off, the 8 far corners of a room.
std::vector<Eigen::Vector3d> CompactObjectsScene(Uniform* u) {
  std::vector<Eigen::Vector3d> points;
  const struct {
    Eigen::Vector3d centre;
    double radius;
    size_t count;
  } blobs[] = {
      {{0.0, 0.05, 1.0}, 0.2, 600}, {{-0.6, 0.3, 1.6}, 0.15, 200}, {{0.5, -0.2, 2.2}, 0.2, 100}};
  for (const auto& blob : blobs) {
    for (size_t n = 0; n < blob.count;) {
      const Eigen::Vector3d d((*u)(-1, 1), (*u)(-1, 1), (*u)(-1, 1));
      if (d.norm() > 1.0) continue;
      points.push_back(blob.centre + blob.radius * d);
      ++n;
    }
  }
  for (const double x : {-2.0, 2.0})
    for (const double y : {-1.2, 1.4})
      for (const double z : {2.5, 4.0}) points.emplace_back(x, y, z);
  return points;
}

// The camera orbits the object at 0.15-0.4 m/s, 30 fps, 0.5 px noise and 1 % of the features at
// another feature's place; frames go through the initialiser until it makes a map. The map's
// motion must be within three of the gate's standard deviations of the truth. Measured over 20
// orbits: 19 maps, worst 0.52 degrees of rotation; without the second opinions of the twin
// check, worst 1.97 degrees (3 maps over 1 degree).
TEST(InitializerGeometry, OrbitAroundACompactObjectInitialisesWithTheTrueMotion) {
  Options options;
  options.camera = Camera();
  const SequenceOutcome o = RunSequences(options, 900, [&](Uniform* u) -> FrameSource {
    const std::vector<Eigen::Vector3d> points = CompactObjectsScene(u);
    const double speed = (*u)(0.15, 0.4), lift = (*u)(-0.05, 0.05);
    return [&options, u, points, speed, lift](int frame, Pose3* truth) {
      const double angle = speed * frame / 30.0;  // an orbit of radius 1 m about the object
      *truth = Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(-angle, Eigen::Vector3d::UnitY())),
                     Eigen::Vector3d(std::sin(angle), lift * angle, 1.0 - std::cos(angle)));
      SortedFeatures view = Project(options.camera, *truth, points, 0.5, u);
      for (size_t i = 0; i < view.size(); ++i) {
        if ((*u)(0.0, 1.0) < 0.005) std::swap(view.uvs[i], view.uvs[(i * 7919) % view.size()]);
      }
      return view;
    };
  });
  std::printf("orbits: %d of 20 initialised, worst %.3f degrees of rotation, %.3f of direction\n",
              o.made, o.worst.rotation_deg, o.worst.direction_deg);
  EXPECT_GE(o.made, 15);
  EXPECT_LT(o.worst.rotation_deg, 3.0 * options.initializer.max_rotation_sigma_deg);
  EXPECT_LT(o.worst.direction_deg, 3.0 * options.initializer.max_direction_sigma_deg);
}

// A drone flying level over a floor with a few low objects on it, looking ahead and down: the
// views are nearly planar (the objects rise 5-40 cm off a floor 2-9 m ahead). The homography's
// two decompositions fit about equally well for the first frames and are refused as ambiguous;
// the essential matrix then picks the plane's twin in some flights, and that twin fits the
// essential matrix's own RANSAC inliers better than the true motion does (cost 44 against 70 on
// 200 points), so the twin check, which compares raw costs on those inliers, lets it through.
std::vector<Eigen::Vector3d> FloorWithLowObjects(Uniform* u) {
  std::vector<Eigen::Vector3d> points;  // world: x right, y down, z ahead; floor at y = 1.5
  for (int i = 0; i < 500; ++i) points.emplace_back((*u)(-4, 4), 1.5, (*u)(1.5, 9));
  for (int object = 0; object < 6; ++object) {
    const Eigen::Vector3d base((*u)(-3, 3), 1.5, (*u)(2, 8));
    const double height = (*u)(0.05, 0.4), width = (*u)(0.2, 0.6);
    for (int i = 0; i < 25; ++i) {
      points.push_back(base +
                       Eigen::Vector3d((*u)(-width, width), -(*u)(0, height), (*u)(-width, width)));
    }
  }
  return points;
}

// 0.5-1.5 m/s in a random heading, a slow yaw, 30 fps, 0.5 px noise; frames go through the
// initialiser until it makes a map. Disabled: it reproduces a known defect of initialisation
// on nearly planar views. Measured over 20 flights: 20 maps, the latest at
// frame 26, two of them the plane's twin (12.7 and 17.5 degrees of rotation, 80 of direction
// off). Comparing the twins after a two-view refinement on an even subset of all shared
// features as well makes all 20 right (worst 0.28 and 5.0 degrees), but changes the corpus
// runs both ways (design/two_view_initialisation.md, Limits).
TEST(InitializerGeometry, DISABLED_DroneOverANearlyPlanarFloorInitialisesWithTheTrueMotion) {
  Options options;
  options.camera = Camera();
  const SequenceOutcome o = RunSequences(options, 1700, [&](Uniform* u) -> FrameSource {
    const std::vector<Eigen::Vector3d> points = FloorWithLowObjects(u);
    const double speed = (*u)(0.5, 1.5), heading = (*u)(-0.6, 0.6), yaw_rate = (*u)(-0.1, 0.1);
    return [&options, u, points, speed, heading, yaw_rate](int frame, Pose3* truth) {
      const double t = frame / 30.0;
      const Eigen::Quaterniond pitch(Eigen::AngleAxisd(-0.35, Eigen::Vector3d::UnitX()));
      const Eigen::Quaterniond yaw(Eigen::AngleAxisd(yaw_rate * t, Eigen::Vector3d::UnitY()));
      const Eigen::Vector3d direction(std::sin(heading), 0.02 * std::sin(3 * t), std::cos(heading));
      *truth = Pose3(yaw * pitch, speed * t * direction);
      return Project(options.camera, *truth, points, 0.5, u);
    };
  });
  std::printf(
      "flights: %d of 20 initialised, the latest at frame %d, worst %.3f degrees of "
      "rotation, %.3f of direction\n",
      o.made, o.latest, o.worst.rotation_deg, o.worst.direction_deg);
  EXPECT_GE(o.made, 18);
  EXPECT_LT(o.latest, 45);
  EXPECT_LT(o.worst.rotation_deg, 3.0 * options.initializer.max_rotation_sigma_deg);
  EXPECT_LT(o.worst.direction_deg, 3.0 * options.initializer.max_direction_sigma_deg);
}

// The drone of the test above on a turning flight (0.8-1.5 rad/s), so that the frames between
// two views lie off the line between them; more views are asked at the first refusal. Two
// views often fit the true motion and the plane's twin about equally (or leave the motion
// undetermined) and are refused; the kept frames between them then decide
// (Initializer::FromMoreViews). Every map made that way must have the true motion, and there
// must be maps made that way. Maps the two views make alone are not judged here: on this floor
// they show the defect of the test above (measured: 13 such maps, 3 of them 2.0-3.6 degrees of
// rotation and 88-95 degrees of direction off, at frames 1-4; the 7 maps from more views, worst
// 0.07 and 0.92 degrees).
TEST(InitializerGeometry, TwinsOverANearlyPlanarFloorAreToldApartByTheFramesBetween) {
  Options options;
  options.camera = Camera();
  options.initializer.more_views_after_s = 0.0;  // at the first refusal
  int from_more_views = 0, from_two = 0;
  MotionError worst{0.0, 0.0}, worst_two{0.0, 0.0};
  RunSequences(
      options, 2300,
      [&](Uniform* u) -> FrameSource {
        const std::vector<Eigen::Vector3d> points = FloorWithLowObjects(u);
        const double speed = (*u)(0.5, 1.5), heading = (*u)(-0.6, 0.6);
        const double turn = (*u)(0.8, 1.5) * ((*u)(-1, 1) < 0 ? -1.0 : 1.0);
        return [&options, u, points, speed, heading, turn](int frame, Pose3* truth) {
          const double t = frame / 30.0;
          const Eigen::Quaterniond pitch(Eigen::AngleAxisd(-0.35, Eigen::Vector3d::UnitX()));
          const Eigen::Quaterniond yaw(Eigen::AngleAxisd(0.3 * turn * t, Eigen::Vector3d::UnitY()));
          // The heading turns at `turn`: the position integrates speed (sin a, 0, cos a).
          const double a = heading + turn * t;
          const Eigen::Vector3d position(speed / turn * (std::cos(heading) - std::cos(a)), 0.0,
                                         speed / turn * (std::sin(a) - std::sin(heading)));
          *truth = Pose3(yaw * pitch, position);
          return Project(options.camera, *truth, points, 0.5, u);
        };
      },
      [&](const InitialMap& map, const MotionError& e) {
        TwoViewRefusal refusal;
        if (ReconstructTwoView(options.measurement(), options.initializer, map.first.features,
                               map.second.features, &refusal)) {
          ++from_two;  // the two views alone make a map
          worst_two.rotation_deg = std::max(worst_two.rotation_deg, e.rotation_deg);
          worst_two.direction_deg = std::max(worst_two.direction_deg, e.direction_deg);
          return;
        }
        ++from_more_views;
        worst.rotation_deg = std::max(worst.rotation_deg, e.rotation_deg);
        worst.direction_deg = std::max(worst.direction_deg, e.direction_deg);
      });
  std::printf(
      "turning flights: %d maps from more views than two, worst %.3f degrees of rotation, %.3f "
      "of direction; %d from two views, worst %.3f and %.3f\n",
      from_more_views, worst.rotation_deg, worst.direction_deg, from_two, worst_two.rotation_deg,
      worst_two.direction_deg);
  EXPECT_GE(from_more_views, 5);
  EXPECT_LT(worst.rotation_deg, 3.0 * options.initializer.max_rotation_sigma_deg);
  EXPECT_LT(worst.direction_deg, 3.0 * options.initializer.max_direction_sigma_deg);
}

}  // namespace
}  // namespace m2s::slam
