#include <lcm/lcm-cpp.hpp>

#include "m2s/client/transport.h"
#include "m2s/common/logging.h"
#include "m2s/common/wire_format.h"

namespace m2s::client {
namespace {
constexpr int kHandleTimeoutMs = 50;
}  // namespace

LcmTransport::LcmTransport(std::string url, wire::BusSecurityOptions security)
    : url_(std::move(url)),
      sealer_(security.key, security.encrypt, wire::RandomSenderId()),
      opener_(security.key, security.opener) {}

LcmTransport::~LcmTransport() { Stop(); }

Status LcmTransport::Start(MessageHandler handler) {
  if (lcm_) return Status::Error("LCM transport already started");
  if (!opener_.keyed()) {
    M2S_LOG(kWarning) << "NO BUS KEY: messages on " << url_
                      << " are neither authenticated nor replay-checked; anyone on this LCM "
                         "network can forge poses and end the session. Use --key-file outside "
                         "local development.";
  }
  lcm_ = std::make_unique<lcm::LCM>(url_);
  if (!lcm_->good()) {
    lcm_.reset();
    return Status::Error("cannot open LCM URL '" + url_ + "'");
  }
  handler_ = std::move(handler);
  for (const char* channel :
       {wire::kPoseChannel, wire::kMapChannel, wire::kSessionChannel, wire::kStatsChannel}) {
    lcm_->subscribe(channel, &LcmTransport::OnRaw, this);
  }
  stop_ = false;
  thread_ = std::thread([this] {
    while (!stop_) {
      if (lcm_->handleTimeout(kHandleTimeoutMs) < 0) {
        M2S_LOG(kError) << "LCM receive failed on " << url_;
        break;
      }
    }
  });
  return Status::Ok();
}

Status LcmTransport::Publish(const std::string& channel, const std::vector<uint8_t>& bytes) {
  const std::vector<uint8_t> sealed = sealer_.Seal(channel, bytes);
  std::lock_guard<std::mutex> lock(publish_mutex_);
  if (!lcm_) return Status::Error("LCM transport not started");
  if (lcm_->publish(channel, sealed.data(), static_cast<unsigned int>(sealed.size())) != 0) {
    return Status::Error("LCM publish on " + channel + " failed");
  }
  return Status::Ok();
}

void LcmTransport::Stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  std::lock_guard<std::mutex> lock(publish_mutex_);
  lcm_.reset();
}

void LcmTransport::OnRaw(const lcm::ReceiveBuffer* buffer, const std::string& channel) {
  auto opened = opener_.Open(channel, static_cast<const uint8_t*>(buffer->data), buffer->data_size,
                             wire::WallClockMicros());
  if (!opened) {
    refused_.fetch_add(1);
    return;
  }
  if (handler_) handler_(channel, opened->data, opened->size);
}

}  // namespace m2s::client
