// The shared numeric helpers against hand-computed values.
#include "m2s/common/numeric.h"

#include <cmath>

#include <gtest/gtest.h>

namespace m2s {
namespace {

std::vector<size_t> Indices(std::initializer_list<size_t> list) { return list; }

TEST(EvenlySpacedIndices, KeepsEverythingWithinTheCap) {
  EXPECT_EQ(EvenlySpacedIndices(4, 10), Indices({0, 1, 2, 3}));
  EXPECT_EQ(EvenlySpacedIndices(4, 4), Indices({0, 1, 2, 3}));
  EXPECT_EQ(EvenlySpacedIndices(3, 0), Indices({0, 1, 2}));  // 0: no cap
  EXPECT_TRUE(EvenlySpacedIndices(0, 5).empty());
}

TEST(EvenlySpacedIndices, SpacesByTheRatioRoundedDownOrUp) {
  // n = 10, max 4: positions 0, 2.5, 5, 7.5.
  EXPECT_EQ(EvenlySpacedIndices(10, 4), Indices({0, 2, 5, 7}));
  EXPECT_EQ(EvenlySpacedIndices(10, 4, IndexRounding::kUp), Indices({0, 3, 5, 8}));
  // n = 8, max 3: positions 0, 2.667, 5.333 (and 8.0 is past the end).
  EXPECT_EQ(EvenlySpacedIndices(8, 3), Indices({0, 2, 5}));
  EXPECT_EQ(EvenlySpacedIndices(8, 3, IndexRounding::kUp), Indices({0, 3, 6}));
  // n = 7, max 2: positions 0, 3.5, and 7.0 is past the end; rounding up never reaches n.
  EXPECT_EQ(EvenlySpacedIndices(7, 2), Indices({0, 3}));
  EXPECT_EQ(EvenlySpacedIndices(7, 2, IndexRounding::kUp), Indices({0, 4}));
  EXPECT_EQ(EvenlySpacedIndices(9, 2, IndexRounding::kUp), Indices({0, 5}));
}

TEST(EvenlySpacedIndices, AccumulatedPositionsCanAddOneIndex) {
  // 1001 / 1000 added up 1000 times stops just short of 1001 in floating point: the last
  // position (1000.99...) still lies inside, as the callers' loops always counted it.
  const std::vector<size_t> kept = EvenlySpacedIndices(1001, 1000);
  ASSERT_EQ(kept.size(), 1001u);
  EXPECT_EQ(kept.front(), 0u);
  EXPECT_EQ(kept.back(), 1000u);
  for (size_t i = 1; i < kept.size(); ++i) EXPECT_GT(kept[i], kept[i - 1]);
}

TEST(Median, IsTheUpperMiddleValue) {
  EXPECT_EQ(Median({}), 0.0);
  EXPECT_EQ(Median({3.0}), 3.0);
  EXPECT_EQ(Median({5.0, 1.0, 3.0}), 3.0);
  EXPECT_EQ(Median({4.0, 1.0, 3.0, 2.0}), 3.0);  // rank n / 2 = 2 of 1, 2, 3, 4
}

TEST(MedianDepth, MeasuresAlongTheCameraAxis) {
  const std::vector<Eigen::Vector3d> points = {{0, 0, 1}, {0, 0, 4}, {5, 5, 2}};
  EXPECT_DOUBLE_EQ(MedianDepth(Pose3::Identity(), points), 2.0);
  // A camera at z = -1 looking along +z sees every point one unit deeper.
  const Pose3 camera_from_world(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 1));
  EXPECT_DOUBLE_EQ(MedianDepth(camera_from_world, points), 3.0);
  EXPECT_EQ(MedianDepth(Pose3::Identity(), {}), 0.0);
}

TEST(Percentile, ThreeConventions) {
  const std::vector<double> v = {10, 40, 20, 30, 50};  // sorted: 10 20 30 40 50
  EXPECT_EQ(Percentile(v, 0.5), 30.0);
  EXPECT_DOUBLE_EQ(Percentile(v, 0.9), 46.0);  // position 3.6: 40 + 0.6 * 10
  EXPECT_DOUBLE_EQ(Percentile(v, 0.1), 14.0);  // position 0.4
  EXPECT_EQ(Percentile(v, 1.0), 50.0);
  EXPECT_EQ(Percentile(v, 0.0), 10.0);
  // Rounded rank: round(q (n - 1)).
  EXPECT_EQ(Percentile(v, 0.9, PercentileMethod::kRoundedRank), 50.0);  // round(3.6) = 4
  EXPECT_EQ(Percentile(v, 0.7, PercentileMethod::kRoundedRank), 40.0);  // round(2.8) = 3
  EXPECT_EQ(Percentile(v, 0.5, PercentileMethod::kRoundedRank), 30.0);
  EXPECT_EQ(Percentile(v, 0.125, PercentileMethod::kRoundedRank), 20.0);  // 0.5 rounds up
  // Floored rank: floor(q n), at most n - 1.
  EXPECT_EQ(Percentile(v, 0.9, PercentileMethod::kFlooredRank), 50.0);   // floor(4.5) = 4
  EXPECT_EQ(Percentile(v, 0.5, PercentileMethod::kFlooredRank), 30.0);   // floor(2.5) = 2
  EXPECT_EQ(Percentile(v, 0.39, PercentileMethod::kFlooredRank), 20.0);  // floor(1.95) = 1
  EXPECT_EQ(Percentile(v, 1.0, PercentileMethod::kFlooredRank), 50.0);
  EXPECT_EQ(Percentile(std::vector<double>{}, 0.5), 0.0);
}

TEST(Percentile, FloatValues) {
  const std::vector<float> v = {1.5f, 0.5f, 2.5f, 3.5f};
  EXPECT_EQ(Percentile(v, 0.5, PercentileMethod::kRoundedRank), 2.5f);  // round(1.5) = 2
  EXPECT_FLOAT_EQ(Percentile(v, 0.5), 2.0f);
  EXPECT_EQ(Percentile(std::vector<float>{}, 0.95, PercentileMethod::kRoundedRank), 0.0f);
}

TEST(ChiSquare, BoundsAreTheQuantilesTheyName) {
  // Each constant against the chi-square CDF at it, in closed form: erf(sqrt(x / 2)) for 1
  // dof, 1 - exp(-x / 2) sum_{i < k/2} (x / 2)^i / i! for an even number k of dof. The
  // constants are rounded to 4 digits: the tolerance is the CDF's slope there times that
  // rounding (3.0e-2 x 5e-4, 2.5e-2 x 5e-4 and 4.2e-4 x 5e-3), rounded up.
  EXPECT_NEAR(std::erf(std::sqrt(kChi2OneDof95 / 2)), 0.95, 2e-5);
  const double h2 = kChi2TwoDof95 / 2;
  EXPECT_NEAR(1 - std::exp(-h2), 0.95, 2e-5);
  const double h6 = kChi2SixDof999 / 2;
  EXPECT_NEAR(1 - std::exp(-h6) * (1 + h6 + h6 * h6 / 2), 0.999, 3e-6);
}

TEST(LookAt, LooksAtTheTargetWithUpUp) {
  const Pose3 pose = LookAt({1, 2, 3}, {1, 5, 3});  // looking along +y, z up
  EXPECT_TRUE(pose.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  const Eigen::Matrix3d r = pose.RotationMatrix();
  EXPECT_TRUE(r.col(2).isApprox(Eigen::Vector3d(0, 1, 0)));   // z forward
  EXPECT_TRUE(r.col(1).isApprox(Eigen::Vector3d(0, 0, -1)));  // y down = -up
  EXPECT_TRUE(r.col(0).isApprox(Eigen::Vector3d(1, 0, 0)));   // x right
  // The target projects to the image centre.
  const Eigen::Vector3d target_in_camera = pose.Inverse() * Eigen::Vector3d(1, 5, 3);
  EXPECT_NEAR(target_in_camera.x(), 0.0, 1e-12);
  EXPECT_NEAR(target_in_camera.y(), 0.0, 1e-12);
  EXPECT_NEAR(target_in_camera.z(), 3.0, 1e-12);
}

TEST(LookAt, LookingAlongUpPicksAPerpendicular) {
  const Pose3 pose = LookAt({0, 0, 0}, {0, 0, 2});  // along the up vector
  const Eigen::Matrix3d r = pose.RotationMatrix();
  ASSERT_TRUE(r.allFinite());
  EXPECT_TRUE(r.col(2).isApprox(Eigen::Vector3d::UnitZ()));
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
  EXPECT_NEAR(r.col(0).dot(Eigen::Vector3d::UnitZ()), 0.0, 1e-12);
  // Another up vector gives the usual frame.
  const Eigen::Matrix3d floor =
      LookAt({0, 0, 1}, {0, 0, 0}, Eigen::Vector3d::UnitX()).RotationMatrix();
  EXPECT_TRUE(floor.col(1).isApprox(-Eigen::Vector3d::UnitX()));
}

}  // namespace
}  // namespace m2s
