// Point uncertainty against independent references: the stereo depth formula, finite
// differences of the projection, and the spread of triangulations of noisy pixels; and what
// the map makes of it: points over a tiny baseline are hidden from clients until a wide one
// constrains them.
#include "mapping/point_uncertainty.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>

#include "m2s/common/numeric.h"
#include "map/map.h"
#include "mapping/triangulation.h"

namespace m2s::slam {
namespace {

// camera_from_world of a camera at `center` with the world's axes (looking along +z).
Pose3 CameraAt(const Eigen::Vector3d& center) {
  return Pose3(Eigen::Matrix3d::Identity(), -center);
}

TEST(PointUncertainty, StereoPairMatchesTheDepthFormula) {
  // Two cameras b apart looking along z at a point on the axis between them: the disparity
  // f b / Z has noise sqrt(2) sigma, so depth has sigma_Z = sqrt(2) sigma Z^2 / (f b).
  const Camera camera;
  const double sigma = 0.7;
  for (const double z : {1.0, 3.0, 8.0}) {
    for (const double b : {0.01, 0.1, 0.5}) {
      const std::vector<Pose3> poses = {CameraAt({-b / 2, 0, 0}), CameraAt({b / 2, 0, 0})};
      const double expected = std::sqrt(2.0) * sigma * z / (camera.fx * b);
      EXPECT_NEAR(RelativePointUncertainty(camera, sigma, poses, {0, 0, z}) / expected, 1.0, 1e-9)
          << "Z " << z << " b " << b;
    }
  }
}

TEST(PointUncertainty, InformationMatchesFiniteDifferencesOfTheProjection) {
  Camera camera;
  camera.fy = 430.0;  // not square pixels
  const Eigen::Vector3d point(0.4, -0.3, 2.5);
  const std::vector<Pose3> poses = {
      LookAt({0, 0, 0}, point, {0, -1, 0}).Inverse(),
      LookAt({0.3, 0.1, -0.2}, point + Eigen::Vector3d(0.2, 0, 0), {0, -1, 0}).Inverse(),
      LookAt({-0.5, 0.2, 0.1}, point + Eigen::Vector3d(0, 0.3, 0), {0, -1, 0}).Inverse()};
  Eigen::Matrix3d reference = Eigen::Matrix3d::Zero();
  const double h = 1e-6;
  for (const Pose3& pose : poses) {
    Eigen::Matrix<double, 2, 3> jacobian;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d step = h * Eigen::Vector3d::Unit(k);
      jacobian.col(k) =
          (camera.Project(pose * (point + step)) - camera.Project(pose * (point - step))) / (2 * h);
    }
    reference += jacobian.transpose() * jacobian;
  }
  Eigen::Matrix3d information;
  double mean_depth = 0.0;
  ASSERT_TRUE(PointInformation(camera, poses, point, &information, &mean_depth));
  EXPECT_LT((information - reference).norm(), 1e-6 * reference.norm());
  double depth_sum = 0.0;
  for (const Pose3& pose : poses) depth_sum += (pose * point).z();
  EXPECT_NEAR(mean_depth, depth_sum / 3.0, 1e-12);

  // Behind a camera: no information, infinite uncertainty.
  const std::vector<Pose3> behind = {poses[0], CameraAt({0, 0, 5})};
  EXPECT_FALSE(PointInformation(camera, behind, point, &information));
  EXPECT_TRUE(std::isinf(RelativePointUncertainty(camera, 1.0, behind, point)));
  EXPECT_TRUE(std::isinf(RelativePointUncertainty(camera, 1.0, {poses[0]}, point)));
}

TEST(PointUncertainty, MatchesTheSpreadOfTriangulationsOfNoisyPixels) {
  // Rotated views with about 6 and 12 degrees of parallax; 0.5 px noise. The predicted largest
  // standard deviation and its direction against 4000 DLT triangulations of noisy pixels.
  const Camera camera;
  const double sigma = 0.5;
  const Eigen::Vector3d point(0.2, 0.1, 3.0);
  for (const double baseline : {0.3, 0.6}) {
    const std::vector<Pose3> poses = {
        LookAt({0, 0, 0}, point, {0, -1, 0}).Inverse(),
        LookAt({baseline, 0.05, 0.1}, point + Eigen::Vector3d(0.1, 0.2, 0), {0, -1, 0}).Inverse()};
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, sigma);
    std::vector<Eigen::Vector3d> samples;
    for (int i = 0; i < 4000; ++i) {
      std::vector<Eigen::Vector2d> uv;
      for (const Pose3& pose : poses)
        uv.push_back(camera.Project(pose * point) + Eigen::Vector2d(noise(rng), noise(rng)));
      const auto p = TriangulateDlt(camera, poses, uv);
      ASSERT_TRUE(p.has_value());
      samples.push_back(*p);
    }
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& s : samples) mean += s;
    mean /= samples.size();
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
    for (const Eigen::Vector3d& s : samples) covariance += (s - mean) * (s - mean).transpose();
    covariance /= samples.size() - 1;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> sampled(covariance);

