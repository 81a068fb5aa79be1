// The bodies of the libFuzzer targets: one function per decoder of untrusted bytes. Each one
// decodes the input, checks the contract (a failure leaves no trace; a success survives a
// round trip where one is defined) and aborts on a violation, so that libFuzzer
// (fuzz_main.cc, one executable per target) and fuzz_regression_test (every committed input
// under corpus/ and regressions/, built without clang) run the same code.
//
//   extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
//     return m2s::fuzz::FuzzSessionControl(data, size);
//   }
#pragma once

#include <cstddef>
#include <cstdint>

namespace m2s::fuzz {

int FuzzFeatureFrame(const uint8_t* data, size_t size);
int FuzzSessionControl(const uint8_t* data, size_t size);
int FuzzPoseEstimate(const uint8_t* data, size_t size);
int FuzzMapDelta(const uint8_t* data, size_t size);
int FuzzServerStats(const uint8_t* data, size_t size);
int FuzzMapFile(const uint8_t* data, size_t size);
int FuzzLcmLog(const uint8_t* data, size_t size);
int FuzzBusEnvelope(const uint8_t* data, size_t size);

// A target by name ("session_control" for fuzz_session_control), for the regression test.
struct FuzzTarget {
  const char* name;
  int (*run)(const uint8_t* data, size_t size);
};
inline constexpr FuzzTarget kFuzzTargets[] = {
    {"feature_frame", FuzzFeatureFrame},
    {"session_control", FuzzSessionControl},
    {"pose_estimate", FuzzPoseEstimate},
    {"map_delta", FuzzMapDelta},
    {"server_stats", FuzzServerStats},
    {"map_file", FuzzMapFile},
    {"lcm_log", FuzzLcmLog},
    {"bus_envelope", FuzzBusEnvelope},
};

// The fixed inputs the targets use: the camera of map files, the bus key and channel.
inline constexpr uint8_t kFuzzBusKeyBytes[32] = {
    'm', '2', 's', '-', 'f', 'u', 'z', 'z', '-', 'k', 'e', 'y', '-', '0', '1', '2',
    '3', '4', '5', '6', '7', '8', '9', 'a', 'b', 'c', 'd', 'e', 'f', 'g', 'h', 'i'};
inline constexpr const char* kFuzzBusChannel = "M2S_FRAME";
inline constexpr int64_t kFuzzBusNowUs = 1700000000000000;

}  // namespace m2s::fuzz
