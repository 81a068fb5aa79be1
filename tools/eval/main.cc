// m2s_eval GT.tum EST.tum [--align sim3|se3|none] [--max-dt S] [--offset S] [--greedy] [--json]
//          [--save-errors FILE]
//
// Trajectory accuracy with the definitions of evo (see common/evaluation.h): with the defaults
// the ATE equals `evo_ape tum GT EST -as` and the RPE `evo_rpe tum GT EST -as`. Prints a table,
// or one JSON object with --json. Bad input: one line on stderr and exit code 1.
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "m2s/common/evaluation.h"
#include "m2s/common/trajectory.h"

namespace {

nlohmann::json StatsJson(const m2s::ErrorStats& s) {
  return {{"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"std", s.std},
          {"min", s.min},   {"max", s.max},   {"sse", s.sse},       {"n", s.n}};
}

void PrintRow(const char* name, const m2s::ErrorStats& s) {
  std::printf("%-8s %10.6f %10.6f %10.6f %10.6f %10.6f %10.6f %8zu\n", name, s.rmse, s.mean,
              s.median, s.std, s.min, s.max, s.n);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Trajectory accuracy (ATE, RPE) of an estimate against ground truth, as evo."};
  std::string gt_path, est_path, align_name = "sim3", errors_path;
  double max_dt = 0.01, offset = 0.0;
  bool json = false, greedy = false;
  app.add_option("GT", gt_path, "ground-truth trajectory (TUM format)")->required();
  app.add_option("EST", est_path, "estimated trajectory (TUM format)")->required();
  app.add_option("--align", align_name, "alignment: sim3 (evo -as), se3 (evo -a) or none")
      ->capture_default_str();
  app.add_option("--max-dt", max_dt, "max timestamp difference for association (s)")
      ->capture_default_str();
  app.add_option("--offset", offset, "time offset added to the estimate's timestamps (s)")
      ->capture_default_str();
  app.add_flag("--greedy", greedy,
               "TUM associate.py matching (each pose used once) instead of evo's");
  app.add_flag("--json", json, "print one JSON object");
  app.add_option("--save-errors", errors_path,
                 "write one line per matched pose: estimate timestamp, ATE error [m] after "
                 "alignment (to find where a trajectory goes wrong)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "m2s_eval: " << e.what() << " (see --help)\n";
    return 1;
  }

  auto fail = [](const std::string& message) {
    std::cerr << "m2s_eval: " << message << "\n";
    return 1;
  };
  const m2s::Expected<m2s::Alignment> alignment = m2s::ParseAlignment(align_name);
  if (!alignment) return fail(alignment.error());
  const m2s::Expected<m2s::Trajectory> gt = m2s::ReadTum(gt_path);
  if (!gt) return fail(gt.error());
  const m2s::Expected<m2s::Trajectory> est = m2s::ReadTum(est_path);
  if (!est) return fail(est.error());

  m2s::EvaluationOptions options;
  options.alignment = *alignment;
  options.association.max_dt = max_dt;
  options.association.estimate_offset_s = offset;
  options.association.method =
      greedy ? m2s::AssociationMethod::kTumGreedy : m2s::AssociationMethod::kEvo;
  const m2s::Expected<m2s::TrajectoryEvaluation> result =
      m2s::EvaluateTrajectory(*gt, *est, options);
  if (!result) return fail(result.error());
  if (!errors_path.empty()) {
    std::ofstream out(errors_path);
    if (!out) return fail("cannot write " + errors_path);
    out.precision(17);
    out << "# timestamp ate_error_m\n";
    for (size_t i = 0; i < result->matches.size(); ++i)
      out << (*est)[result->matches[i].estimate].timestamp << " " << result->ate_errors[i] << "\n";
    if (!out) return fail("cannot write " + errors_path);
  }

  if (json) {
    const nlohmann::json out = {{"ate_rmse", result->ate.rmse},
                                {"ate_mean", result->ate.mean},
                                {"ate_median", result->ate.median},
                                {"ate_max", result->ate.max},
                                {"ate_min", result->ate.min},
                                {"ate_std", result->ate.std},
                                {"ate_sse", result->ate.sse},
                                {"rpe_rmse", result->rpe.rmse},
                                {"rpe_mean", result->rpe.mean},
                                {"rpe_max", result->rpe.max},
                                {"scale", result->scale},
                                {"n_matched", result->matches.size()},
                                {"n_reference", gt->size()},
                                {"n_estimate", est->size()},
                                {"alignment", m2s::AlignmentName(*alignment)},
                                {"ate", StatsJson(result->ate)},
                                {"rpe", StatsJson(result->rpe)}};
    std::cout << out.dump() << "\n";
    return 0;
  }
  std::printf(
      "matched %zu of %zu reference / %zu estimated poses (max dt %g s), alignment %s, "
      "scale %.6f\n",
      result->matches.size(), gt->size(), est->size(), max_dt, m2s::AlignmentName(*alignment),
      result->scale);
  std::printf("%-8s %10s %10s %10s %10s %10s %10s %8s\n", "metric", "rmse", "mean", "median", "std",
              "min", "max", "n");
  PrintRow("ATE [m]", result->ate);
  PrintRow("RPE [m]", result->rpe);
  return 0;
}
