// Shell lines (POSIX sh) for tests that run m2s_server as a process next to its clients.
//
//   script << StartServerLines(Bin("m2s_server") + " --lcm-url URL", dir)
//          << client_command << "\nrc=$?\n"
//          << StopServerLines(dir / "server.rc") << "exit $rc\n";
#pragma once

#include <filesystem>
#include <sstream>
#include <string>

namespace m2s::testing {

// Starts `server_command` in the background, its stderr copied to `dir`/server.log, and
// returns once the server has logged "listening on" (its LCM subscriptions are in place, so a
// client started next is heard from its first message). The wait reads the server's stderr
// through a FIFO: it blocks on the server's own output, no sleep and no polling. Exits the
// script with 91 when the server ended before listening. Sets $server (its pid) and
// $server_log (the process copying the rest of its stderr).
inline std::string StartServerLines(const std::string& server_command,
                                    const std::filesystem::path& dir) {
  const std::filesystem::path fifo = dir / "server.fifo", log = dir / "server.log";
  std::ostringstream lines;
  lines << "rm -f " << fifo << " && mkfifo " << fifo << " || exit 92\n"
        << server_command << " 2> " << fifo << " &\n"
        << "server=$!\n"
        << "exec 3< " << fifo << "\n"
        << "listening=0\n"
        << "while IFS= read -r line <&3; do\n"
        << "  printf '%s\\n' \"$line\" >> " << log << "\n"
        << "  case \"$line\" in *'listening on'*) listening=1; break;; esac\n"
        << "done\n"
        << "cat <&3 >> " << log << " &\n"
        << "server_log=$!\n"
        << "exec 3<&-\n"
        << "[ $listening = 1 ] || { wait $server; wait $server_log; exit 91; }\n";
  return lines.str();
}

// Stops the server of StartServerLines() with SIGTERM and waits for it and for its log; its
// exit status goes to `rc_file` when that is not empty.
inline std::string StopServerLines(const std::filesystem::path& rc_file = {}) {
  std::ostringstream lines;
  lines << "kill -TERM $server\nwait $server\n";
  if (!rc_file.empty()) lines << "echo $? > " << rc_file << "\n";
  lines << "wait $server_log\n";
  return lines.str();
}

}  // namespace m2s::testing
