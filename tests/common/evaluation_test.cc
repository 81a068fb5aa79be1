// Evaluation against hand-computed values and an independent transcription of evo's
// definitions (association, Umeyama with scale, APE translation part, numpy statistics).
#include "m2s/common/evaluation.h"

#include <cmath>
#include <optional>
#include <random>

#include <gtest/gtest.h>
#include <Eigen/SVD>

#include "m2s/common/alignment.h"

namespace m2s {
namespace {

Trajectory FromPositions(const std::vector<Eigen::Vector3d>& positions, double t0 = 0.0,
                         double dt = 0.1) {
  std::vector<TimedPose> poses;
  for (size_t i = 0; i < positions.size(); ++i) {
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitZ()));
    poses.push_back({t0 + dt * i, Pose3(q, positions[i])});
  }
  return *Trajectory::FromPoses(poses);
}

Trajectory Transformed(const Trajectory& t, const Sim3& s, double time_shift = 0.0) {
  std::vector<TimedPose> poses;
  for (const TimedPose& p : t)
    poses.push_back({p.timestamp + time_shift, s.TransformPose(p.world_from_camera)});
  return *Trajectory::FromPoses(poses);
}

// A wiggly 3-D path, 200 poses at 30 Hz.
Trajectory Wiggle() {
  std::vector<Eigen::Vector3d> positions;
  for (int i = 0; i < 200; ++i) {
    const double s = 0.05 * i;
    positions.emplace_back(std::cos(s) * 2.0, std::sin(1.3 * s),
                           0.3 * std::sin(0.7 * s) + 0.01 * i);
  }
  return FromPositions(positions, 100.0, 1.0 / 30.0);
}

TEST(Evaluation, StatsMatchHandComputedValues) {
  const ErrorStats s = ComputeStats({0.1, 0.2, 0.3, 0.4});
  EXPECT_EQ(s.n, 4u);
  EXPECT_NEAR(s.rmse, std::sqrt(0.075), 1e-15);
  EXPECT_NEAR(s.mean, 0.25, 1e-15);
  EXPECT_NEAR(s.median, 0.25, 1e-15);            // numpy: mean of the middle two
  EXPECT_NEAR(s.std, std::sqrt(0.0125), 1e-15);  // population std (ddof 0)
  EXPECT_NEAR(s.sse, 0.3, 1e-15);
  EXPECT_EQ(s.min, 0.1);
  EXPECT_EQ(s.max, 0.4);
  EXPECT_NEAR(s.p95, 0.385, 1e-15);  // numpy.percentile(errors, 95)
  EXPECT_EQ(ComputeStats({3.0, 1.0, 2.0}).median, 2.0);
  EXPECT_EQ(ComputeStats({7.0}).p95, 7.0);
  EXPECT_EQ(ComputeStats({}).n, 0u);
}

TEST(Evaluation, KnownOffsetWithoutAlignment) {
  // Reference along x; the estimate is off by 0.1, 0.2, 0.3, 0.4 m along y.
  const Trajectory ref = FromPositions({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}});
  const Trajectory est = FromPositions({{0, 0.1, 0}, {1, 0.2, 0}, {2, 0.3, 0}, {3, 0.4, 0}});
  EvaluationOptions options;
  options.alignment = Alignment::kNone;
  const Expected<TrajectoryEvaluation> r = EvaluateTrajectory(ref, est, options);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->matches.size(), 4u);
  EXPECT_EQ(r->scale, 1.0);
  EXPECT_NEAR(r->ate.rmse, std::sqrt(0.075), 1e-12);
  EXPECT_NEAR(r->ate.max, 0.4, 1e-12);
  // Relative motion: the estimate moves (1, 0.1, 0) per step in the frame of a pose that turns
  // 0.1 rad per step, like the reference; the error of each step is |R_i^T (0, 0.1, 0)| = 0.1.
  ASSERT_EQ(r->rpe_errors.size(), 3u);
  for (double e : r->rpe_errors) EXPECT_NEAR(e, 0.1, 1e-12);
}

