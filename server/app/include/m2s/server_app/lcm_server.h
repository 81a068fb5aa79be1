// The SLAM server on an LCM network: one IO thread receives raw frames and session messages
// and hands them to a SessionManager (which only decodes, validates and queues), publishes the
// sessions' poses and map deltas, ends timed-out sessions and publishes server_stats_t
// periodically on M2S_STATS (also written to the log).
//
// With a bus key (options.bus.key) every message in and out goes through wire::BusOpener /
// BusSealer (common/bus_auth.h): what fails authentication, replays and stale messages are
// counted by reason and dropped before any decoding, and the server's messages carry its
// server_instance as their sender id. Without a key the server says once, loudly, that the bus
// is open.
//
// Thread-safety: Start() and Stop() from one controlling thread; Counters() from any thread.
//
//   LcmServer server(options);
//   if (Status s = server.Start(); !s) return fail(s);
//   ...                      // until SIGTERM
//   server.Stop();           // ends sessions (saving maps when asked), joins the IO thread
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "m2s/common/bus_auth.h"
#include "m2s/common/status.h"
#include "m2s/server_app/session_manager.h"

namespace lcm {
class LCM;
class ReceiveBuffer;
}  // namespace lcm

namespace m2s::server_app {

struct LcmServerOptions {
  std::string lcm_url = wire::kDefaultLcmUrl;
  // server_stats_t period in seconds (0: never).
  double stats_period_s = 5.0;
  // Write the stats line to the log too.
  bool log_stats = true;
  // Shared secret of the bus (none: open bus), payload encryption, replay checks.
  wire::BusSecurityOptions bus;
  ServerOptions server;
  // Map groups created at Start() from saved maps, localisation-only: group name -> map file
  // (SessionManager::LoadGroupMap; each group's camera is its map's).
  std::map<std::string, std::string> group_maps;
  // Start() also resumes the group maps saved in server.save_maps_dir (this shard's), mapping
  // on (SessionManager::ResumeGroupMaps): a restarted server continues its groups.
  bool resume_maps = false;
};

class LcmServer {
 public:
  explicit LcmServer(LcmServerOptions options,
                     SystemFactory factory = &SessionManager::DefaultSystemFactory,
                     MapGroupFactory group_factory = &SessionManager::DefaultMapGroupFactory);
  ~LcmServer();  // Stop()

  // Opens the LCM URL, loads the group maps, subscribes and starts the IO thread.
  Status Start();
  // Ends every session and stops the IO thread. Idempotent.
  void Stop();

  // The counters; after Stop() the final ones.
  ServerCounters Counters() const;
  // Counters, map groups and drops by reason name as JSON (SessionManager::StatsJson), e.g.
  // for m2s_server --stats-out; after Stop() the final ones.
  std::string CountersJson() const;
  int64_t server_instance() const;
  SessionManager* manager() { return manager_.get(); }

 private:
  void IoLoop();
  void OnRaw(const lcm::ReceiveBuffer* buffer, const std::string& channel);
  void PublishStats();
  void PublishSealed(const std::string& channel, const std::vector<uint8_t>& bytes);

  const LcmServerOptions options_;
  wire::BusSealer sealer_;
  wire::BusOpener opener_;
  const SystemFactory factory_;
  const MapGroupFactory group_factory_;
  std::unique_ptr<lcm::LCM> lcm_;
  std::mutex publish_mutex_;
  std::unique_ptr<SessionManager> manager_;
  std::atomic<bool> stop_{false};
  std::thread io_thread_;
  ServerCounters final_counters_;
  std::string final_json_;
};

}  // namespace m2s::server_app
