// The solve shared by the optimisation problems without a Schur structure (the Sim3 pose
// graph, the trajectory with a motion prior): sparse normal Cholesky where Ceres has a sparse
// library, dense QR otherwise; silent.
#pragma once

#include <ceres/problem.h>
#include <ceres/solver.h>

namespace m2s::slam::internal {

inline ceres::Solver::Summary SolveSparse(ceres::Problem* problem, int max_iterations) {
  ceres::Solver::Options options;
  options.linear_solver_type =
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ||
              ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::EIGEN_SPARSE)
          ? ceres::SPARSE_NORMAL_CHOLESKY
          : ceres::DENSE_QR;
  options.max_num_iterations = max_iterations;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(options, problem, &summary);
  return summary;
}

}  // namespace m2s::slam::internal
