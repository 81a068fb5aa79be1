#include "m2s/client/recording_transport.h"

#include <lcm/lcm-cpp.hpp>

#include "m2s/common/wire_format.h"

namespace m2s::client {

RecordingTransport::RecordingTransport(std::unique_ptr<Transport> inner, std::string log_path)
    : inner_(std::move(inner)), log_path_(std::move(log_path)) {}

RecordingTransport::~RecordingTransport() { Stop(); }

Status RecordingTransport::Start(MessageHandler handler) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    log_ = std::make_unique<lcm::LogFile>(log_path_, "w");
    if (!log_->good()) {
      log_.reset();
      return Status::Error("cannot write log " + log_path_);
    }
  }
  return inner_->Start(std::move(handler));
}

Status RecordingTransport::Publish(const std::string& channel, const std::vector<uint8_t>& bytes) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (log_) {
      lcm::LogEvent event;
      event.eventnum = event_number_++;
      event.timestamp = wire::WallClockMicros();
      event.channel = channel;
      event.datalen = static_cast<int32_t>(bytes.size());
      event.data = const_cast<uint8_t*>(bytes.data());
      if (log_->writeEvent(&event) != 0) return Status::Error("cannot write log " + log_path_);
    }
  }
  return inner_->Publish(channel, bytes);
}

void RecordingTransport::Stop() {
  inner_->Stop();
  std::lock_guard<std::mutex> lock(mutex_);
  log_.reset();
}

}  // namespace m2s::client
