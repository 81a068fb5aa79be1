#include "m2s/client/on_device_transport.h"

namespace m2s::client {

OnDeviceTransport::OnDeviceTransport(server_app::ServerOptions options,
                                     server_app::SystemFactory factory,
                                     server_app::MapGroupFactory group_factory)
    : options_(std::move(options)),
      factory_(std::move(factory)),
      group_factory_(std::move(group_factory)) {}

OnDeviceTransport::~OnDeviceTransport() { Stop(); }

Status OnDeviceTransport::Start(MessageHandler handler) {
  if (manager_) return Status::Error("on-device transport already started");
  if (Status s = options_.Check(); !s) return s.Prefixed("server options: ");
  manager_ = std::make_unique<server_app::SessionManager>(
      options_,
      [handler = std::move(handler)](const std::string& channel, std::vector<uint8_t> bytes) {
        handler(channel, bytes.data(), bytes.size());
      },
      factory_, group_factory_);
  return Status::Ok();
}

Status OnDeviceTransport::Publish(const std::string& channel, const std::vector<uint8_t>& bytes) {
  if (!manager_) return Status::Error("on-device transport not started");
  manager_->HandleMessage(channel, bytes.data(), bytes.size());
  manager_->Tick();
  return Status::Ok();
}

void OnDeviceTransport::Stop() {
  if (manager_) manager_->Shutdown();
  manager_.reset();
}

}  // namespace m2s::client
