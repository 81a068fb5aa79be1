// Sim3 pose graph on Ceres (drift correction, as ORB-SLAM2's essential graph): nodes are
// world_from_camera similarities on Sim3Manifold, edges RelativeSim3Error, fixed nodes constant,
// the first node held when none is fixed.
#include <array>
#include <cmath>

#include <ceres/problem.h>
#include <ceres/solver.h>

#include "optimization/cost_functions.h"
#include "optimization/problems.h"
#include "optimization/sparse_solver.h"

namespace m2s::slam {

std::array<double, kSim3ParameterSize> Sim3ToParameters(const Sim3& sim3) {
  const Eigen::Quaterniond& q = sim3.rotation();
  const Eigen::Vector3d& t = sim3.translation();
  return {q.x(), q.y(), q.z(), q.w(), t.x(), t.y(), t.z(), std::log(sim3.scale())};
}

Sim3 Sim3FromParameters(const double* p) {
  return Sim3(std::exp(p[7]), Eigen::Quaterniond(p[3], p[0], p[1], p[2]).normalized(),
              Eigen::Vector3d(p[4], p[5], p[6]));
}

Status PoseGraphOptions::Check() const {
  if (max_iterations < 1) {
    return Status::Error("PoseGraphOptions: max_iterations must be at least 1");
  }
  return Status::Ok();
}

namespace {

bool Valid(const Sim3& s) {
  return std::isfinite(s.scale()) && s.scale() > 0.0 && s.rotation().coeffs().allFinite() &&
         s.rotation().norm() > 0.0 && s.translation().allFinite();
}

}  // namespace

PoseGraphResult OptimizePoseGraph(const PoseGraphOptions& options,
                                  std::vector<PoseGraphNode>* nodes,
                                  const std::vector<PoseGraphEdge>& edges) {
  PoseGraphResult result;
  if (nodes == nullptr || !options.Check()) return result;
  const int num_nodes = static_cast<int>(nodes->size());
  for (const PoseGraphNode& node : *nodes) {
    if (!Valid(node.world_from_camera)) return result;
  }
  for (const PoseGraphEdge& edge : edges) {
    if (edge.from_index < 0 || edge.from_index >= num_nodes || edge.to_index < 0 ||
        edge.to_index >= num_nodes || edge.from_index == edge.to_index ||
        !Valid(edge.from_from_to) || !(edge.weight > 0.0) || !std::isfinite(edge.weight)) {
      return result;
    }
  }
  if (edges.empty()) {
    result.success = true;
    return result;
  }

  std::vector<std::array<double, kSim3ParameterSize>> parameters(num_nodes);
  for (int i = 0; i < num_nodes; ++i)
    parameters[i] = Sim3ToParameters((*nodes)[i].world_from_camera);

  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  Sim3Manifold manifold;
  std::vector<bool> in_problem(num_nodes, false);
  for (const PoseGraphEdge& edge : edges) {
    double* from = parameters[edge.from_index].data();
    double* to = parameters[edge.to_index].data();
    problem.AddResidualBlock(RelativeSim3Error::Create(edge.from_from_to, edge.weight), nullptr,
                             from, to);
    for (int index : {edge.from_index, edge.to_index}) {
      if (!in_problem[index]) {
        in_problem[index] = true;
        problem.SetManifold(parameters[index].data(), &manifold);
      }
    }
  }
  bool any_fixed = false;
  for (int i = 0; i < num_nodes; ++i) {
    if (in_problem[i] && (*nodes)[i].fixed) {
      problem.SetParameterBlockConstant(parameters[i].data());
      any_fixed = true;
    }
  }
  if (!any_fixed) {
    for (int i = 0; i < num_nodes; ++i) {
      if (in_problem[i]) {
        problem.SetParameterBlockConstant(parameters[i].data());
        break;
      }
    }
  }

  const ceres::Solver::Summary summary = internal::SolveSparse(&problem, options.max_iterations);
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.success = summary.IsSolutionUsable();
  if (!result.success) return result;
  for (int i = 0; i < num_nodes; ++i) {
    if (in_problem[i] && !(*nodes)[i].fixed) {
      (*nodes)[i].world_from_camera = Sim3FromParameters(parameters[i].data());
    }
  }
  return result;
}

}  // namespace m2s::slam
