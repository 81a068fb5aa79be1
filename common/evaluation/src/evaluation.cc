#include "m2s/common/evaluation.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "m2s/common/alignment.h"

namespace m2s {
namespace {

// evo.core.sync.matching_time_indices: for each short stamp, the nearest long stamp (first on
// ties, as numpy argmin), kept if the difference is <= max_dt.
std::vector<std::pair<size_t, size_t>> NearestMatches(const std::vector<double>& short_stamps,
                                                      const std::vector<double>& long_stamps,
                                                      double max_dt) {
  std::vector<std::pair<size_t, size_t>> matches;
  if (long_stamps.empty()) return matches;
  // Stamps strictly increase, so the nearest is one of the two around the insertion point and
  // taking the lower one on a tie equals argmin's first index.
  for (size_t i = 0; i < short_stamps.size(); ++i) {
    const auto upper = std::lower_bound(long_stamps.begin(), long_stamps.end(), short_stamps[i]);
    size_t best = static_cast<size_t>(upper - long_stamps.begin());
    if (best == long_stamps.size()) --best;
    double best_diff = std::abs(long_stamps[best] - short_stamps[i]);
    if (best > 0 && std::abs(long_stamps[best - 1] - short_stamps[i]) <= best_diff) {
      --best;
      best_diff = std::abs(long_stamps[best] - short_stamps[i]);
    }
    if (best_diff <= max_dt) matches.emplace_back(i, best);
  }
  return matches;
}

// TUM RGB-D associate.py: candidate pairs with |dt| < max_dt, greedily by smallest |dt|.
std::vector<MatchedPair> GreedyMatches(const std::vector<double>& reference,
                                       const std::vector<double>& estimate, double max_dt) {
  struct Candidate {
    double diff;
    size_t reference, estimate;
  };
  std::vector<Candidate> candidates;
  for (size_t i = 0; i < reference.size(); ++i) {
    // Both sorted: only estimates within max_dt of this reference time.
    auto it = std::lower_bound(estimate.begin(), estimate.end(), reference[i] - max_dt);
    for (; it != estimate.end() && *it <= reference[i] + max_dt; ++it) {
      const double diff = std::abs(*it - reference[i]);
      if (diff < max_dt) {
        candidates.push_back({diff, i, static_cast<size_t>(it - estimate.begin())});
      }
    }
  }
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const Candidate& a, const Candidate& b) { return a.diff < b.diff; });
  std::vector<bool> used_reference(reference.size(), false), used_estimate(estimate.size(), false);
  std::vector<MatchedPair> matches;
  for (const Candidate& c : candidates) {
    if (used_reference[c.reference] || used_estimate[c.estimate]) continue;
    used_reference[c.reference] = used_estimate[c.estimate] = true;
    matches.push_back({c.reference, c.estimate});
  }
  std::sort(matches.begin(), matches.end(),
            [](const MatchedPair& a, const MatchedPair& b) { return a.reference < b.reference; });
  return matches;
}

std::vector<double> Stamps(const Trajectory& trajectory, double offset) {
  std::vector<double> stamps;
  stamps.reserve(trajectory.size());
  for (const TimedPose& p : trajectory) stamps.push_back(p.timestamp + offset);
  return stamps;
}

// Matched poses in the order of the matches.
struct MatchedPoses {
  std::vector<Eigen::Vector3d> reference, estimate;         // positions
  std::vector<Eigen::Quaterniond> reference_q, estimate_q;  // orientations

  void Add(const Pose3& ref, const Pose3& est) {
    reference.push_back(ref.translation());
    estimate.push_back(est.translation());
    reference_q.push_back(ref.rotation());
    estimate_q.push_back(est.rotation());
  }
};

// Positions that keep within 1e-3 of their length of one line (a straight walk, or the first
// seconds of one) fix everything but the rotation about that line; Umeyama's answer for it
// follows the estimate's noise, and a map judged with it is wrong by metres.
constexpr double kStraightRatio = 1e-3;

// The mean and principal direction of points, and the ratio of their second principal extent
// to their first (0 when all points coincide).
struct PrincipalLine {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
  double ratio = 0.0;
};

