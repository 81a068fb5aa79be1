#include "m2s/server_app/lcm_server.h"

#include <chrono>

#include <lcm/lcm-cpp.hpp>

#include "m2s/common/logging.h"

namespace m2s::server_app {
namespace {

constexpr int kIoTimeoutMs = 50;
constexpr double kTickPeriodS = 0.1;

}  // namespace

LcmServer::LcmServer(LcmServerOptions options, SystemFactory factory)
    : options_(std::move(options)), factory_(std::move(factory)) {}

LcmServer::~LcmServer() { Stop(); }

Status LcmServer::Start() {
  std::string why;
  if (!options_.server.Check(&why)) return Status::Error("server options: " + why);
  if (!(options_.stats_period_s >= 0)) return Status::Error("stats period must be >= 0");
  lcm_ = std::make_unique<lcm::LCM>(options_.lcm_url);
  if (!lcm_->good()) {
    lcm_.reset();
    return Status::Error("cannot open LCM URL '" + options_.lcm_url + "'");
  }
  manager_ = std::make_unique<SessionManager>(
      options_.server,
      [this](const std::string& channel, std::vector<uint8_t> bytes) {
        std::lock_guard<std::mutex> lock(publish_mutex_);
        lcm_->publish(channel, bytes.data(), static_cast<unsigned int>(bytes.size()));
      },
      factory_);
  lcm_->subscribe(wire::kFrameChannel, &LcmServer::OnRaw, this);
  lcm_->subscribe(wire::kSessionChannel, &LcmServer::OnRaw, this);
  stop_ = false;
  io_thread_ = std::thread([this] { IoLoop(); });
  M2S_LOG(kInfo) << "m2s server " << manager_->server_instance() << " listening on "
                 << options_.lcm_url;
  return Status::Ok();
}

void LcmServer::Stop() {
  if (!lcm_) return;
  stop_ = true;
  if (io_thread_.joinable()) io_thread_.join();
  if (manager_) {
    manager_->Shutdown();
    M2S_LOG(kInfo) << "m2s server stopped: " << manager_->StatsLine();
  }
  manager_.reset();
  lcm_.reset();
}

void LcmServer::OnRaw(const lcm::ReceiveBuffer* buffer, const std::string& channel) {
  manager_->HandleMessage(channel, buffer->data, buffer->data_size);
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
  const std::vector<uint8_t> bytes = wire::Encode(stats);
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    lcm_->publish(wire::kStatsChannel, bytes.data(), static_cast<unsigned int>(bytes.size()));
  }
  if (options_.log_stats) M2S_LOG(kInfo) << "stats: " << manager_->StatsLine();
}

ServerCounters LcmServer::Counters() const {
  return manager_ ? manager_->Counters() : ServerCounters{};
}

int64_t LcmServer::server_instance() const { return manager_ ? manager_->server_instance() : 0; }

}  // namespace m2s::server_app
