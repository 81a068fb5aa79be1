// The bus envelope: authentication, encryption, replay window, freshness and key files. The
// envelope layout is checked against libsodium directly (an independent opening of the
// documented format), not only through BusOpener.
#include "m2s/common/bus_auth.h"

#include <sodium.h>

#include <cstring>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace m2s::wire {
namespace {

constexpr int64_t kNow = 1'800'000'000'000'000;  // a wall clock in microseconds
constexpr uint64_t kSender = 0x1234'5678'9abc'def0ULL;

BusKey Key(uint8_t fill) {
  std::vector<uint8_t> bytes(32, fill);
  return *BusKeyFromBytes(bytes.data(), bytes.size());
}

std::vector<uint8_t> Payload(size_t n) {
  std::vector<uint8_t> p(n);
  for (size_t i = 0; i < n; ++i) p[i] = static_cast<uint8_t>(i * 7 + 3);
  return p;
}

std::vector<uint8_t> Opened(const Expected<OpenedMessage>& m) {
  return std::vector<uint8_t>(m->data, m->data + m->size);
}

uint64_t BigEndian64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | p[i];
  return v;
}

TEST(BusAuthTest, OpenBusPassesMessagesThroughUnchanged) {
  BusSealer sealer(std::nullopt, false, kSender);
  BusOpener opener(std::nullopt);
  const auto payload = Payload(100);
  const auto sealed = sealer.Seal("M2S_FRAME", payload.data(), payload.size(), kNow);
  EXPECT_EQ(sealed, payload);
  auto opened = opener.Open("M2S_FRAME", sealed.data(), sealed.size(), kNow);
  ASSERT_TRUE(opened.ok());
  EXPECT_EQ(opened->sender, 0u);
  EXPECT_EQ(Opened(opened), payload);
  // No replay protection without a key: the same bytes pass again.
  EXPECT_TRUE(opener.Open("M2S_FRAME", sealed.data(), sealed.size(), kNow).ok());
}

TEST(BusAuthTest, EnvelopeLayoutOpensWithLibsodiumDirectly) {
  const BusKey key = Key(5);
  for (bool encrypt : {false, true}) {
    BusSealer sealer(key, encrypt, kSender);
    const auto payload = Payload(333);
    const auto sealed = sealer.Seal("M2S_POSE", payload.data(), payload.size(), kNow);
    ASSERT_EQ(sealed.size(), payload.size() + kEnvelopeOverhead);
    EXPECT_EQ(std::memcmp(sealed.data(), "M2SB", 4), 0);
    EXPECT_EQ(sealed[4], 1);
    EXPECT_EQ(sealed[5], encrypt ? 1 : 0);
    EXPECT_EQ(BigEndian64(sealed.data() + 6), kSender);
    EXPECT_EQ(BigEndian64(sealed.data() + 14), 1u);  // the first counter
    EXPECT_EQ(static_cast<int64_t>(BigEndian64(sealed.data() + 22)), kNow);
    // Independent opening: nonce = sender || counter || 0, AD = channel || 0 || header.
    uint8_t nonce[crypto_aead_xchacha20poly1305_ietf_NPUBBYTES] = {};
    std::memcpy(nonce, sealed.data() + 6, 16);
    std::vector<uint8_t> ad = {'M', '2', 'S', '_', 'P', 'O', 'S', 'E', 0};
    ad.insert(ad.end(), sealed.begin(), sealed.begin() + kEnvelopeHeaderBytes);
    const uint8_t* body = sealed.data() + kEnvelopeHeaderBytes;
    const uint8_t* tag = body + payload.size();
    std::vector<uint8_t> plain(payload.size());
    if (encrypt) {
      EXPECT_NE(std::memcmp(body, payload.data(), payload.size()), 0);  // not in the clear
      ASSERT_EQ(crypto_aead_xchacha20poly1305_ietf_decrypt_detached(
                    plain.data(), nullptr, body, payload.size(), tag, ad.data(), ad.size(), nonce,
                    key.bytes.data()),
                0);
    } else {
      ad.insert(ad.end(), body, body + payload.size());
      // No ciphertext (clen 0); libsodium declares the buffers non-null all the same.
      unsigned char none[1] = {0};
      ASSERT_EQ(crypto_aead_xchacha20poly1305_ietf_decrypt_detached(
                    none, nullptr, none, 0, tag, ad.data(), ad.size(), nonce, key.bytes.data()),
                0);
      plain.assign(body, body + payload.size());
    }
    EXPECT_EQ(plain, payload);
  }
}