PrincipalLine FindPrincipalLine(const std::vector<Eigen::Vector3d>& points) {
  PrincipalLine line;
  for (const Eigen::Vector3d& p : points) line.mean += p;
  line.mean /= static_cast<double>(points.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : points)
    scatter.noalias() += (p - line.mean) * (p - line.mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter);  // ascending
  const Eigen::Vector3d lambda = eigen.eigenvalues().cwiseMax(0.0);
  line.ratio = lambda(2) > 0.0 ? std::sqrt(lambda(1) / lambda(2)) : 0.0;
  line.axis = eigen.eigenvectors().col(2);
  return line;
}

// The alignment of a straight reference (its principal line `ref`; `est` the estimate's): the
// estimate's line onto the reference's (Umeyama's rotation and scale when it has one, else the
// principal directions), then the rotation about the reference's line that best fits the
// matched orientations in the chordal sense,
// argmax_phi sum_i trace(Rot(a, phi) N_i) with N_i = R0 R_est_i R_ref_i^T, which is
// phi = atan2(B, A) for A = tr N - a^T N a and B = a . (N12 - N21, N20 - N02, N01 - N10).
std::optional<Sim3> AlignStraight(const MatchedPoses& m, const PrincipalLine& ref,
                                  const PrincipalLine& est, const std::optional<Sim3>& umeyama,
                                  bool with_scale) {
  const Eigen::Vector3d& axis = ref.axis;
  Eigen::Matrix3d r0;
  double scale = 1.0;
  if (umeyama) {
    r0 = umeyama->rotation().toRotationMatrix();
    scale = umeyama->scale();
  } else {
    Eigen::Vector3d est_axis = est.axis;
    double along = 0.0, est_spread = 0.0;
    for (size_t i = 0; i < m.reference.size(); ++i) {
      along += (m.reference[i] - ref.mean).dot(axis) * (m.estimate[i] - est.mean).dot(est_axis);
      est_spread += (m.estimate[i] - est.mean).squaredNorm();
    }
    if (along < 0.0) est_axis = -est_axis;
    r0 = Eigen::Quaterniond::FromTwoVectors(est_axis, axis).toRotationMatrix();
    if (with_scale) scale = std::abs(along) / est_spread;
  }
  Eigen::Matrix3d n = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < m.reference_q.size(); ++i) {
    n.noalias() +=
        r0 * m.estimate_q[i].toRotationMatrix() * m.reference_q[i].toRotationMatrix().transpose();
  }
  const double a = n.trace() - axis.dot(n * axis);
  const double b =
      axis.dot(Eigen::Vector3d(n(1, 2) - n(2, 1), n(2, 0) - n(0, 2), n(0, 1) - n(1, 0)));
  const Eigen::Matrix3d r = Eigen::AngleAxisd(std::atan2(b, a), axis).toRotationMatrix() * r0;
  if (!(scale > 0.0) || !std::isfinite(scale) || !r.allFinite()) return std::nullopt;
  return Sim3(scale, Eigen::Quaterniond(r), ref.mean - scale * r * est.mean);
}

// The alignment of matched poses (identity for kNone): Umeyama on the positions (evo's), with
// the rotation about the line taken from the orientations when the reference is straight.
Expected<Sim3> AlignMatched(const MatchedPoses& matched, Alignment kind) {
  if (kind == Alignment::kNone) return Sim3::Identity();
  const bool with_scale = kind == Alignment::kSim3;
  std::optional<Sim3> alignment = AlignPoints(matched.estimate, matched.reference, with_scale);
  if (matched.reference.size() >= 3) {
    const PrincipalLine ref = FindPrincipalLine(matched.reference);
    if (ref.ratio < kStraightRatio) {
      const PrincipalLine est = FindPrincipalLine(matched.estimate);
      if (alignment || est.ratio < kStraightRatio)
        alignment = AlignStraight(matched, ref, est, alignment, with_scale);
    }
  }
  if (!alignment) {
    return Expected<Sim3>::Error(std::string(AlignmentName(kind)) +
                                 " alignment failed: " + std::to_string(matched.reference.size()) +
                                 " matched poses (need at least 3, not all at one place, and an "
                                 "estimate on one line only where the reference is)");
  }
  return *alignment;
}

}  // namespace

