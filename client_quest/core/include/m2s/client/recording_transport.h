// RecordingTransport: wraps another transport and writes every message the client publishes
// (frames and session messages) into an LCM log, in the format lcm-logger writes, so any run
// (on-device included) can be replayed with m2s_replay.
//
// Thread-safety: as Transport (one internal mutex around the log).
//
//   auto inner = std::make_unique<OnDeviceTransport>(server_options);
//   RecordingTransport transport(std::move(inner), "run.lcmlog");
#pragma once

#include <memory>
#include <mutex>
#include <string>

#include "m2s/client/transport.h"

namespace lcm {
class LogFile;
}  // namespace lcm

namespace m2s::client {

class RecordingTransport final : public Transport {
 public:
  RecordingTransport(std::unique_ptr<Transport> inner, std::string log_path);
  ~RecordingTransport() override;
  Status Start(MessageHandler handler) override;  // opens the log too
  Status Publish(const std::string& channel, const std::vector<uint8_t>& bytes) override;
  void Stop() override;
  std::string_view name() const override { return inner_->name(); }
  int64_t refused_messages() const override { return inner_->refused_messages(); }

 private:
  const std::unique_ptr<Transport> inner_;
  const std::string log_path_;
  std::mutex mutex_;
  std::unique_ptr<lcm::LogFile> log_;
  int64_t event_number_ = 0;
};

}  // namespace m2s::client