TEST(BusAuthTest, AuthenticMessagesOpenOnceEncryptedOrNot) {
  const BusKey key = Key(1);
  for (bool encrypt : {false, true}) {
    BusSealer sealer(key, encrypt, kSender);
    BusOpener opener(key);
    for (size_t n : {size_t{0}, size_t{1}, size_t{16200}}) {
      const auto payload = Payload(n);
      const auto sealed = sealer.Seal("M2S_FRAME", payload.data(), payload.size(), kNow);
      auto opened = opener.Open("M2S_FRAME", sealed.data(), sealed.size(), kNow + 1000);
      ASSERT_TRUE(opened.ok()) << opened.error();
      EXPECT_EQ(opened->sender, kSender);
      EXPECT_EQ(Opened(opened), payload);
      auto again = opener.Open("M2S_FRAME", sealed.data(), sealed.size(), kNow + 2000);
      ASSERT_FALSE(again.ok());
      EXPECT_EQ(again.reason(), DropReason::kReplayed);
    }
  }
}

TEST(BusAuthTest, AnyChangedByteChannelOrKeyFailsAuthentication) {
  const BusKey key = Key(1);
  BusSealer sealer(key, false, kSender);
  const auto payload = Payload(64);
  const auto sealed = sealer.Seal("M2S_SESSION", payload.data(), payload.size(), kNow);
  for (size_t i = 0; i < sealed.size(); ++i) {
    BusOpener opener(key);  // fresh, so nothing is refused as a replay
    auto tampered = sealed;
    tampered[i] ^= 0x01;
    auto opened = opener.Open("M2S_SESSION", tampered.data(), tampered.size(), kNow);
    ASSERT_FALSE(opened.ok()) << "byte " << i;
    EXPECT_EQ(opened.reason(), DropReason::kNotAuthenticated) << "byte " << i;
  }
  BusOpener opener(key);
  EXPECT_EQ(opener.Open("M2S_FRAME", sealed.data(), sealed.size(), kNow).reason(),
            DropReason::kNotAuthenticated);  // moved to another channel
  BusOpener other_key(Key(2));
  EXPECT_EQ(other_key.Open("M2S_SESSION", sealed.data(), sealed.size(), kNow).reason(),
            DropReason::kNotAuthenticated);
  EXPECT_EQ(opener.Open("M2S_SESSION", payload.data(), payload.size(), kNow).reason(),
            DropReason::kNotAuthenticated);  // a bare message on a keyed bus
  for (size_t n = 0; n < kEnvelopeOverhead; ++n) {
    EXPECT_EQ(opener.Open("M2S_SESSION", sealed.data(), n, kNow).reason(),
              DropReason::kNotAuthenticated);
  }
  // The untouched message still opens (none of the above consumed its counter).
  EXPECT_TRUE(opener.Open("M2S_SESSION", sealed.data(), sealed.size(), kNow).ok());
}

TEST(BusAuthTest, ReplayWindowTakesReorderedMessagesOnceAndRefusesOldOnes) {
  const BusKey key = Key(3);
  BusSealer sealer(key, false, kSender);
  BusOpenerOptions options;
  options.replay_window = 64;
  BusOpener opener(key, options);
  const auto payload = Payload(8);
  std::vector<std::vector<uint8_t>> sealed;
  for (int i = 0; i < 200; ++i) {
    sealed.push_back(sealer.Seal("C", payload.data(), payload.size(), kNow));
  }
  auto open = [&](int i) { return opener.Open("C", sealed[i].data(), sealed[i].size(), kNow); };
  // Counters 1..200 are sealed[0..199]. Deliver 100 first, then late ones inside the window.
  EXPECT_TRUE(open(99).ok());
  EXPECT_TRUE(open(50).ok());  // 100 - 51 = 49 behind: inside the 64-wide window
  EXPECT_EQ(open(50).reason(), DropReason::kReplayed);
  EXPECT_EQ(open(20).reason(), DropReason::kReplayed);  // 80 behind: outside the window
  EXPECT_TRUE(open(100).ok());
  EXPECT_TRUE(open(98).ok());
  EXPECT_EQ(open(99).reason(), DropReason::kReplayed);
  // A jump far ahead clears the window; everything behind it is then refused.
  EXPECT_TRUE(open(199).ok());
  EXPECT_EQ(open(101).reason(), DropReason::kReplayed);  // 98 behind
  EXPECT_TRUE(open(150).ok());                           // 49 behind, never seen
  EXPECT_EQ(open(150).reason(), DropReason::kReplayed);
}

TEST(BusAuthTest, SendersHaveIndependentCounters) {
  const BusKey key = Key(4);
  BusSealer a(key, false, 11), b(key, false, 22);
  BusOpener opener(key);
  const auto payload = Payload(4);
  const auto from_a = a.Seal("C", payload.data(), payload.size(), kNow);
  const auto from_b = b.Seal("C", payload.data(), payload.size(), kNow);  // counter 1 too
  EXPECT_EQ(opener.Open("C", from_a.data(), from_a.size(), kNow)->sender, 11u);
  EXPECT_EQ(opener.Open("C", from_b.data(), from_b.size(), kNow)->sender, 22u);
}

