// Runs a sweep's cells as m2s_client processes, several at a time.
//
// Each cell runs `m2s_client <ClientArguments>` in out_dir/runs/<cell name>/, its stdout and
// stderr in log.txt there, under a wall-clock limit (coreutils `timeout`, then SIGKILL). Cells
// are independent and deterministic (`--fast`), so running them in parallel changes no figure
// but the wall times; `jobs` bounds the processes at once.
//
//   RunnerOptions options{.client = "build/bin/m2s_client", .out_dir = "out/bench", .jobs = 2};
//   std::vector<CellResult> rows = RunSweep(config, options);
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "m2s/workbench/results.h"
#include "m2s/workbench/sweep.h"

namespace m2s::workbench {

struct RunnerOptions {
  std::string client;   // the m2s_client executable
  std::string out_dir;  // runs/ and the tables go here
  int jobs = 1;
  // Called (from worker threads, one call at a time) when a cell ends.
  std::function<void(const CellResult&, size_t done, size_t total)> on_cell_done;

  Status Check() const;
};

// The exit status of a command run with its output in log_path; -1 when it could not start.
struct CommandResult {
  int exit_code = -1;
  bool timed_out = false;
};
CommandResult RunCommand(const std::vector<std::string>& argv, const std::string& log_path,
                         double timeout_s);

// Every cell of the sweep, in ExpandCells order (a failed run is a row with status "failed"
// and the log's last line; a skipped cell a row with status "skipped").
std::vector<CellResult> RunSweep(const SweepConfig& config, const RunnerOptions& options);

}  // namespace m2s::workbench
