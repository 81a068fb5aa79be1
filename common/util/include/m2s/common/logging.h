// The one logging function of the libraries. Libraries never print to stdout; they call
// Log(), and the application chooses where messages go (stderr by default) and the level.
// Thread-safe: the sink is called under an internal lock owned by the logger object.
//
//   m2s::SetLogSink([](m2s::LogLevel level, std::string_view msg) { ... });
//   M2S_LOG(kWarning) << "dropped " << n << " frames";
#pragma once

#include <functional>
#include <sstream>
#include <string_view>

namespace m2s {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3 };

using LogSink = std::function<void(LogLevel, std::string_view)>;

// Replaces the sink (nullptr restores the default: stderr). Messages below min_level are dropped.
void SetLogSink(LogSink sink);
void SetMinLogLevel(LogLevel min_level);
void Log(LogLevel level, std::string_view message);

namespace internal {
class LogMessage {
 public:
  explicit LogMessage(LogLevel level) : level_(level) {}
  ~LogMessage() { Log(level_, stream_.str()); }
  std::ostream& stream() { return stream_; }

 private:
  LogLevel level_;
  std::ostringstream stream_;
};
}  // namespace internal

}  // namespace m2s

#define M2S_LOG(level) ::m2s::internal::LogMessage(::m2s::LogLevel::level).stream()