TEST(Evaluation, Sim3AlignmentRemovesAKnownSimilarity) {
  const Trajectory ref = Wiggle();
  // The estimate lives in a frame 2.5x smaller, rotated and shifted: est = S^-1 * ref.
  const Sim3 ref_from_est(
      2.5, Eigen::Quaterniond(Eigen::AngleAxisd(1.1, Eigen::Vector3d(1, 2, -1).normalized())),
      Eigen::Vector3d(0.4, -3.0, 1.5));
  const Trajectory est = Transformed(ref, ref_from_est.Inverse());
  const Expected<TrajectoryEvaluation> r = EvaluateTrajectory(ref, est);  // default: sim3
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->matches.size(), 200u);
  EXPECT_LT(r->ate.rmse, 1e-9);
  EXPECT_LT(r->ate.max, 1e-9);
  EXPECT_LT(r->rpe.rmse, 1e-9);
  EXPECT_NEAR(r->scale, 2.5, 1e-9);
  EXPECT_LT((r->reference_from_estimate.translation() - ref_from_est.translation()).norm(), 1e-9);

  // SE3 cannot undo the scale; no alignment cannot undo anything.
  EvaluationOptions se3;
  se3.alignment = Alignment::kSe3;
  EXPECT_GT(EvaluateTrajectory(ref, est, se3)->ate.rmse, 0.1);
  EXPECT_EQ(EvaluateTrajectory(ref, est, se3)->scale, 1.0);
  // A rigid transform alone is removed by SE3.
  const Sim3 rigid(1.0, ref_from_est.rotation(), ref_from_est.translation());
  EXPECT_LT(EvaluateTrajectory(ref, Transformed(ref, rigid), se3)->ate.rmse, 1e-9);
}

// evo's geometry.umeyama_alignment, transcribed step by step (numpy -> Eigen).
Sim3 EvoUmeyama(const std::vector<Eigen::Vector3d>& x, const std::vector<Eigen::Vector3d>& y) {
  const double n = static_cast<double>(x.size());
  Eigen::Vector3d mean_x = Eigen::Vector3d::Zero(), mean_y = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < x.size(); ++i) {
    mean_x += x[i] / n;
    mean_y += y[i] / n;
  }
  double sigma_x = 0.0;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < x.size(); ++i) {
    sigma_x += (x[i] - mean_x).squaredNorm() / n;
    cov += (y[i] - mean_y) * (x[i] - mean_x).transpose() / n;
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d s = Eigen::Matrix3d::Identity();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) s(2, 2) = -1.0;
  const Eigen::Matrix3d r = svd.matrixU() * s * svd.matrixV().transpose();
  const double c = (svd.singularValues().asDiagonal() * s).trace() / sigma_x;
  return Sim3(c, Eigen::Quaterniond(r), mean_y - c * r * mean_x);
}

TEST(Evaluation, NoisyEstimateEqualsEvoApeWithScaleCorrection) {
  const Trajectory ref = Wiggle();
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.02);
  const Sim3 est_from_ref(0.37,
                          Eigen::Quaterniond(Eigen::AngleAxisd(-0.6, Eigen::Vector3d::UnitY())),
                          Eigen::Vector3d(2, 1, 0));
  std::vector<TimedPose> poses;
  // Every other reference pose, 3 ms late: evo matches each estimate to its nearest reference.
  for (size_t i = 0; i < ref.size(); i += 2) {
    Pose3 p = est_from_ref.TransformPose(ref[i].world_from_camera);
    p = Pose3(p.rotation(), p.translation() + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
    poses.push_back({ref[i].timestamp + 0.003, p});
  }
  const Trajectory est = *Trajectory::FromPoses(poses);
  const Expected<TrajectoryEvaluation> r = EvaluateTrajectory(ref, est);
  ASSERT_TRUE(r.ok()) << r.error();
  ASSERT_EQ(r->matches.size(), 100u);

  std::vector<Eigen::Vector3d> x, y;
  for (size_t i = 0; i < est.size(); ++i) {
    x.push_back(est[i].world_from_camera.translation());
    y.push_back(ref[2 * i].world_from_camera.translation());
  }
  const Sim3 evo = EvoUmeyama(x, y);
  std::vector<double> errors;
  for (size_t i = 0; i < x.size(); ++i) errors.push_back((evo * x[i] - y[i]).norm());
  double sse = 0.0;
  for (double e : errors) sse += e * e;
  EXPECT_NEAR(r->scale, evo.scale(), 1e-9);
  EXPECT_NEAR(r->ate.rmse, std::sqrt(sse / errors.size()), 1e-9);
  EXPECT_NEAR(r->ate.sse, sse, 1e-9);
  // The noise is really there, at its size: 0.02 m per axis in the estimate frame is
  // sqrt(3) * 0.02 / 0.37 = 0.094 m after the alignment undoes the scale (measured 0.090 m;
  // 15 % is about 4 standard errors of an rmse over 300 residuals).
  const double expected_rmse = std::sqrt(3.0) * 0.02 / 0.37;
  EXPECT_NEAR(r->ate.rmse, expected_rmse, 0.15 * expected_rmse);
}