Expected<Alignment> ParseAlignment(const std::string& name) {
  if (name == "none") return Alignment::kNone;
  if (name == "se3") return Alignment::kSe3;
  if (name == "sim3") return Alignment::kSim3;
  return Expected<Alignment>::Error("unknown alignment '" + name + "' (none, se3 or sim3)");
}

const char* AlignmentName(Alignment alignment) {
  switch (alignment) {
    case Alignment::kNone:
      return "none";
    case Alignment::kSe3:
      return "se3";
    case Alignment::kSim3:
      return "sim3";
  }
  return "unknown";
}

Status AssociationOptions::Check() const {
  if (!std::isfinite(max_dt) || max_dt < 0.0) {
    return Status::Error("max_dt must be finite and non-negative");
  }
  if (!std::isfinite(estimate_offset_s)) {
    return Status::Error("estimate_offset_s must be finite");
  }
  return Status::Ok();
}

Status EvaluationOptions::Check() const { return association.Check(); }

std::vector<MatchedPair> Associate(const Trajectory& reference, const Trajectory& estimate,
                                   const AssociationOptions& options) {
  const std::vector<double> ref = Stamps(reference, 0.0);
  const std::vector<double> est = Stamps(estimate, options.estimate_offset_s);
  if (options.method == AssociationMethod::kTumGreedy) {
    return GreedyMatches(ref, est, options.max_dt);
  }
  std::vector<MatchedPair> matches;
  const bool estimate_longer = est.size() > ref.size();
  if (estimate_longer) {
    for (const auto& [r, e] : NearestMatches(ref, est, options.max_dt)) matches.push_back({r, e});
  } else {
    for (const auto& [e, r] : NearestMatches(est, ref, options.max_dt)) matches.push_back({r, e});
  }
  return matches;
}

ErrorStats ComputeStats(const std::vector<double>& errors) {
  ErrorStats stats;
  stats.n = errors.size();
  if (errors.empty()) return stats;
  const double n = static_cast<double>(errors.size());
  double sum = 0.0;
  for (double e : errors) {
    sum += e;
    stats.sse += e * e;
  }
  stats.mean = sum / n;
  stats.rmse = std::sqrt(stats.sse / n);
  double var = 0.0;
  for (double e : errors) var += (e - stats.mean) * (e - stats.mean);
  stats.std = std::sqrt(var / n);
  std::vector<double> sorted = errors;
  std::sort(sorted.begin(), sorted.end());
  stats.min = sorted.front();
  stats.max = sorted.back();
  const size_t mid = sorted.size() / 2;
  stats.median = sorted.size() % 2 == 1 ? sorted[mid] : 0.5 * (sorted[mid - 1] + sorted[mid]);
  const double rank = 0.95 * static_cast<double>(sorted.size() - 1);
  const size_t below = static_cast<size_t>(std::floor(rank));
  const size_t above = std::min(below + 1, sorted.size() - 1);
  stats.p95 = sorted[below] + (sorted[above] - sorted[below]) * (rank - static_cast<double>(below));
  return stats;
}