    Eigen::Matrix3d information;
    double mean_depth = 0.0;
    ASSERT_TRUE(PointInformation(camera, poses, point, &information, &mean_depth));
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> predicted(information);
    const double predicted_std = sigma / std::sqrt(predicted.eigenvalues()[0]);
    const double sampled_std = std::sqrt(sampled.eigenvalues()[2]);
    EXPECT_NEAR(sampled_std / predicted_std, 1.0, 0.05) << "baseline " << baseline;
    EXPECT_GT(std::abs(sampled.eigenvectors().col(2).dot(predicted.eigenvectors().col(0))), 0.99);
    EXPECT_NEAR(RelativePointUncertainty(camera, sigma, poses, point), predicted_std / mean_depth,
                1e-12);
  }
}

// Three keyframes looking along +z: 1 and 2 are 1 cm and 60 cm right of 0.
MapData ThreeKeyframes(const Camera& camera, const std::vector<Eigen::Vector3d>& points) {
  MapData m;
  const std::vector<Eigen::Vector3d> centers = {{0, 0, 0}, {0.01, 0, 0}, {0.6, 0, 0}};
  for (KeyframeId k = 0; k < centers.size(); ++k) {
    Keyframe kf;
    kf.id = k;
    kf.world_from_camera = CameraAt(centers[k]).Inverse();
    for (VertexId v = 0; v < points.size(); ++v) {
      kf.ids.push_back(v);
      kf.uvs.push_back(camera.Project(CameraAt(centers[k]) * points[v]));
    }
    m.AddKeyframe(std::move(kf));
  }
  return m;
}

TEST(PointUncertainty, ATinyBaselinePointIsHiddenUntilAWideOneConstrainsIt) {
  const Camera camera;
  const std::vector<Eigen::Vector3d> points = {{0.1, 0.2, 3.0}, {-0.2, 0.1, 2.5}};
  Map map;
  map.Write([&](MapData& m) {
    m = ThreeKeyframes(camera, points);
    m.AddPoint(0, points[0], 0);  // seen over 1 cm: ~85 % of its depth at 1 px
    m.AddObservation(0, 0);
    m.AddObservation(0, 1);
    m.AddPoint(1, points[1], 0);  // seen over 60 cm: ~1.2 %
    m.AddObservation(1, 0);
    m.AddObservation(1, 2);
    UpdatePointUncertainty(camera, {1.0, 0.02, 2.45}, {0, 1}, &m);
  });
  map.Read([&](const MapData& m) {
    EXPECT_GT(m.point(0)->uncertainty, 0.2);
    EXPECT_LT(m.point(1)->uncertainty, 0.02);
    EXPECT_FALSE(m.point(0)->constrained);
    EXPECT_TRUE(m.point(1)->constrained);
  });
  MapDelta delta = map.TakeDelta();
  EXPECT_EQ(delta.point_ids, std::vector<VertexId>{1});
  EXPECT_EQ(map.FullDelta().point_ids, std::vector<VertexId>{1});

  // The wide view joins point 0: it appears. Point 1 loses it: it goes.
  map.Write([&](MapData& m) {
    m.AddObservation(0, 2);
    m.RemoveObservation(1, 2);
    m.AddObservation(1, 1);
    UpdatePointUncertainty(camera, {1.0, 0.02, 2.45}, {0, 1}, &m);
  });
  delta = map.TakeDelta();
  EXPECT_FALSE(delta.full);
  EXPECT_EQ(delta.point_ids, std::vector<VertexId>{0});
  EXPECT_EQ(delta.removed_points, std::vector<VertexId>{1});
  EXPECT_EQ(map.FullDelta().point_ids, std::vector<VertexId>{0});

  // A new uncertainty alone is no change for clients; neither is a hidden point that moves.
  const uint64_t revision = map.revision();
  map.Write([&](MapData& m) {
    UpdatePointUncertainty(camera, {1.0, 0.03, 2.45}, {0, 1}, &m);
    m.SetPointPosition(1, points[1] * 1.01);
  });
  EXPECT_EQ(map.revision(), revision + 1);
  delta = map.TakeDelta();
  EXPECT_TRUE(delta.point_ids.empty());
  EXPECT_TRUE(delta.removed_points.empty());
}

TEST(PointUncertainty, APointItsObservationsDisagreeWithIsNotConstrained) {
  // Wide baseline, but the position is 5 cm from where the rays meet (about 10 px off in every
  // view): small uncertainty, not shown.
  const Camera camera;
  const std::vector<Eigen::Vector3d> points = {{-0.2, 0.1, 2.5}};
  MapData m = ThreeKeyframes(camera, points);
  m.AddPoint(0, points[0] + Eigen::Vector3d(0.05, 0.0, 0.0), 0);
  m.AddObservation(0, 0);
  m.AddObservation(0, 2);
  UpdatePointUncertainty(camera, {1.0, 0.02, 2.45}, {0}, &m);
  EXPECT_LT(m.point(0)->uncertainty, 0.02);
  EXPECT_FALSE(m.point(0)->constrained);
  m.SetPointPosition(0, points[0]);
  UpdatePointUncertainty(camera, {1.0, 0.02, 2.45}, {0}, &m);
  EXPECT_TRUE(m.point(0)->constrained);
}

}  // namespace
}  // namespace m2s::slam
