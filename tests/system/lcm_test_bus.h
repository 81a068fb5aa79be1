// The LCM bus of the in-process system tests: UDP multicast on the loopback of a private
// network namespace, which the test process enters once (unshare(CLONE_NEWNET)). Tests skip
// with one line where namespaces are not permitted.
#pragma once

#include <sched.h>

#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <mutex>
#include <string>

#include <gtest/gtest.h>

#include "m2s/client/transport.h"
#include "m2s/common/wire_format.h"
#include "m2s/server_app/lcm_server.h"

namespace m2s::testing {

inline constexpr const char* kTestLcmUrl = "udpm://239.255.76.67:7667?ttl=0";

// Enters a private network namespace with multicast routed over loopback, once per process;
// returns why that failed ("" when it worked).
inline const std::string& NetworkProblem() {
  static const std::string problem = [] {
    if (unshare(CLONE_NEWNET) != 0) return std::string("unshare(CLONE_NEWNET) not permitted");
    if (std::system("ip link set lo up && ip route add 224.0.0.0/4 dev lo") != 0) {
      return std::string("cannot set up loopback multicast in the namespace");
    }
    return std::string();
  }();
  return problem;
}

// An LCM server on the test bus, publishing its statistics every 0.2 s.
inline server_app::LcmServerOptions TestServerOptions() {
  server_app::LcmServerOptions options;
  options.lcm_url = kTestLcmUrl;
  options.stats_period_s = 0.2;
  options.log_stats = false;
  options.server.drop_log_period_s = 100;
  return options;
}

// How long a test waits for another thread before it gives up and fails (never reached when
// the code works: it only turns a hang into a failure).
inline constexpr std::chrono::seconds kGiveUp{60};

// A count that threads raise and wait on.
class WaitableCount {
 public:
  void Add() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++value_;
    }
    cv_.notify_all();
  }
  // False when the count did not reach `n` within kGiveUp.
  bool WaitAtLeast(int n) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, kGiveUp, [&] { return value_ >= n; });
  }
  int value() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return value_;
  }

 private:
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  int value_ = 0;
};

// An LcmTransport that tells the test about the SESSION_ENDED messages it receives: each is
// counted in `session_ends` after the session handled it, or dropped before the session sees it
// when `drop_session_ends` (a server that vanished without a word).
class SessionEndTransport final : public client::Transport {
 public:
  SessionEndTransport(std::string url, bool drop_session_ends)
      : inner_(std::move(url)), drop_(drop_session_ends) {}
  Status Start(client::MessageHandler handler) override {
    return inner_.Start(
        [this, handler](const std::string& channel, const uint8_t* data, size_t size) {
          bool end = false;
          if (channel == wire::kSessionChannel) {
            auto message = wire::DecodeSessionControl(data, size);
            end = message && message->type == session_control_t::SESSION_ENDED;
          }
          if (!(end && drop_)) handler(channel, data, size);
          if (end) session_ends.Add();
        });
  }
  Status Publish(const std::string& channel, const std::vector<uint8_t>& bytes) override {
    return inner_.Publish(channel, bytes);
  }
  void Stop() override { inner_.Stop(); }
  std::string_view name() const override { return "lcm (session ends watched)"; }

  WaitableCount session_ends;

 private:
  client::LcmTransport inner_;
  const bool drop_;
};

}  // namespace m2s::testing

#define M2S_REQUIRE_NETWORK()                                          \
  if (!::m2s::testing::NetworkProblem().empty()) {                     \
    GTEST_SKIP() << "skipped: network namespaces not permitted here (" \
                 << ::m2s::testing::NetworkProblem() << ")";           \
  }