Expected<TrajectoryEvaluation> EvaluateTrajectory(const Trajectory& reference,
                                                  const Trajectory& estimate,
                                                  const EvaluationOptions& options) {
  if (Status s = options.Check(); !s) return s.Prefixed("evaluation: ");
  TrajectoryEvaluation result;
  result.matches = Associate(reference, estimate, options.association);
  if (result.matches.empty()) {
    return Expected<TrajectoryEvaluation>::Error(
        "no matching timestamps between the reference (" + std::to_string(reference.size()) +
        " poses) and the estimate (" + std::to_string(estimate.size()) + " poses) within max_dt " +
        std::to_string(options.association.max_dt) + " s");
  }
  MatchedPoses matched;
  for (const MatchedPair& m : result.matches) {
    matched.Add(reference[m.reference].world_from_camera, estimate[m.estimate].world_from_camera);
  }
  auto alignment = AlignMatched(matched, options.alignment);
  if (!alignment) return alignment.status();
  result.reference_from_estimate = *alignment;
  result.scale = result.reference_from_estimate.scale();

  std::vector<Pose3> ref_poses, aligned;
  for (const MatchedPair& m : result.matches) {
    ref_poses.push_back(reference[m.reference].world_from_camera);
    aligned.push_back(
        result.reference_from_estimate.TransformPose(estimate[m.estimate].world_from_camera));
  }
  for (size_t i = 0; i < aligned.size(); ++i) {
    result.ate_errors.push_back((aligned[i].translation() - ref_poses[i].translation()).norm());
  }
  for (size_t i = 0; i + 1 < aligned.size(); ++i) {
    const Pose3 ref_delta = ref_poses[i].Inverse() * ref_poses[i + 1];
    const Pose3 est_delta = aligned[i].Inverse() * aligned[i + 1];
    result.rpe_errors.push_back((ref_delta.Inverse() * est_delta).translation().norm());
  }
  result.ate = ComputeStats(result.ate_errors);
  result.rpe = ComputeStats(result.rpe_errors);
  return result;
}

Expected<GroupEvaluation> EvaluateGroup(const std::vector<AgentTrajectories>& agents,
                                        const EvaluationOptions& options) {
  if (agents.empty()) return Expected<GroupEvaluation>::Error("no agent trajectories");
  GroupEvaluation result;
  MatchedPoses matched;
  for (size_t a = 0; a < agents.size(); ++a) {
    auto own = EvaluateTrajectory(agents[a].reference, agents[a].estimate, options);
    if (!own) return own.status().Prefixed("agent " + std::to_string(a + 1) + ": ");
    for (const MatchedPair& m : own->matches) {
      matched.Add(agents[a].reference[m.reference].world_from_camera,
                  agents[a].estimate[m.estimate].world_from_camera);
    }
    result.agents.push_back(std::move(*own));
  }
  auto alignment = AlignMatched(matched, options.alignment);
  if (!alignment) return alignment.status().Prefixed("joint: ");
  result.reference_from_estimate = *alignment;
  result.scale = alignment->scale();
  for (size_t i = 0; i < matched.reference.size(); ++i) {
    result.ate_errors.push_back((*alignment * matched.estimate[i] - matched.reference[i]).norm());
  }
  result.ate = ComputeStats(result.ate_errors);
  return result;
}

Expected<Trajectory> InterpolateReferenceAt(const Trajectory& reference,
                                            const Trajectory& estimate) {
  if (reference.empty()) return Expected<Trajectory>::Error("the reference trajectory is empty");
  std::vector<double> times;
  for (const TimedPose& p : estimate) {
    if (p.timestamp >= reference.start_time() && p.timestamp <= reference.end_time()) {
      times.push_back(p.timestamp);
    }
  }
  if (times.empty()) {
    return Expected<Trajectory>::Error("no estimated timestamp lies inside the reference's range");
  }
  return reference.SampleAt(times);
}

Expected<ErrorStats> EvaluateMap(const std::vector<MapPoint>& map_points,
                                 const std::vector<Eigen::Vector3f>& true_positions,
                                 const Sim3& reference_from_estimate) {
  std::vector<double> errors;
  errors.reserve(map_points.size());
  for (const MapPoint& point : map_points) {
    if (point.id >= true_positions.size()) {
      return Expected<ErrorStats>::Error("map point id " + std::to_string(point.id) +
                                         " is not a scene vertex (the scene has " +
                                         std::to_string(true_positions.size()) + ")");
    }
    if (!point.position.allFinite()) {
      return Expected<ErrorStats>::Error("map point " + std::to_string(point.id) +
                                         " has a non-finite position");
    }
    errors.push_back(
        (reference_from_estimate * point.position - true_positions[point.id].cast<double>())
            .norm());
  }
  return ComputeStats(errors);
}

}  // namespace m2s
