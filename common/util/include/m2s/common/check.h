// Programmer-error checks: M2S_CHECK(cond) << "context"; reports and aborts when cond is false.
// Expected failures (bad input, tracking lost, missing files) are returned as values, never
// checked with this macro.
#pragma once

#include <sstream>

namespace m2s::internal {

class CheckFailure {
 public:
  CheckFailure(const char* file, int line, const char* condition);
  [[noreturn]] ~CheckFailure();
  std::ostream& stream() { return stream_; }

 private:
  std::ostringstream stream_;
};

}  // namespace m2s::internal

#define M2S_CHECK(condition) \
  if (condition) {           \
  } else                     \
    ::m2s::internal::CheckFailure(__FILE__, __LINE__, #condition).stream()
