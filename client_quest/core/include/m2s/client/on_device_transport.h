// OnDeviceTransport: the server's session logic (server_app::SessionManager, the same code the
// LCM server runs) in the client's process. Messages are encoded and decoded exactly as over
// the network; only the network is missing.
//
// Thread-safety: as Transport. The handler runs on the session worker thread.
//
//   OnDeviceTransport transport(server_app::ServerOptions{});
//   ClientSession session(&transport, options);
#pragma once

#include <memory>
#include <mutex>

#include "m2s/client/transport.h"
#include "m2s/server_app/session_manager.h"

namespace m2s::client {

class OnDeviceTransport final : public Transport {
 public:
  explicit OnDeviceTransport(
      server_app::ServerOptions options,
      server_app::SystemFactory factory = &server_app::SessionManager::DefaultSystemFactory,
      server_app::MapGroupFactory group_factory =
          &server_app::SessionManager::DefaultMapGroupFactory);
  ~OnDeviceTransport() override;
  Status Start(MessageHandler handler) override;
  Status Publish(const std::string& channel, const std::vector<uint8_t>& bytes) override;
  void Stop() override;
  std::string_view name() const override { return "on-device"; }
  // The in-process server (null before Start and after Stop).
  server_app::SessionManager* manager() { return manager_.get(); }

 private:
  const server_app::ServerOptions options_;
  const server_app::SystemFactory factory_;
  const server_app::MapGroupFactory group_factory_;
  std::unique_ptr<server_app::SessionManager> manager_;
};

}  // namespace m2s::client