TEST(Evaluation, AssociationFollowsEvo) {
  // Same length: the estimate is the "short" one. Offsets of 4 ms match, 20 ms do not.
  const Trajectory ref = Wiggle();
  const Sim3 identity;
  EXPECT_EQ(Associate(ref, Transformed(ref, identity, 0.004)).size(), 200u);
  EXPECT_TRUE(Associate(ref, Transformed(ref, identity, 0.02)).empty());
  AssociationOptions shifted;
  shifted.estimate_offset_s = -0.02;
  EXPECT_EQ(Associate(ref, Transformed(ref, identity, 0.02), shifted).size(), 200u);
  EXPECT_FALSE(EvaluateTrajectory(ref, Transformed(ref, identity, 0.02)).ok());

  // The longer trajectory's pose can be used twice (evo); TUM's greedy matching uses it once.
  auto stamps = [](std::vector<double> times) {
    std::vector<TimedPose> poses;
    for (double t : times) poses.push_back({t, Pose3()});
    return *Trajectory::FromPoses(poses);
  };
  const Trajectory long_ref = stamps({0.0, 0.005, 0.010, 1.0});
  const Trajectory short_est = stamps({0.004, 0.006});
  const std::vector<MatchedPair> evo = Associate(long_ref, short_est);
  ASSERT_EQ(evo.size(), 2u);
  EXPECT_EQ(evo[0].reference, 1u);
  EXPECT_EQ(evo[1].reference, 1u);
  AssociationOptions greedy;
  greedy.method = AssociationMethod::kTumGreedy;
  const std::vector<MatchedPair> tum = Associate(long_ref, short_est, greedy);
  ASSERT_EQ(tum.size(), 2u);
  EXPECT_EQ(tum[0].reference, 1u);
  EXPECT_EQ(tum[0].estimate, 0u);
  EXPECT_EQ(tum[1].reference, 2u);
  EXPECT_EQ(tum[1].estimate, 1u);
  // A tie goes to the earlier pose, like numpy's argmin.
  const std::vector<MatchedPair> tie = Associate(stamps({0.0, 0.01}), stamps({0.005}));
  ASSERT_EQ(tie.size(), 1u);
  EXPECT_EQ(tie[0].reference, 0u);
}

