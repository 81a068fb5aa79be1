// The libFuzzer entry point of one target; M2S_FUZZ_FUNCTION names its body (fuzz_targets.h).
#include <cstddef>
#include <cstdint>

#include "fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return m2s::fuzz::M2S_FUZZ_FUNCTION(data, size);
}
