// m2s_eval GT.tum EST.tum [--align sim3|se3|none] [--max-dt S] [--offset S] [--greedy] [--json]
//          [--save-errors FILE]
// m2s_eval --agent GT1.tum EST1.tum --agent GT2.tum EST2.tum ... [same options but --save-errors]
//
// Group mode (--agent, once per agent of a map group): every agent's estimate against its own
// ground truth, all in one ground-truth world. The joint ATE aligns every agent's matched
// positions together with ONE transform (common/evaluation.h EvaluateGroup): it is small only
// when the agents' estimates share one world, as a merged map group's do; each agent's own ATE
// (its own alignment) is reported too.
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

// The --agent pairs as trajectories; the first file that cannot be read fails.
m2s::Expected<std::vector<m2s::AgentTrajectories>> ReadAgents(
    const std::vector<std::string>& files) {
  std::vector<m2s::AgentTrajectories> agents;
  for (size_t i = 0; i + 1 < files.size(); i += 2) {
    m2s::Expected<m2s::Trajectory> gt = m2s::ReadTum(files[i]);
    if (!gt) return gt.status();
    m2s::Expected<m2s::Trajectory> est = m2s::ReadTum(files[i + 1]);
    if (!est) return est.status();
    agents.push_back({std::move(*gt), std::move(*est)});
  }
  return agents;
}

// Group mode: prints the joint and per-agent ATE (table or JSON).
int EvaluateAgents(const std::vector<std::string>& files, const m2s::EvaluationOptions& options,
                   bool json) {
  auto fail = [](const std::string& message) {
    std::cerr << "m2s_eval: " << message << "\n";
    return 1;
  };
  const auto agents = ReadAgents(files);
  if (!agents) return fail(agents.error());
  const m2s::Expected<m2s::GroupEvaluation> group = m2s::EvaluateGroup(*agents, options);
  if (!group) return fail(group.error());
  if (json) {
    nlohmann::json list = nlohmann::json::array();
    for (size_t a = 0; a < group->agents.size(); ++a) {
      const m2s::TrajectoryEvaluation& e = group->agents[a];
      list.push_back({{"gt", files[2 * a]},
                      {"est", files[2 * a + 1]},
                      {"ate_rmse", e.ate.rmse},
                      {"scale", e.scale},
                      {"n_matched", e.matches.size()},
                      {"ate", StatsJson(e.ate)}});
    }
    const nlohmann::json out = {{"alignment", m2s::AlignmentName(options.alignment)},
                                {"joint",
                                 {{"ate_rmse", group->ate.rmse},
                                  {"scale", group->scale},
                                  {"n_matched", group->ate.n},
                                  {"ate", StatsJson(group->ate)}}},
                                {"agents", list}};
    std::cout << out.dump() << "\n";
    return 0;
  }
  std::printf("%zu agents, alignment %s, joint scale %.6f\n", group->agents.size(),
              m2s::AlignmentName(options.alignment), group->scale);
  std::printf("%-8s %10s %10s %10s %10s %10s %10s %8s\n", "ATE [m]", "rmse", "mean", "median",
              "std", "min", "max", "n");
  PrintRow("joint", group->ate);
  for (size_t a = 0; a < group->agents.size(); ++a) {
    PrintRow(("agent " + std::to_string(a + 1)).c_str(), group->agents[a].ate);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Trajectory accuracy (ATE, RPE) of an estimate against ground truth, as evo."};
  std::string gt_path, est_path, align_name = "sim3", errors_path;
  double max_dt = 0.01, offset = 0.0;
  bool json = false, greedy = false;
  std::vector<std::string> agent_files;
  auto* gt_opt = app.add_option("GT", gt_path, "ground-truth trajectory (TUM format)");
  auto* est_opt = app.add_option("EST", est_path, "estimated trajectory (TUM format)");
  auto* agent_opt = app.add_option("--agent", agent_files,
                                   "GT.tum EST.tum of one agent of a map group (repeat per "
                                   "agent): joint ATE under one alignment, and each agent's")
                        ->expected(2)
                        ->take_all();
  agent_opt->excludes(gt_opt)->excludes(est_opt);
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
  if (agent_files.empty() && (gt_path.empty() || est_path.empty())) {
    return fail("give GT.tum EST.tum, or --agent GT.tum EST.tum per agent (see --help)");
  }
  if (!agent_files.empty() && !errors_path.empty()) {
    return fail("--save-errors takes one trajectory, not --agent");
  }
  m2s::EvaluationOptions options;
  options.alignment = *alignment;
  options.association.max_dt = max_dt;
  options.association.estimate_offset_s = offset;
  options.association.method =
      greedy ? m2s::AssociationMethod::kTumGreedy : m2s::AssociationMethod::kEvo;
  if (!agent_files.empty()) return EvaluateAgents(agent_files, options, json);
  const m2s::Expected<m2s::Trajectory> gt = m2s::ReadTum(gt_path);
  if (!gt) return fail(gt.error());
  const m2s::Expected<m2s::Trajectory> est = m2s::ReadTum(est_path);
  if (!est) return fail(est.error());

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