TEST(Evaluation, RpeOnAKnownScaleDrift) {
  // The estimate walks 10% too far per step: each relative translation is off by 0.1 m.
  std::vector<Eigen::Vector3d> ref_positions, est_positions;
  for (int i = 0; i < 20; ++i) {
    ref_positions.emplace_back(1.0 * i, 0, 0);
    est_positions.emplace_back(1.1 * i, 0, 0);
  }
  EvaluationOptions options;
  options.alignment = Alignment::kNone;
  const Expected<TrajectoryEvaluation> r =
      EvaluateTrajectory(FromPositions(ref_positions), FromPositions(est_positions), options);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->rpe.n, 19u);
  EXPECT_NEAR(r->rpe.rmse, 0.1, 1e-12);
  EXPECT_NEAR(r->rpe.std, 0.0, 1e-12);
  EXPECT_NEAR(r->ate.max, 1.9, 1e-12);
  // On a curved path, Sim3 alignment removes a pure scale drift entirely.
  for (int i = 0; i < 20; ++i) {
    ref_positions[i].y() = std::sin(0.5 * i);
    est_positions[i].y() = 1.1 * std::sin(0.5 * i);
  }
  const Expected<TrajectoryEvaluation> aligned =
      EvaluateTrajectory(FromPositions(ref_positions), FromPositions(est_positions));
  ASSERT_TRUE(aligned.ok()) << aligned.error();
  EXPECT_NEAR(aligned->scale, 1.0 / 1.1, 1e-12);
  EXPECT_LT(aligned->rpe.rmse, 1e-12);
  EXPECT_LT(aligned->ate.rmse, 1e-12);
}

TEST(Evaluation, AlignmentFailuresAreReported) {
  const Trajectory two = FromPositions({{0, 0, 0}, {1, 0, 0}});
  Expected<TrajectoryEvaluation> r = EvaluateTrajectory(two, two);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("sim3 alignment failed"), std::string::npos) << r.error();
  const Trajectory one_place = FromPositions({{1, 2, 3}, {1, 2, 3}, {1, 2, 3}, {1, 2, 3}});
  EXPECT_FALSE(EvaluateTrajectory(one_place, one_place).ok());
  // A straight reference with an estimate collapsed to one place has no scale.
  const Trajectory line = FromPositions({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}});
  EXPECT_FALSE(EvaluateTrajectory(line, one_place).ok());
  EvaluationOptions bad;
  bad.association.max_dt = -1.0;
  EXPECT_FALSE(EvaluateTrajectory(line, line, bad).ok());
  EXPECT_TRUE(ParseAlignment("se3").ok());
  EXPECT_FALSE(ParseAlignment("affine").ok());
}

// A straight walk: 60 poses along x that look around (yaw and pitch change), and an estimate in
// a known similar frame. Positions fix everything but the rotation about the line; the
// orientations fix that, so a map 3 m beside the line is judged right.
TEST(Evaluation, StraightWalkTakesTheRotationAboutItsLineFromTheOrientations) {
  std::vector<TimedPose> poses;
  for (int i = 0; i < 60; ++i) {
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.02 * i, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(0.3 - 0.01 * i, Eigen::Vector3d::UnitY()));
    poses.push_back({i / 30.0, Pose3(q, Eigen::Vector3d(0.01 * i - 1.5, 1.5, 1.6))});
  }
  const Trajectory ref = *Trajectory::FromPoses(poses);
  const Sim3 ref_from_est(
      4.2, Eigen::Quaterniond(Eigen::AngleAxisd(2.0, Eigen::Vector3d(0.3, -1, 0.5).normalized())),
      Eigen::Vector3d(-0.7, 2.0, 0.4));
  const Sim3 est_from_ref = ref_from_est.Inverse();
  // Exact, and with 10 um of lateral noise (in the reference's units) on the estimate.
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 1e-5);
  std::vector<TimedPose> noisy;
  for (const TimedPose& p : ref) {
    const Pose3 shifted(
        p.world_from_camera.rotation(),
        p.world_from_camera.translation() + Eigen::Vector3d(0.0, noise(rng), noise(rng)));
    noisy.push_back({p.timestamp, est_from_ref.TransformPose(shifted)});
  }
  const Trajectory exact_est = Transformed(ref, est_from_ref);
  const Trajectory noisy_est = *Trajectory::FromPoses(noisy);

  std::vector<Eigen::Vector3f> truth;
  for (int i = 0; i < 20; ++i) truth.emplace_back(0.1f * i - 1.0f, 4.5f, 1.6f + 0.05f * i);
  std::vector<MapPoint> map;
  for (VertexId id = 0; id < truth.size(); ++id) {
    map.push_back({id, est_from_ref * truth[id].cast<double>()});
  }
  for (const Trajectory* est : {&exact_est, &noisy_est}) {
    const Expected<TrajectoryEvaluation> r = EvaluateTrajectory(ref, *est);
    ASSERT_TRUE(r.ok()) << r.error();
    EXPECT_NEAR(r->scale, 4.2, 1e-3);
    EXPECT_LT(r->reference_from_estimate.rotation().angularDistance(ref_from_est.rotation()), 1e-3);
    EXPECT_LT(r->ate.rmse, 2e-5);
    const Expected<ErrorStats> map_error = EvaluateMap(map, truth, r->reference_from_estimate);
    ASSERT_TRUE(map_error.ok()) << map_error.error();
    EXPECT_LT(map_error->max, 5e-3);
  }
  // Positions alone (Umeyama) follow the noise about the line: the same map is off by metres.
  std::vector<Eigen::Vector3d> ref_xyz, est_xyz;
  for (size_t i = 0; i < ref.size(); ++i) {
    ref_xyz.push_back(ref[i].world_from_camera.translation());
    est_xyz.push_back(noisy_est[i].world_from_camera.translation());
  }
  const std::optional<Sim3> by_positions = AlignPoints(est_xyz, ref_xyz, true);
  ASSERT_TRUE(by_positions.has_value());
  EXPECT_GT(EvaluateMap(map, truth, *by_positions)->median, 0.1);
}