TEST(BusAuthTest, StaleMessagesAreRefusedAndFreshnessCanBeTurnedOff) {
  const BusKey key = Key(6);
  BusSealer sealer(key, false, kSender);
  const auto payload = Payload(4);
  BusOpenerOptions options;
  options.max_age_s = 30;
  BusOpener opener(key, options);
  const auto old = sealer.Seal("C", payload.data(), payload.size(), kNow - 31'000'000);
  EXPECT_EQ(opener.Open("C", old.data(), old.size(), kNow).reason(), DropReason::kStale);
  const auto future = sealer.Seal("C", payload.data(), payload.size(), kNow + 31'000'000);
  EXPECT_EQ(opener.Open("C", future.data(), future.size(), kNow).reason(), DropReason::kStale);
  const auto recent = sealer.Seal("C", payload.data(), payload.size(), kNow - 29'000'000);
  EXPECT_TRUE(opener.Open("C", recent.data(), recent.size(), kNow).ok());
  options.max_age_s = 0;
  BusOpener replaying(key, options);
  EXPECT_TRUE(replaying.Open("C", old.data(), old.size(), kNow).ok());
}

TEST(BusAuthTest, SenderTableIsBoundedAndForgetsOnlyIdleSenders) {
  const BusKey key = Key(7);
  BusOpenerOptions options;
  options.max_senders = 3;
  options.max_age_s = 10;
  BusOpener opener(key, options);
  const auto payload = Payload(4);
  auto from = [&](uint64_t sender, int64_t sent_us) {
    return BusSealer(key, false, sender).Seal("C", payload.data(), payload.size(), sent_us);
  };
  for (uint64_t s = 1; s <= 3; ++s) {
    const auto m = from(s, kNow);
    ASSERT_TRUE(opener.Open("C", m.data(), m.size(), kNow).ok());
  }
  const auto fourth = from(4, kNow);
  EXPECT_EQ(opener.Open("C", fourth.data(), fourth.size(), kNow).reason(),
            DropReason::kTooManySenders);
  // Eleven seconds later the first three are idle past the message age: room again, and
  // their old messages are stale rather than new.
  const int64_t later = kNow + 11'000'000;
  const auto fifth = from(5, later);
  EXPECT_TRUE(opener.Open("C", fifth.data(), fifth.size(), later).ok());
  const auto replay_of_1 = from(1, kNow);
  EXPECT_EQ(opener.Open("C", replay_of_1.data(), replay_of_1.size(), later).reason(),
            DropReason::kStale);
}

TEST(BusAuthTest, KeyFilesAreHashedAndShortOnesRefused) {
  const auto dir = std::filesystem::temp_directory_path() / "m2s_bus_auth_test";
  std::filesystem::create_directories(dir);
  const auto write = [&](const std::string& name, const std::string& bytes) {
    std::ofstream(dir / name, std::ios::binary) << bytes;
    return (dir / name).string();
  };
  const std::string random32(32, '\x5a');
  auto a = ReadBusKey(write("a", random32));
  auto b = ReadBusKey(write("b", random32));
  ASSERT_TRUE(a.ok()) << a.error();
  EXPECT_EQ(a->bytes, b->bytes);
  EXPECT_NE(a->bytes, ReadBusKey(write("c", std::string(32, '\x5b')))->bytes);
  // The key is BLAKE2b-256 of the file, keyed with the context string.
  std::array<uint8_t, 32> expected{};
  const char context[] = "mesh2slam bus key v1";
  crypto_generichash(expected.data(), 32, reinterpret_cast<const uint8_t*>(random32.data()), 32,
                     reinterpret_cast<const uint8_t*>(context), sizeof(context) - 1);
  EXPECT_EQ(a->bytes, expected);
  auto short_key = ReadBusKey(write("short", "0123456789"));
  ASSERT_FALSE(short_key.ok());
  EXPECT_NE(short_key.error().find("at least 16"), std::string::npos) << short_key.error();
  EXPECT_FALSE(ReadBusKey((dir / "missing").string()).ok());
  EXPECT_FALSE(MakeBusSecurity("", true, 30).ok());  // --encrypt without a key
  EXPECT_FALSE(MakeBusSecurity("", false, -1).ok());
  auto open_bus = MakeBusSecurity("", false, 30);
  ASSERT_TRUE(open_bus.ok());
  EXPECT_FALSE(open_bus->key.has_value());
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace m2s::wire
