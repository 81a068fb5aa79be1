#include "m2s/workbench/runner.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>

extern char** environ;

namespace m2s::workbench {
namespace {

namespace fs = std::filesystem;

// The last non-empty line of a log, for a failed run's message.
std::string LastLine(const std::string& path) {
  std::ifstream in(path);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  return last.empty() ? "no output" : last;
}

CellResult RunCell(const SweepConfig& config, const Cell& cell, const RunnerOptions& options) {
  CellResult row;
  row.cell = cell;
  if (std::string reason = SkipReason(config, cell); !reason.empty()) {
    row.status = "skipped";
    row.message = reason;
    return row;
  }
  const fs::path run_dir = fs::path(options.out_dir) / "runs" / cell.Name(config);
  std::error_code error;
  fs::remove_all(run_dir, error);
  fs::create_directories(run_dir, error);
  if (error) {
    row.status = "failed";
    row.message = "cannot create " + run_dir.string() + ": " + error.message();
    return row;
  }
  std::vector<std::string> argv = {options.client};
  for (std::string& a : ClientArguments(config, cell, run_dir.string())) argv.push_back(a);
  const std::string log = (run_dir / "log.txt").string();
  const CommandResult result = RunCommand(argv, log, config.timeout_s);
  if (result.timed_out) {
    row.status = "timeout";
    row.message = "over " + std::to_string(static_cast<int>(config.timeout_s)) + " s";
    return row;
  }
  if (result.exit_code != 0) {
    row.status = "failed";
    row.message = "exit " + std::to_string(result.exit_code) + ": " + LastLine(log);
    return row;
  }
  Expected<CellResult> read = ReadCellResult(cell, run_dir.string());
  if (!read) {
    row.status = "failed";
    row.message = read.error();
    return row;
  }
  return *read;
}

}  // namespace

Status RunnerOptions::Check() const {
  if (client.empty()) return Status::Error("no m2s_client executable given");
  if (!fs::exists(client)) return Status::Error("m2s_client not found at " + client);
  if (out_dir.empty()) return Status::Error("no output folder given");
  if (jobs < 1 || jobs > 256) return Status::Error("jobs must be in [1, 256]");
  return Status::Ok();
}

CommandResult RunCommand(const std::vector<std::string>& argv, const std::string& log_path,
                         double timeout_s) {
  // coreutils timeout: SIGTERM at the limit, SIGKILL 10 s later; exit 124 (or 137) then.
  std::vector<std::string> command = {"timeout", "--kill-after=10",
                                      std::to_string(std::max(1, static_cast<int>(timeout_s)))};
  command.insert(command.end(), argv.begin(), argv.end());
  std::vector<char*> args;
  for (std::string& a : command) args.push_back(a.data());
  args.push_back(nullptr);

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log_path.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  pid_t pid = 0;
  const int spawned = posix_spawnp(&pid, "timeout", &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  CommandResult result;
  if (spawned != 0) return result;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return result;
  }
  if (WIFEXITED(status)) {
    result.exit_code = WEXITSTATUS(status);
    result.timed_out = result.exit_code == 124 || result.exit_code == 137;
  } else if (WIFSIGNALED(status)) {
    result.exit_code = 128 + WTERMSIG(status);
  }
  return result;
}

std::vector<CellResult> RunSweep(const SweepConfig& config, const RunnerOptions& options) {
  const std::vector<Cell> cells = ExpandCells(config);
  std::vector<CellResult> rows(cells.size());
  std::atomic<size_t> next{0};
  size_t done = 0;
  std::mutex report_mutex;
  auto worker = [&]() {
    for (size_t i = next++; i < cells.size(); i = next++) {
      rows[i] = RunCell(config, cells[i], options);
      std::lock_guard<std::mutex> lock(report_mutex);
      ++done;
      if (options.on_cell_done) options.on_cell_done(rows[i], done, cells.size());
    }
  };
  std::vector<std::thread> threads;
  const size_t workers = std::min<size_t>(static_cast<size_t>(options.jobs), cells.size());
  for (size_t k = 0; k < workers; ++k) threads.emplace_back(worker);
  for (std::thread& t : threads) t.join();
  return rows;
}

}  // namespace m2s::workbench
