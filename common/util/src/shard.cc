#include "m2s/common/shard.h"

#include <charconv>

namespace m2s {

uint64_t Fnv1a64(std::string_view bytes) {
  constexpr uint64_t kOffsetBasis = 14695981039346656037ull;
  constexpr uint64_t kPrime = 1099511628211ull;
  uint64_t hash = kOffsetBasis;
  for (const char c : bytes) {
    hash ^= static_cast<uint8_t>(c);
    hash *= kPrime;
  }
  return hash;
}

uint64_t ShardKeyOfGroup(std::string_view group) { return Fnv1a64(group); }

uint64_t ShardKeyOfSession(int64_t session_id) { return Fnv1a64(std::to_string(session_id)); }

Expected<ShardSpec> ShardSpec::Parse(const std::string& text) {
  const auto fail = [&text] {
    return Status::Error("shard \"" + text +
                         "\": expected K/N with 0 <= K < N <= " + std::to_string(kMaxShards));
  };
  const size_t slash = text.find('/');
  if (slash == std::string::npos) return fail();
  ShardSpec spec;
  const char* begin = text.data();
  const char* end = begin + text.size();
  auto k = std::from_chars(begin, begin + slash, spec.index);
  auto n = std::from_chars(begin + slash + 1, end, spec.count);
  if (k.ec != std::errc() || k.ptr != begin + slash || n.ec != std::errc() || n.ptr != end ||
      slash == 0) {
    return fail();
  }
  if (!spec.Check()) return fail();
  return spec;
}

Status ShardSpec::Check() const {
  if (count < 1 || count > kMaxShards || index < 0 || index >= count) {
    return Status::Error("shard " + ToString() +
                         ": expected 0 <= K < N <= " + std::to_string(kMaxShards));
  }
  return Status::Ok();
}

std::string ShardSpec::ToString() const {
  return std::to_string(index) + "/" + std::to_string(count);
}

}  // namespace m2s