TEST(Evaluation, MapErrorAfterAKnownSimilarity) {
  std::vector<Eigen::Vector3f> truth;
  for (int i = 0; i < 50; ++i) truth.emplace_back(0.1f * i, std::sin(0.3f * i), 2.0f - 0.05f * i);
  const Sim3 ref_from_est(0.5, Eigen::Quaterniond(Eigen::AngleAxisd(0.9, Eigen::Vector3d::UnitX())),
                          Eigen::Vector3d(1, 2, 3));
  std::vector<MapPoint> map;
  for (VertexId id = 0; id < truth.size(); id += 3) {
    map.push_back({id, ref_from_est.Inverse() * truth[id].cast<double>()});
  }
  Expected<ErrorStats> exact = EvaluateMap(map, truth, ref_from_est);
  ASSERT_TRUE(exact.ok()) << exact.error();
  EXPECT_EQ(exact->n, map.size());
  EXPECT_LT(exact->rmse, 1e-6);
  // Shift every point by 0.2 m (estimate frame) = 0.1 m after the 0.5 scale.
  for (MapPoint& p : map) p.position += Eigen::Vector3d(0, 0, 0.2);
  Expected<ErrorStats> shifted = EvaluateMap(map, truth, ref_from_est);
  ASSERT_TRUE(shifted.ok());
  EXPECT_NEAR(shifted->rmse, 0.1, 1e-6);
  EXPECT_NEAR(shifted->median, 0.1, 1e-6);
  map.push_back({999, Eigen::Vector3d::Zero()});
  EXPECT_FALSE(EvaluateMap(map, truth, ref_from_est).ok());
  EXPECT_EQ(EvaluateMap({}, truth, ref_from_est)->n, 0u);
}

TEST(Evaluation, ReferenceInterpolatedAtEstimateTimes) {
  const Trajectory ref = Wiggle();  // [100, 100 + 199/30]
  std::vector<TimedPose> est;
  for (double t : {99.0, 100.05, 102.0, 200.0}) est.push_back({t, Pose3()});
  const Expected<Trajectory> gt = InterpolateReferenceAt(ref, *Trajectory::FromPoses(est));
  ASSERT_TRUE(gt.ok()) << gt.error();
  ASSERT_EQ(gt->size(), 2u);
  EXPECT_EQ((*gt)[0].timestamp, 100.05);
  EXPECT_EQ((*gt)[1].world_from_camera.translation(), ref.Interpolate(102.0)->translation());
  EXPECT_FALSE(InterpolateReferenceAt(ref, *Trajectory::FromPoses({{1.0, Pose3()}})).ok());
}

}  // namespace
}  // namespace m2s
