// Fuzz target of the bus envelope (common/src/bus_auth.cc): BusOpener::Open with a fixed key.
#include <cstring>
#include <vector>

#include "fuzz_targets.h"
#include "m2s/common/bus_auth.h"
#include "m2s/common/check.h"

namespace m2s::fuzz {
namespace {

uint64_t BigEndianU64(const uint8_t* bytes) {
  uint64_t value = 0;
  for (int i = 0; i < 8; ++i) value = (value << 8) | bytes[i];
  return value;
}

}  // namespace

int FuzzBusEnvelope(const uint8_t* data, size_t size) {
  static const wire::BusKey key =
      *wire::BusKeyFromBytes(kFuzzBusKeyBytes, sizeof(kFuzzBusKeyBytes));
  wire::BusOpenerOptions options;
  options.max_age_s = 0;  // no clock: the committed envelopes stay valid
  wire::BusOpener opener(key, options);
  const auto opened = opener.Open(kFuzzBusChannel, data, size, kFuzzBusNowUs);
  if (!opened) {
    M2S_CHECK(!opened.error().empty());
    return 0;
  }
  // An authentic envelope: header, payload, tag.
  M2S_CHECK(size >= wire::kEnvelopeOverhead && opened->size == size - wire::kEnvelopeOverhead);
  M2S_CHECK(opened->sender != 0 && opened->sender == BigEndianU64(data + 6));
  const bool encrypted = (data[5] & 1) != 0;
  if (!encrypted) {
    M2S_CHECK(opened->data == data + wire::kEnvelopeHeaderBytes);
  }
  // The same envelope again is a replay.
  M2S_CHECK(opener.Open(kFuzzBusChannel, data, size, kFuzzBusNowUs).reason() ==
            wire::DropReason::kReplayed);
  // The first message of a sender seals to the same bytes.
  if (BigEndianU64(data + 14) == 1) {
    const wire::BusSealer sealer(key, encrypted, opened->sender);
    const std::vector<uint8_t> sealed = sealer.Seal(kFuzzBusChannel, opened->data, opened->size,
                                                    static_cast<int64_t>(BigEndianU64(data + 22)));
    M2S_CHECK(sealed.size() == size && std::memcmp(sealed.data(), data, size) == 0);
  }
  return 0;
}

}  // namespace m2s::fuzz
