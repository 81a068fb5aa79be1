// The shard hash (common/shard.h): 64-bit FNV-1a, checked against values computed
// independently in Python (tests/data/shard/make_fnv1a64.py), so two processes, builds or
// languages agree on which server serves a key; balance over 1000 keys; the K/N parser.
#include "m2s/common/shard.h"

#include <cmath>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace m2s {
namespace {

TEST(ShardTest, Fnv1aMatchesTheIndependentPythonValues) {
  std::ifstream in(std::string(M2S_SOURCE_DIR) + "/tests/data/shard/fnv1a64.txt");
  ASSERT_TRUE(in) << "tests/data/shard/fnv1a64.txt";
  std::string line;
  int checked = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const size_t close = line.rfind('"');
    ASSERT_NE(close, 0u) << line;
    const std::string key = line.substr(1, close - 1);
    const uint64_t expected = std::stoull(line.substr(close + 2));
    EXPECT_EQ(Fnv1a64(key), expected) << key;
    EXPECT_EQ(ShardKeyOfGroup(key), expected) << key;
    ++checked;
  }
  EXPECT_EQ(checked, 12);
  // Session ids hash as their decimal text (the file holds "1234", "-5" and the extremes).
  EXPECT_EQ(ShardKeyOfSession(1234), 2282126479029740061ull);
  EXPECT_EQ(ShardKeyOfSession(-5), 562966479190349815ull);
  EXPECT_EQ(ShardKeyOfSession(INT64_MIN), 6683966621886827385ull);
  // The published FNV-1a test vector (offset basis for "", 0xaf63dc4c8601ec8c for "a").
  EXPECT_EQ(Fnv1a64(""), 0xcbf29ce484222325ull);
  EXPECT_EQ(Fnv1a64("a"), 0xaf63dc4c8601ec8cull);
}

// 1000 group names and 1000 random session ids over N = 2, 3, 4 servers: every server gets
// 1000 / N keys within 4 standard deviations of a uniform random assignment, 4 sqrt(1000 p
// (1 - p)) with p = 1 / N: 63, 60 and 55 keys (measured: at most 2.41 of them, 33 keys, ids over 4
// servers).
TEST(ShardTest, KeysSpreadEvenlyOverTheServers) {
  std::vector<uint64_t> groups, sessions;
  std::mt19937_64 rng(1);
  for (int i = 0; i < 1000; ++i) {
    groups.push_back(ShardKeyOfGroup("agent-" + std::to_string(i)));
    sessions.push_back(ShardKeyOfSession(static_cast<int64_t>(rng() >> 1)));
  }
  for (const auto* keys : {&groups, &sessions}) {
    for (int n = 2; n <= 4; ++n) {
      std::vector<int> served(n, 0);
      for (uint64_t key : *keys) {
        int owners = 0;
        for (int k = 0; k < n; ++k) {
          if (ShardSpec{k, n}.Owns(key)) {
            ++served[k];
            ++owners;
          }
        }
        ASSERT_EQ(owners, 1);  // exactly one server of N owns every key
      }
      for (int k = 0; k < n; ++k) {
        const double p = 1.0 / n;
        EXPECT_NEAR(served[k], 1000.0 * p, 4.0 * std::sqrt(1000.0 * p * (1.0 - p)))
            << "shard " << k << "/" << n;
      }
    }
  }
}

TEST(ShardTest, ParsesKOverNAndRefusesTheRest) {
  auto spec = ShardSpec::Parse("1/3");
  ASSERT_TRUE(spec.ok()) << spec.error();
  EXPECT_EQ(spec->index, 1);
  EXPECT_EQ(spec->count, 3);
  EXPECT_EQ(spec->ToString(), "1/3");
  EXPECT_TRUE(ShardSpec::Parse("0/1").ok());
  EXPECT_FALSE(ShardSpec().sharded());
  for (const char* bad : {"", "3/3", "-1/2", "1/0", "1", "/2", "1/", "a/2", "1/2x", "0/65537"}) {
    EXPECT_FALSE(ShardSpec::Parse(bad).ok()) << bad;
  }
  EXPECT_TRUE(ShardSpec().Check().ok());
  EXPECT_FALSE((ShardSpec{2, 2}.Check().ok()));
}

}  // namespace
}  // namespace m2s
