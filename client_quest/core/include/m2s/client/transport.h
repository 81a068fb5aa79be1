// Transports: how encoded messages travel between the client and the server. Everything above
// this interface (frame encoding, sessions, map replica) is the same for every transport.
//
//   LcmTransport: any LCM URL (udpm://...?ttl=0, memq://); its own thread handles LCM. With
//     a bus key it seals what it publishes and hands the handler only messages that pass
//     wire::BusOpener (authentic, not replayed, fresh); the others are counted by reason.
//   OnDeviceTransport (on_device_transport.h): the server's session logic in-process.
//
// The handler is called from the transport's thread (LCM) or the server worker (on-device);
// it must not block for long. Publish() is thread-safe and may be called from the handler.
//
//   LcmTransport transport("udpm://239.255.76.67:7667?ttl=0");
//   transport.Start([](const std::string& ch, const uint8_t* data, size_t n) { ... });
//   transport.Publish(wire::kFrameChannel, bytes);
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "m2s/common/bus_auth.h"
#include "m2s/common/status.h"

namespace lcm {
class LCM;
class ReceiveBuffer;
}  // namespace lcm

namespace m2s::client {

using MessageHandler =
    std::function<void(const std::string& channel, const uint8_t* data, size_t size)>;

class Transport {
 public:
  virtual ~Transport() = default;
  // Starts delivering the server's messages (pose, map, session, stats channels) to handler.
  virtual Status Start(MessageHandler handler) = 0;
  virtual Status Publish(const std::string& channel, const std::vector<uint8_t>& bytes) = 0;
  // Stops delivering; idempotent, done by the destructor too.
  virtual void Stop() = 0;
  virtual std::string_view name() const = 0;
  // Messages refused before decoding (authentication, replay, freshness); 0 when the
  // transport checks nothing.
  virtual int64_t refused_messages() const { return 0; }
};

class LcmTransport final : public Transport {
 public:
  explicit LcmTransport(std::string url, wire::BusSecurityOptions security = {});
  ~LcmTransport() override;
  Status Start(MessageHandler handler) override;
  Status Publish(const std::string& channel, const std::vector<uint8_t>& bytes) override;
  void Stop() override;
  std::string_view name() const override { return "lcm"; }
  int64_t refused_messages() const override { return refused_.load(); }
  const std::string& url() const { return url_; }

 private:
  void OnRaw(const lcm::ReceiveBuffer* buffer, const std::string& channel);

  const std::string url_;
  const wire::BusSealer sealer_;
  wire::BusOpener opener_;
  std::atomic<int64_t> refused_{0};
  std::unique_ptr<lcm::LCM> lcm_;
  MessageHandler handler_;
  std::mutex publish_mutex_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace m2s::client
