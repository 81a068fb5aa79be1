// Trajectory and map accuracy: timestamp association, ATE with none / SE3 / Sim3 alignment,
// RPE, and map error against the true vertex positions.
//
// The definitions replicate evo (github.com/MichaelGrupp/evo) so that, on the same TUM files,
// EvaluateTrajectory with the defaults (AssociationMethod::kEvo, max_dt 0.01 s, kSim3) gives
// the numbers of `evo_ape tum GT EST -as` (and `evo_rpe tum GT EST -as` for the RPE):
//  * Association (evo.core.sync.associate_trajectories): the trajectory with fewer poses
//    (the estimate when both have the same count) is the "short" one; each of its poses is paired
//    with the pose of the other whose time is nearest (first such index on ties) if the time
//    difference is <= max_dt. A pose of the longer trajectory can be used more than once.
//    AssociationMethod::kTumGreedy is the TUM RGB-D benchmark's associate.py instead: all
//    candidate pairs with |dt| < max_dt, taken greedily by smallest |dt|, each pose used once.
//  * Alignment (evo Trajectory.align, Umeyama 1991 via AlignPoints): the estimated positions of
//    all matched pairs are aligned onto the reference positions with a similarity (kSim3, evo
//    -as), a rigid transform (kSe3, evo -a), or not at all (kNone). One departure: when the
//    reference positions keep within 1e-3 of their length of one line (a straight walk, or its
//    first seconds), positions fix everything but the rotation about that line, and Umeyama's
//    choice of it follows the estimate's noise; that rotation is then taken from the matched
//    orientations (chordal fit), so a map judged with the alignment is not wrong by metres. The
//    ATE is unchanged by it (a rotation about the line moves no point on the line).
//  * ATE (evo APE, translation part): e_i = |t_ref_i - t_aligned_est_i| in metres.
//  * RPE (evo RPE defaults: delta 1 frame, translation part, consecutive pairs of the matched
//    sequence): e_i = |translation((ref_i^-1 ref_i+1)^-1 (est_i^-1 est_i+1))|, computed on the
//    aligned estimate (evo aligns first when -a / -as is given), so a Sim3 scale applies.
//  * Statistics as numpy: rmse = sqrt(mean(e^2)), population std (ddof 0), median of the sorted
//    values (mean of the two middle ones for an even count), sse = sum(e^2).
//
// Stateless functions, safe to call from any thread.
//
//   Expected<TrajectoryEvaluation> result = EvaluateTrajectory(ground_truth, estimate, {});
//   if (result) std::cout << result->ate.rmse << " m at scale " << result->scale << "\n";
#pragma once

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/geometry.h"
#include "m2s/common/status.h"
#include "m2s/common/trajectory.h"
#include "m2s/common/types.h"

namespace m2s {

enum class Alignment { kNone, kSe3, kSim3 };
enum class AssociationMethod { kEvo, kTumGreedy };

// Parses "none", "se3" or "sim3".
Expected<Alignment> ParseAlignment(const std::string& name);
const char* AlignmentName(Alignment alignment);

struct AssociationOptions {
  double max_dt = 0.01;            // seconds; evo's --t_max_diff default
  double estimate_offset_s = 0.0;  // added to the estimate's timestamps (evo --t_offset)
  AssociationMethod method = AssociationMethod::kEvo;

  Status Check() const;
};

struct MatchedPair {
  size_t reference = 0;  // index into the reference trajectory
  size_t estimate = 0;   // index into the estimated trajectory
};

// Pairs in increasing time order of the short trajectory (kEvo) or of the reference
// (kTumGreedy). May be empty.
std::vector<MatchedPair> Associate(const Trajectory& reference, const Trajectory& estimate,
                                   const AssociationOptions& options = {});

struct ErrorStats {
  double rmse = 0.0, mean = 0.0, median = 0.0, std = 0.0, min = 0.0, max = 0.0, sse = 0.0;
  double p95 = 0.0;  // 95th percentile, interpolated between ranks as numpy's default
  size_t n = 0;      // all fields are 0 when n == 0
};
ErrorStats ComputeStats(const std::vector<double>& errors);

struct EvaluationOptions {
  Alignment alignment = Alignment::kSim3;
  AssociationOptions association;

  Status Check() const;
};

struct TrajectoryEvaluation {
  std::vector<MatchedPair> matches;
  // The alignment applied to the estimate: aligned = reference_from_estimate * estimate
  // (identity for kNone; scale 1 for kSe3).
  Sim3 reference_from_estimate;
  double scale = 1.0;              // reference_from_estimate.scale()
  std::vector<double> ate_errors;  // per matched pair, metres
  ErrorStats ate;
  std::vector<double> rpe_errors;  // per consecutive matched pair, metres
  ErrorStats rpe;
};

// Fails when the options are invalid, no timestamps match, or the alignment is impossible
// (for kSe3 / kSim3: fewer than 3 matches, all reference positions at one place, or estimated
// positions on one line where the reference's are not).
Expected<TrajectoryEvaluation> EvaluateTrajectory(const Trajectory& reference,
                                                  const Trajectory& estimate,
                                                  const EvaluationOptions& options = {});

// Several agents' trajectories in one world (the agents of a map group), each with its own
// ground truth in the common ground-truth world.
struct AgentTrajectories {
  Trajectory reference;
  Trajectory estimate;
};

struct GroupEvaluation {
  // The joint alignment: ONE transform for every agent's matched positions together, so the
  // joint ATE is small only when the agents' estimates share one world.
  Sim3 reference_from_estimate;
  double scale = 1.0;
  std::vector<double> ate_errors;  // joint, the agents' matched pairs in order
  ErrorStats ate;
  // Each agent on its own (its own alignment, as EvaluateTrajectory).
  std::vector<TrajectoryEvaluation> agents;
};

// Fails as EvaluateTrajectory for any agent (the message names it) or when the joint alignment
// is impossible.
Expected<GroupEvaluation> EvaluateGroup(const std::vector<AgentTrajectories>& agents,
                                        const EvaluationOptions& options = {});

// The reference interpolated at each timestamp of `estimate` that lies inside the reference's
// time range (other timestamps are dropped): the ground truth to compare a trajectory estimated
// from frames rendered at those times. Fails when no timestamp is inside the range.
Expected<Trajectory> InterpolateReferenceAt(const Trajectory& reference,
                                            const Trajectory& estimate);

struct MapPoint {
  VertexId id = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // in the estimate's frame
};

// Map error: |reference_from_estimate * position - true_positions[id]| per map point (use the
// trajectory's alignment so map and trajectory are judged in one frame). Fails on an id that is
// not a vertex of the scene or a non-finite position; an empty map gives n == 0.
Expected<ErrorStats> EvaluateMap(const std::vector<MapPoint>& map_points,
                                 const std::vector<Eigen::Vector3f>& true_positions,
                                 const Sim3& reference_from_estimate);

}  // namespace m2s
