// Replay of a recorded session: an lcm-logger log is read with the bounds-checked reader of
// common/lcm_log.h (every length checked against the bytes that remain) and its frame and
// session messages are fed, in order, through the server's session logic
// (server_app::SessionManager, synchronous: every frame tracked, deterministic SLAM), as fast
// as possible. The poses and map deltas it publishes are collected like a live client does and
// the same outputs are written (run_outputs.h). A `--fast` live run and its replay give
// identical trajectories.
//
// A truncated or corrupt log is reported with the byte offset where it broke; the events
// before it are used.
//
//   ReplayOptions options{.log_path = "session.lcmlog", .out_dir = "out/replay"};
//   Expected<ReplayResult> result = Replay(options);
#pragma once

#include <cstdint>
#include <string>

#include "m2s/reporting/run_outputs.h"
#include "m2s/server_app/session_manager.h"

namespace m2s::replay {

struct ReplayOptions {
  std::string log_path;
  std::string out_dir = "out";
  std::string mesh_path;  // the scene of the run (map error, map.png); empty: default scene
  bool render_map = true;
  server_app::ServerOptions server;  // synchronous and deterministic are forced on
};

struct ReplayResult {
  reporting::RunMetrics metrics;
  int64_t events = 0;  // log events read
  int64_t frames = 0;  // frame messages fed to the server
  int64_t evaluated_session = 0;
  std::string log_problem;  // empty, or where and how the log broke
  server_app::ServerCounters server;
};

Expected<ReplayResult> Replay(const ReplayOptions& options);

}  // namespace m2s::replay
