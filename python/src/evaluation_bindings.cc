// mesh2slam.evaluate_ate / evaluate_rpe: common/evaluation (evo's definitions) on numpy poses.
#include <string>
#include <vector>

#include "bindings.h"
#include "convert.h"
#include "m2s/common/evaluation.h"

namespace m2s::python {
namespace {

using namespace pybind11::literals;

py::dict StatsToDict(const ErrorStats& stats) {
  py::dict dict;
  dict["rmse"] = stats.rmse;
  dict["mean"] = stats.mean;
  dict["median"] = stats.median;
  dict["std"] = stats.std;
  dict["min"] = stats.min;
  dict["max"] = stats.max;
  dict["n"] = stats.n;
  return dict;
}

py::array_t<double> ToArray(const std::vector<double>& values) {
  py::array_t<double> array(static_cast<py::ssize_t>(values.size()));
  for (size_t i = 0; i < values.size(); ++i) array.mutable_at(i) = values[i];
  return array;
}

// Pairs estimate_poses[i] with ground_truth_poses[i] (the same timestamps, index i unless
// given) and evaluates as EvaluateTrajectory: ATE and RPE after the alignment.
TrajectoryEvaluation Evaluate(const py::object& estimate_poses,
                              const py::object& ground_truth_poses, const std::string& align,
                              const py::object& timestamps, Trajectory* estimate) {
  Expected<Alignment> alignment = ParseAlignment(align);
  if (!alignment) RaiseValueError(alignment.status());
  const py::ssize_t n = py::len(estimate_poses);
  py::object times = timestamps;
  if (times.is_none())
    times = py::module_::import("numpy").attr("arange")(n, "dtype"_a = "float64");
  *estimate = TrajectoryFromArrays(times, estimate_poses, "estimate");
  const Trajectory reference = TrajectoryFromArrays(times, ground_truth_poses, "ground truth");
  EvaluationOptions options;
  options.alignment = *alignment;
  options.association.max_dt = 1e-6;  // the same timestamps: pairs by index
  Expected<TrajectoryEvaluation> result = EvaluateTrajectory(reference, *estimate, options);
  if (!result) RaiseValueError(result.status());
  return std::move(*result);
}

}  // namespace

void RegisterEvaluation(py::module_& m) {
  m.def(
      "evaluate_ate",
      [](const py::object& estimate_poses, const py::object& ground_truth_poses,
         const std::string& align, const py::object& timestamps) {
        Trajectory estimate;
        const TrajectoryEvaluation result =
            Evaluate(estimate_poses, ground_truth_poses, align, timestamps, &estimate);
        std::vector<Pose3> aligned;
        for (const MatchedPair& pair : result.matches) {
          aligned.push_back(result.reference_from_estimate.TransformPose(
              estimate[pair.estimate].world_from_camera));
        }
        py::dict dict = StatsToDict(result.ate);
        dict["errors"] = ToArray(result.ate_errors);
        dict["scale"] = result.scale;
        dict["reference_from_estimate"] = MatrixToArray(result.reference_from_estimate.Matrix());
        dict["aligned_poses"] = PosesToArray(aligned);
        return dict;
      },
      py::arg("estimate_poses"), py::arg("ground_truth_poses"), py::arg("align") = "sim3",
      py::arg("timestamps") = py::none(),
      "Absolute trajectory error (evo's APE, translation) of (N,4,4) estimated poses against "
      "(N,4,4) ground truth, pose i with pose i, after a 'sim3', 'se3' or 'none' alignment: "
      "dict of rmse, mean, median, std, min, max, n, errors, scale, reference_from_estimate "
      "(4x4) and aligned_poses (N,4,4).");
  m.def(
      "evaluate_rpe",
      [](const py::object& estimate_poses, const py::object& ground_truth_poses,
         const std::string& align, const py::object& timestamps) {
        Trajectory estimate;
        const TrajectoryEvaluation result =
            Evaluate(estimate_poses, ground_truth_poses, align, timestamps, &estimate);
        py::dict dict = StatsToDict(result.rpe);
        dict["errors"] = ToArray(result.rpe_errors);
        dict["scale"] = result.scale;
        return dict;
      },
      py::arg("estimate_poses"), py::arg("ground_truth_poses"), py::arg("align") = "sim3",
      py::arg("timestamps") = py::none(),
      "Relative pose error (evo's RPE: translation, 1-frame delta) on the aligned estimate: "
      "dict of rmse, mean, median, std, min, max, n, errors, scale.");
}

}  // namespace m2s::python
