// Scale-out of the SLAM server: N server processes on one bus each serve a disjoint share of
// the sessions. The share of a session is picked by a stable hash of its key: the map group's
// name when its HELLO names one (every agent of a group lands on the same server, which holds
// the group's map), else the session id written in decimal ASCII ("1234"). The hash is 64-bit
// FNV-1a (offset basis 14695981039346656037, prime 1099511628211, one byte at a time), the
// same in every process, build and language, so it can be checked against any independent
// implementation; server K of N serves the keys with Fnv1a64(key) % N == K.
//
//   ShardSpec shard = *ShardSpec::Parse("1/3");
//   if (shard.Owns(ShardKeyOfGroup("room-a"))) ...
//
// Thread-safety: values and free functions.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "m2s/common/status.h"

namespace m2s {

// 64-bit FNV-1a of the bytes.
uint64_t Fnv1a64(std::string_view bytes);

// The shard key of a map group (its name) and of a session without a group (its id in
// decimal ASCII, with a '-' for negative ids).
uint64_t ShardKeyOfGroup(std::string_view group);
uint64_t ShardKeyOfSession(int64_t session_id);

// Server `index` of `count` (0 <= index < count); the default serves everything.
struct ShardSpec {
  int index = 0;
  int count = 1;

  // Parses "K/N" (decimal, 0 <= K < N <= kMaxShards).
  static Expected<ShardSpec> Parse(const std::string& text);
  static constexpr int kMaxShards = 1 << 16;

  Status Check() const;
  bool Owns(uint64_t key) const {
    return key % static_cast<uint64_t>(count) == static_cast<uint64_t>(index);
  }
  bool sharded() const { return count > 1; }
  std::string ToString() const;  // "K/N"
};

}  // namespace m2s
