#include "m2s/common/bus_auth.h"

#include <sodium.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>

namespace m2s::wire {
namespace {

constexpr uint8_t kMagic[4] = {'M', '2', 'S', 'B'};
constexpr uint8_t kEnvelopeVersion = 1;
constexpr uint8_t kFlagEncrypted = 1;
constexpr size_t kMinKeyFileBytes = 16;
constexpr size_t kMaxKeyFileBytes = 4096;
// Domain separation of the key derivation.
constexpr char kKeyContext[] = "mesh2slam bus key v1";

static_assert(kEnvelopeTagBytes == crypto_aead_xchacha20poly1305_ietf_ABYTES);
static_assert(kBusKeyBytes == crypto_aead_xchacha20poly1305_ietf_KEYBYTES);

bool SodiumReady() {
  static const bool ready = sodium_init() >= 0;
  return ready;
}

void PutU64(uint8_t* out, uint64_t value) {
  for (int i = 7; i >= 0; --i) {
    out[i] = static_cast<uint8_t>(value);
    value >>= 8;
  }
}

uint64_t GetU64(const uint8_t* in) {
  uint64_t value = 0;
  for (int i = 0; i < 8; ++i) value = (value << 8) | in[i];
  return value;
}

std::array<uint8_t, crypto_aead_xchacha20poly1305_ietf_NPUBBYTES> Nonce(uint64_t sender,
                                                                        uint64_t counter) {
  std::array<uint8_t, crypto_aead_xchacha20poly1305_ietf_NPUBBYTES> nonce{};
  PutU64(nonce.data(), sender);
  PutU64(nonce.data() + 8, counter);
  return nonce;
}

// Associated data: channel, a zero byte, the envelope header.
std::vector<uint8_t> AssociatedData(std::string_view channel, const uint8_t* header) {
  std::vector<uint8_t> ad(channel.size() + 1 + kEnvelopeHeaderBytes);
  std::memcpy(ad.data(), channel.data(), channel.size());
  ad[channel.size()] = 0;
  std::memcpy(ad.data() + channel.size() + 1, header, kEnvelopeHeaderBytes);
  return ad;
}

}  // namespace

Expected<BusKey> BusKeyFromBytes(const void* data, size_t size) {
  if (size < kMinKeyFileBytes) {
    return Status::Error("bus key: " + std::to_string(size) + " bytes, need at least " +
                         std::to_string(kMinKeyFileBytes) +
                         " random bytes (head -c 32 /dev/urandom > key)");
  }
  if (!SodiumReady()) return Status::Error("bus key: libsodium failed to initialise");
  BusKey key;
  crypto_generichash(key.bytes.data(), key.bytes.size(), static_cast<const uint8_t*>(data), size,
                     reinterpret_cast<const uint8_t*>(kKeyContext), sizeof(kKeyContext) - 1);
  return key;
}

Expected<BusKey> ReadBusKey(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error("cannot open key file " + path);
  std::vector<char> bytes;
  bytes.reserve(kBusKeyBytes);
  char c = 0;
  while (bytes.size() <= kMaxKeyFileBytes && in.get(c)) bytes.push_back(c);
  if (bytes.size() > kMaxKeyFileBytes) {
    return Status::Error("key file " + path + " is larger than " +
                         std::to_string(kMaxKeyFileBytes) + " bytes; is it the right file?");
  }
  auto key = BusKeyFromBytes(bytes.data(), bytes.size());
  if (!key) return Status::Error("key file " + path + ": " + key.error());
  return key;
}

uint64_t RandomSenderId() {
  SodiumReady();
  uint64_t id = 0;
  while (id == 0) {
    randombytes_buf(&id, sizeof(id));
    id >>= 1;
  }
  return id;
}

Expected<BusSecurityOptions> MakeBusSecurity(const std::string& key_file, bool encrypt,
                                             double max_message_age_s) {
  BusSecurityOptions security;
  security.opener.max_age_s = max_message_age_s;
  if (Status s = security.opener.Check(); !s) return s.Prefixed("--max-message-age: ");
  if (encrypt && key_file.empty()) return Status::Error("--encrypt needs --key-file");
  security.encrypt = encrypt;
  if (!key_file.empty()) {
    auto key = ReadBusKey(key_file);
    if (!key) return key.status();
    security.key = *key;
  }
  return security;
}

BusSealer::BusSealer(std::optional<BusKey> key, bool encrypt, uint64_t sender_id)
    : key_(std::move(key)), encrypt_(encrypt), sender_id_(sender_id) {
  SodiumReady();
}

std::vector<uint8_t> BusSealer::Seal(std::string_view channel,
                                     const std::vector<uint8_t>& payload) const {
  return Seal(channel, payload.data(), payload.size(), WallClockMicros());
}

std::vector<uint8_t> BusSealer::Seal(std::string_view channel, const uint8_t* payload, size_t size,
                                     int64_t wall_us) const {
  if (!key_) return std::vector<uint8_t>(payload, payload + size);
  const uint64_t counter = counter_.fetch_add(1) + 1;
  std::vector<uint8_t> out(kEnvelopeOverhead + size);
  uint8_t* header = out.data();
  std::memcpy(header, kMagic, sizeof(kMagic));
  header[4] = kEnvelopeVersion;
  header[5] = encrypt_ ? kFlagEncrypted : 0;
  PutU64(header + 6, sender_id_);
  PutU64(header + 14, counter);
  PutU64(header + 22, static_cast<uint64_t>(wall_us));
  const auto nonce = Nonce(sender_id_, counter);
  uint8_t* body = out.data() + kEnvelopeHeaderBytes;
  uint8_t* tag = body + size;
  std::vector<uint8_t> ad = AssociatedData(channel, header);
  if (encrypt_) {
    crypto_aead_xchacha20poly1305_ietf_encrypt_detached(body, tag, nullptr, payload, size,
                                                        ad.data(), ad.size(), nullptr, nonce.data(),
                                                        key_->bytes.data());
  } else {
    if (size > 0) std::memcpy(body, payload, size);
    ad.insert(ad.end(), payload, payload + size);
    uint8_t no_ciphertext = 0;  // libsodium wants a valid pointer even for 0 bytes
    crypto_aead_xchacha20poly1305_ietf_encrypt_detached(&no_ciphertext, tag, nullptr, nullptr, 0,
                                                        ad.data(), ad.size(), nullptr, nonce.data(),
                                                        key_->bytes.data());
  }
  return out;
}

Status BusOpenerOptions::Check() const {
  if (!(max_age_s >= 0) || !std::isfinite(max_age_s))
    return Status::Error("max_age_s must be >= 0");
  if (replay_window < 64 || replay_window > (1 << 16)) {
    return Status::Error("replay_window must be in [64, 65536]");
  }
  if (max_senders <= 0) return Status::Error("max_senders must be positive");
  return Status::Ok();
}

BusOpener::BusOpener(std::optional<BusKey> key, BusOpenerOptions options)
    : key_(std::move(key)), options_(options) {
  SodiumReady();
}

Expected<OpenedMessage> BusOpener::Open(std::string_view channel, const uint8_t* data, size_t size,
                                        int64_t now_wall_us) {
  OpenedMessage opened;
  if (!key_) {
    opened.data = data;
    opened.size = size;
    return opened;
  }
  if (size < kEnvelopeOverhead || std::memcmp(data, kMagic, sizeof(kMagic)) != 0) {
    return Expected<OpenedMessage>::Error(
        DropReason::kNotAuthenticated,
        "message on " + std::string(channel) + " without an envelope");
  }
  const uint8_t* header = data;
  if (header[4] != kEnvelopeVersion || (header[5] & ~kFlagEncrypted) != 0) {
    return Expected<OpenedMessage>::Error(DropReason::kNotAuthenticated,
                                          "envelope version or flags unknown");
  }
  const bool encrypted = (header[5] & kFlagEncrypted) != 0;
  const uint64_t sender = GetU64(header + 6);
  const uint64_t counter = GetU64(header + 14);
  const int64_t sent_us = static_cast<int64_t>(GetU64(header + 22));
  const size_t body_size = size - kEnvelopeOverhead;
  const uint8_t* body = data + kEnvelopeHeaderBytes;
  const uint8_t* tag = body + body_size;
  const auto nonce = Nonce(sender, counter);
  std::vector<uint8_t> ad = AssociatedData(channel, header);
  int verified = -1;
  if (encrypted) {
    opened.plaintext.resize(body_size);
    verified = crypto_aead_xchacha20poly1305_ietf_decrypt_detached(
        opened.plaintext.data(), nullptr, body, body_size, tag, ad.data(), ad.size(), nonce.data(),
        key_->bytes.data());
  } else {
    ad.insert(ad.end(), body, body + body_size);
    const uint8_t no_ciphertext = 0;  // libsodium wants a valid pointer even for 0 bytes
    verified = crypto_aead_xchacha20poly1305_ietf_decrypt_detached(
        nullptr, nullptr, &no_ciphertext, 0, tag, ad.data(), ad.size(), nonce.data(),
        key_->bytes.data());
  }
  if (verified != 0 || sender == 0 || counter == 0) {
    return Expected<OpenedMessage>::Error(
        DropReason::kNotAuthenticated,
        "message on " + std::string(channel) +
            " fails authentication (forged, corrupt, or another key)");
  }
  if (options_.max_age_s > 0) {
    const double age_s =
        std::abs(static_cast<double>(now_wall_us) - static_cast<double>(sent_us)) * 1e-6;
    if (age_s > options_.max_age_s) {
      return Expected<OpenedMessage>::Error(
          DropReason::kStale,
          "message on " + std::string(channel) + " sent " + std::to_string(age_s) + " s from now");
    }
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = senders_.find(sender);
    if (it == senders_.end()) {
      if (!MakeRoom(now_wall_us)) {
        return Expected<OpenedMessage>::Error(
            DropReason::kTooManySenders,
            "sender table full (" + std::to_string(options_.max_senders) + " fresh senders)");
      }
      it = senders_.emplace(sender, SenderState{}).first;
      it->second.seen.assign(static_cast<size_t>(options_.replay_window + 63) / 64, 0);
    }
    if (!AcceptCounter(&it->second, counter)) {
      return Expected<OpenedMessage>::Error(DropReason::kReplayed,
                                            "message on " + std::string(channel) + " from sender " +
                                                std::to_string(sender) + " replayed");
    }
    it->second.last_wall_us = now_wall_us;
  }
  opened.sender = sender;
  if (encrypted) {
    opened.data = opened.plaintext.data();
    opened.size = opened.plaintext.size();
  } else {
    opened.data = body;
    opened.size = body_size;
  }
  return opened;
}

// Sliding window: bit (c % window) of `seen` marks counter c, for c in (highest - window,
// highest]. A counter ahead of the window clears the bits of the counters it skips.
bool BusOpener::AcceptCounter(SenderState* state, uint64_t counter) const {
  const uint64_t window = static_cast<uint64_t>(state->seen.size()) * 64;
  auto bit = [&](uint64_t c) -> std::pair<uint64_t&, uint64_t> {
    const uint64_t slot = c % window;
    return {state->seen[slot / 64], uint64_t{1} << (slot % 64)};
  };
  if (counter > state->highest) {
    const uint64_t advance = counter - state->highest;
    if (advance >= window) {
      std::fill(state->seen.begin(), state->seen.end(), 0);
    } else {
      for (uint64_t c = state->highest + 1; c < counter; ++c) {
        auto [word, mask] = bit(c);
        word &= ~mask;
      }
    }
    state->highest = counter;
    auto [word, mask] = bit(counter);
    word |= mask;
    return true;
  }
  if (state->highest - counter >= window) return false;  // behind the window
  auto [word, mask] = bit(counter);
  if (word & mask) return false;
  word |= mask;
  return true;
}

bool BusOpener::MakeRoom(int64_t now_wall_us) {
  if (static_cast<int>(senders_.size()) < options_.max_senders) return true;
  if (options_.max_age_s > 0) {
    const int64_t max_idle_us = static_cast<int64_t>(options_.max_age_s * 1e6);
    for (auto it = senders_.begin(); it != senders_.end();) {
      it = now_wall_us - it->second.last_wall_us > max_idle_us ? senders_.erase(it) : std::next(it);
    }
    return static_cast<int>(senders_.size()) < options_.max_senders;
  }
  // Without a freshness check nothing is safe to forget; the least recently seen goes.
  auto oldest = std::min_element(
      senders_.begin(), senders_.end(),
      [](const auto& a, const auto& b) { return a.second.last_wall_us < b.second.last_wall_us; });
  senders_.erase(oldest);
  return true;
}

}  // namespace m2s::wire
