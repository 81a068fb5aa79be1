// Runs every committed fuzz input through its target (the functions libFuzzer runs): the
// seed corpus (corpus/<target>/*) and the inputs of past findings
// (regressions/<target>_*.bin), so that they are checked in every build, without clang.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "fuzz_targets.h"
#include "m2s/common/bus_auth.h"
#include "m2s/common/camera.h"
#include "m2s/common/lcm_log.h"
#include "m2s/common/wire_format.h"
#include "map/map.h"

namespace m2s::fuzz {
namespace {

namespace fs = std::filesystem;

const fs::path kFuzzDir = fs::path(M2S_SOURCE_DIR) / "tests" / "fuzz";

std::vector<uint8_t> ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)),
                              std::istreambuf_iterator<char>());
}

// The files of a target: its corpus folder and its regression inputs.
std::vector<fs::path> InputsOf(const std::string& target) {
  std::vector<fs::path> inputs;
  const fs::path corpus = kFuzzDir / "corpus" / target;
  if (fs::is_directory(corpus)) {
    for (const auto& entry : fs::directory_iterator(corpus)) inputs.push_back(entry.path());
  }
  for (const auto& entry : fs::directory_iterator(kFuzzDir / "regressions")) {
    if (entry.path().filename().string().rfind(target + "_", 0) == 0) {
      inputs.push_back(entry.path());
    }
  }
  std::sort(inputs.begin(), inputs.end());
  return inputs;
}

class FuzzRegressionTest : public ::testing::TestWithParam<FuzzTarget> {};

TEST_P(FuzzRegressionTest, EveryCommittedInputRunsCleanly) {
  const FuzzTarget& target = GetParam();
  const std::vector<fs::path> inputs = InputsOf(target.name);
  EXPECT_GE(inputs.size(), 2u) << "no seed corpus for " << target.name;
  for (const fs::path& input : inputs) {
    SCOPED_TRACE(input.string());
    const std::vector<uint8_t> bytes = ReadBytes(input);
    EXPECT_EQ(target.run(bytes.data(), bytes.size()), 0);
  }
}

INSTANTIATE_TEST_SUITE_P(Targets, FuzzRegressionTest, ::testing::ValuesIn(kFuzzTargets),
                         [](const ::testing::TestParamInfo<FuzzTarget>& info) {
                           return std::string(info.param.name);
                         });

TEST(FuzzRegressionInputs, EveryRegressionInputHasATarget) {
  for (const auto& entry : fs::directory_iterator(kFuzzDir / "regressions")) {
    const std::string name = entry.path().filename().string();
    EXPECT_TRUE(std::any_of(
        std::begin(kFuzzTargets), std::end(kFuzzTargets),
        [&name](const FuzzTarget& t) { return name.rfind(std::string(t.name) + "_", 0) == 0; }))
        << name;
  }
}

TEST(FuzzRegressionInputs, TheReviewFindingsAreRejected) {
  const std::vector<uint8_t> message =
      ReadBytes(kFuzzDir / "regressions" / "session_control_len_int32_min.bin");
  ASSERT_EQ(message.size(), 120u);  // 115 before session_control_t version 2's map_group
  EXPECT_EQ(wire::DecodeSessionControl(message.data(), message.size()).reason(),
            wire::DropReason::kBadBytes);
  const std::vector<uint8_t> map_file =
      ReadBytes(kFuzzDir / "regressions" / "map_file_count_2pow28.bin");
  ASSERT_EQ(map_file.size(), 148u);
  slam::Map map;
  const Status s = map.LoadFromBytes(map_file.data(), map_file.size(), Camera());
  EXPECT_NE(s.message().find("truncated or corrupt keyframe count 268435456"), std::string::npos)
      << s.message();
}

// The seeds are valid inputs, so that the round trips of the targets run on them.
TEST(FuzzRegressionInputs, TheSeedsAreAccepted) {
  const auto accepted = [](const std::string& target, const std::vector<uint8_t>& b) -> bool {
    if (target == "feature_frame") return wire::DecodeFeatureFrame(b.data(), b.size(), {}).ok();
    if (target == "session_control") return wire::DecodeSessionControl(b.data(), b.size()).ok();
    if (target == "pose_estimate") return wire::DecodePoseEstimate(b.data(), b.size()).ok();
    if (target == "map_delta") return wire::DecodeMapDelta(b.data(), b.size()).ok();
    if (target == "server_stats") return wire::DecodeServerStats(b.data(), b.size()).ok();
    if (target == "map_file") return slam::Map().LoadFromBytes(b.data(), b.size(), Camera()).ok();
    if (target == "lcm_log") {
      wire::LcmLogReader reader(b.data(), b.size());
      wire::LcmLogEvent event;
      return reader.Next(&event);
    }
    const auto key = wire::BusKeyFromBytes(kFuzzBusKeyBytes, sizeof(kFuzzBusKeyBytes));
    wire::BusOpener opener(*key, {.max_age_s = 0});
    return opener.Open(kFuzzBusChannel, b.data(), b.size(), kFuzzBusNowUs).ok();
  };
  for (const FuzzTarget& target : kFuzzTargets) {
    for (const auto& entry : fs::directory_iterator(kFuzzDir / "corpus" / target.name)) {
      EXPECT_TRUE(accepted(target.name, ReadBytes(entry.path()))) << entry.path();
    }
  }
}

}  // namespace
}  // namespace m2s::fuzz
