#include "m2s/common/logging.h"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <string>

#include "m2s/common/check.h"

namespace m2s {
namespace {

// The logger is one object with its own lock (not a free-standing global mutex).
class Logger {
 public:
  void SetSink(LogSink sink) {
    std::lock_guard<std::mutex> lock(mutex_);
    sink_ = std::move(sink);
  }
  void SetMinLevel(LogLevel level) { min_level_.store(static_cast<int>(level)); }
  void Write(LogLevel level, std::string_view message) {
    if (static_cast<int>(level) < min_level_.load()) return;
    std::lock_guard<std::mutex> lock(mutex_);
    if (sink_) {
      sink_(level, message);
      return;
    }
    static constexpr const char* kNames[] = {"debug", "info", "warning", "error"};
    std::fprintf(stderr, "[m2s %s] %.*s\n", kNames[static_cast<int>(level)],
                 static_cast<int>(message.size()), message.data());
  }

 private:
  std::mutex mutex_;
  LogSink sink_;
  std::atomic<int> min_level_{static_cast<int>(LogLevel::kInfo)};
};

Logger& TheLogger() {
  static Logger logger;
  return logger;
}

}  // namespace

void SetLogSink(LogSink sink) { TheLogger().SetSink(std::move(sink)); }
void SetMinLogLevel(LogLevel min_level) { TheLogger().SetMinLevel(min_level); }
void Log(LogLevel level, std::string_view message) { TheLogger().Write(level, message); }

namespace internal {

CheckFailure::CheckFailure(const char* file, int line, const char* condition) {
  stream_ << file << ":" << line << ": check failed: " << condition << " ";
}

CheckFailure::~CheckFailure() {
  std::fprintf(stderr, "%s\n", stream_.str().c_str());
  std::fflush(stderr);
  std::abort();
}

}  // namespace internal
}  // namespace m2s
