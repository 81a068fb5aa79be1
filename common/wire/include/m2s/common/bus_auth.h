// Authenticated, replay-proof messages on a shared LCM bus.
//
// LCM itself authenticates nothing: anyone on the network (or the same multicast group) can
// publish any message. With a shared secret (`--key-file`, e.g. `head -c 32 /dev/urandom >
// key`) every message is wrapped in an envelope that carries the sender's random id, a
// per-sender counter, the sender's wall clock and an authentication tag over the channel name,
// the header and the payload (XChaCha20-Poly1305 from libsodium, the payload optionally
// encrypted). A receiver verifies the tag before anything else looks at the bytes, then
// rejects what it has seen before (a sliding window of counters per sender) and what is older
// than `max_age_s` (so a capture cannot be replayed later, even to a freshly started
// receiver). Without a key both ends pass messages through unchanged (the bus is open).
//
// Envelope (big-endian), kEnvelopeOverhead bytes around the payload:
//   "M2SB" | u8 version (1) | u8 flags (bit 0: payload encrypted) | u64 sender | u64 counter
//   | i64 sender wall clock (us) | payload (plain or encrypted) | 16-byte tag
// The AEAD nonce is sender || counter || 0 (unique per key while sender ids are random and
// counters never repeat); the associated data is the channel name, a zero byte and the header.
//
// Thread-safety: BusSealer::Seal and BusOpener::Open may be called from any thread.
//
//   auto key = wire::ReadBusKey("key");                 // Expected<BusKey>
//   wire::BusSealer sealer(*key, /*encrypt=*/false, sender_id);
//   std::vector<uint8_t> sealed = sealer.Seal(channel, bytes.data(), bytes.size());
//   wire::BusOpener opener(*key);
//   auto opened = opener.Open(channel, sealed.data(), sealed.size(), wire::WallClockMicros());
//   if (!opened) counters[opened.reason()]++;   // kNotAuthenticated, kReplayed, kStale, ...
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "m2s/common/wire_format.h"

namespace m2s::wire {

inline constexpr size_t kBusKeyBytes = 32;
inline constexpr size_t kEnvelopeHeaderBytes = 4 + 1 + 1 + 8 + 8 + 8;
inline constexpr size_t kEnvelopeTagBytes = 16;
inline constexpr size_t kEnvelopeOverhead = kEnvelopeHeaderBytes + kEnvelopeTagBytes;

struct BusKey {
  std::array<uint8_t, kBusKeyBytes> bytes{};
};

// The key for the contents of a key file (at least 16 bytes; the key is their BLAKE2b-256
// hash, so any length of random bytes works). Fails with a clear message otherwise.
Expected<BusKey> ReadBusKey(const std::string& path);
// The same from bytes in memory (tests, the headset app's config).
Expected<BusKey> BusKeyFromBytes(const void* data, size_t size);
// A random non-zero 63-bit sender id.
uint64_t RandomSenderId();

// Wraps outgoing messages. Unkeyed: Seal returns the payload unchanged.
class BusSealer {
 public:
  BusSealer(std::optional<BusKey> key, bool encrypt, uint64_t sender_id);
  std::vector<uint8_t> Seal(std::string_view channel, const uint8_t* payload, size_t size,
                            int64_t wall_us) const;
  std::vector<uint8_t> Seal(std::string_view channel, const std::vector<uint8_t>& payload) const;
  bool keyed() const { return key_.has_value(); }
  uint64_t sender_id() const { return sender_id_; }

 private:
  const std::optional<BusKey> key_;
  const bool encrypt_;
  const uint64_t sender_id_;
  mutable std::atomic<uint64_t> counter_{0};
};

struct BusOpenerOptions {
  // Messages whose sender clock differs from ours by more than this are stale (0: no check,
  // for replaying recorded logs).
  double max_age_s = 30.0;
  // Counters accepted out of order behind the highest seen from a sender.
  int replay_window = 1024;
  // Senders remembered at once. Senders idle for longer than max_age_s are forgotten first
  // (their old messages are stale anyway); when every entry is fresh, new senders are refused.
  int max_senders = 4096;
  Status Check() const;
};

// What a process on the bus is configured with (server and clients alike).
struct BusSecurityOptions {
  std::optional<BusKey> key;  // std::nullopt: open bus
  bool encrypt = false;       // encrypt payloads too (keyed only)
  BusOpenerOptions opener;
};

// The options for the command-line flags every program on the bus has: --key-file (empty: an
// open bus), --encrypt (needs a key), --max-message-age (seconds).
Expected<BusSecurityOptions> MakeBusSecurity(const std::string& key_file, bool encrypt,
                                             double max_message_age_s);

// A verified message: who sent it and the payload to decode.
struct OpenedMessage {
  uint64_t sender = 0;  // 0 on an open bus
  const uint8_t* data = nullptr;
  size_t size = 0;
  std::vector<uint8_t> plaintext;  // holds the payload when it was encrypted
};

// Verifies incoming messages. Unkeyed: every message passes, sender 0.
class BusOpener {
 public:
  explicit BusOpener(std::optional<BusKey> key, BusOpenerOptions options = {});
  // Failure reasons: kNotAuthenticated (no envelope, bad tag, another key), kReplayed (counter
  // seen or behind the window), kStale (clock too far off), kTooManySenders.
  Expected<OpenedMessage> Open(std::string_view channel, const uint8_t* data, size_t size,
                               int64_t now_wall_us);
  bool keyed() const { return key_.has_value(); }

 private:
  struct SenderState {
    uint64_t highest = 0;
    std::vector<uint64_t> seen;  // bitmap of counters highest - window + 1 .. highest
    int64_t last_wall_us = 0;
  };
  bool AcceptCounter(SenderState* state, uint64_t counter) const;
  bool MakeRoom(int64_t now_wall_us);

  const std::optional<BusKey> key_;
  const BusOpenerOptions options_;
  std::mutex mutex_;
  std::unordered_map<uint64_t, SenderState> senders_;
};

}  // namespace m2s::wire
