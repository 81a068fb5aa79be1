#include "m2s/server_app/lcm_server.h"

#include <chrono>

#include <lcm/lcm-cpp.hpp>

#include "m2s/common/logging.h"

namespace m2s::server_app {
namespace {

constexpr int kIoTimeoutMs = 50;
constexpr double kTickPeriodS = 0.1;

LcmServerOptions WithInstance(LcmServerOptions options) {
  if (options.server.server_instance == 0) {
    options.server.server_instance = static_cast<int64_t>(wire::RandomSenderId());
  }
  return options;
}

}  // namespace

LcmServer::LcmServer(LcmServerOptions options, SystemFactory factory, MapGroupFactory group_factory)
    : options_(WithInstance(std::move(options))),
      sealer_(options_.bus.key, options_.bus.encrypt,
              static_cast<uint64_t>(options_.server.server_instance)),
      opener_(options_.bus.key, options_.bus.opener),
      factory_(std::move(factory)),
      group_factory_(std::move(group_factory)) {}

LcmServer::~LcmServer() { Stop(); }

Status LcmServer::Start() {
  if (Status s = options_.server.Check(); !s) return s.Prefixed("server options: ");
  if (!(options_.stats_period_s >= 0)) return Status::Error("stats period must be >= 0");
  if (Status s = options_.bus.opener.Check(); !s) return s.Prefixed("bus options: ");
  lcm_ = std::make_unique<lcm::LCM>(options_.lcm_url);
  if (!lcm_->good()) {
    lcm_.reset();
    return Status::Error("cannot open LCM URL '" + options_.lcm_url + "'");
  }
  manager_ = std::make_unique<SessionManager>(
      options_.server,
      [this](const std::string& channel, std::vector<uint8_t> bytes) {
        PublishSealed(channel, bytes);
      },
      factory_, group_factory_);
  Status groups = Status::Ok();
  for (const auto& [group, path] : options_.group_maps) {
    if (groups = manager_->LoadGroupMap(group, path); !groups) break;
  }
  if (groups && options_.resume_maps) {
    const Expected<int> resumed = manager_->ResumeGroupMaps();
    if (resumed) {
      M2S_LOG(kInfo) << "resumed " << *resumed << " map group(s) from "
                     << options_.server.save_maps_dir;
    } else {
      groups = resumed.status();
    }
  }
  if (!groups) {
    manager_.reset();
    lcm_.reset();
    return groups;
  }
  lcm_->subscribe(wire::kFrameChannel, &LcmServer::OnRaw, this);
  lcm_->subscribe(wire::kSessionChannel, &LcmServer::OnRaw, this);
  stop_ = false;
  io_thread_ = std::thread([this] { IoLoop(); });
  M2S_LOG(kInfo) << "m2s server " << manager_->server_instance() << " listening on "
                 << options_.lcm_url
                 << (options_.bus.key ? (options_.bus.encrypt ? " (authenticated, encrypted)"
                                                              : " (authenticated)")
                                      : "");
  if (!options_.bus.key) {
    M2S_LOG(kWarning) << "NO BUS KEY: messages are neither authenticated nor replay-checked; "
                         "anyone on this LCM network can end, reset or feed sessions. Use "
                         "--key-file outside local development.";
  }
  return Status::Ok();
}

void LcmServer::Stop() {
  if (!lcm_) return;
  stop_ = true;
  if (io_thread_.joinable()) io_thread_.join();
  if (manager_) {
    manager_->Shutdown();
    M2S_LOG(kInfo) << "m2s server stopped: " << manager_->StatsLine();
    final_counters_ = manager_->Counters();
    final_json_ = manager_->StatsJson(options_.bus.key.has_value());
  }
  manager_.reset();
  lcm_.reset();
}

void LcmServer::OnRaw(const lcm::ReceiveBuffer* buffer, const std::string& channel) {
  auto opened = opener_.Open(channel, static_cast<const uint8_t*>(buffer->data), buffer->data_size,
                             wire::WallClockMicros());
  if (!opened) return manager_->Drop(opened.reason(), opened.error());
  manager_->HandleMessage(channel, opened->data, opened->size, opened->sender);
}

void LcmServer::PublishSealed(const std::string& channel, const std::vector<uint8_t>& bytes) {
  const std::vector<uint8_t> sealed = sealer_.Seal(channel, bytes);
  std::lock_guard<std::mutex> lock(publish_mutex_);
  lcm_->publish(channel, sealed.data(), static_cast<unsigned int>(sealed.size()));
}

void LcmServer::IoLoop() {
  using Clock = std::chrono::steady_clock;
  auto next_tick = Clock::now();
  auto next_stats = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(options_.stats_period_s));
  while (!stop_) {
    if (lcm_->handleTimeout(kIoTimeoutMs) < 0) {
      M2S_LOG(kError) << "LCM receive failed; stopping the IO thread";
      break;
    }
    const auto now = Clock::now();
    if (now >= next_tick) {
      manager_->Tick();
      next_tick = now + std::chrono::duration_cast<Clock::duration>(
                            std::chrono::duration<double>(kTickPeriodS));
    }
    if (options_.stats_period_s > 0 && now >= next_stats) {
      PublishStats();
      next_stats = now + std::chrono::duration_cast<Clock::duration>(
                             std::chrono::duration<double>(options_.stats_period_s));
    }
  }
}

void LcmServer::PublishStats() {
  const server_stats_t stats = manager_->StatsMessage();
  PublishSealed(wire::kStatsChannel, wire::Encode(stats));
  if (options_.log_stats) M2S_LOG(kInfo) << "stats: " << manager_->StatsLine();
}

ServerCounters LcmServer::Counters() const {
  return manager_ ? manager_->Counters() : final_counters_;
}

std::string LcmServer::CountersJson() const {
  return manager_ ? manager_->StatsJson(options_.bus.key.has_value()) : final_json_;
}

int64_t LcmServer::server_instance() const { return manager_ ? manager_->server_instance() : 0; }

}  // namespace m2s::server_app
