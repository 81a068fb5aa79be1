// SessionManager's reports: the stats JSON (m2s_server --stats-out), the periodic stats
// message and the one-line summary.
#include <sstream>

#include <nlohmann/json.hpp>

#include "m2s/common/numeric.h"
#include "m2s/common/wire_format.h"
#include "m2s/server_app/session_manager.h"

namespace m2s::server_app {

std::string SessionManager::StatsJson(bool authenticated) const {
  const ServerCounters c = Counters();
  nlohmann::json drops = nlohmann::json::object();
  for (int r = 0; r < wire::kNumDropReasons; ++r) {
    drops[wire::ToString(static_cast<wire::DropReason>(r))] = c.drops[r];
  }
  nlohmann::json groups = nlohmann::json::array();
  for (const GroupReport& g : Groups()) {
    groups.push_back({{"name", g.name},
                      {"agents_joined", g.stats.agents_joined},
                      {"agents_active", g.stats.agents_active},
                      {"merges", g.stats.merges},
                      {"merge_ms", g.stats.merge_ms},
                      {"keyframes", g.stats.keyframes},
                      {"map_points", g.stats.map_points},
                      {"localization_only", g.stats.localization_only}});
  }
  const nlohmann::json j = {{"server_instance", server_instance()},
                            {"shard", options_.shard.ToString()},
                            {"shard_index", options_.shard.index},
                            {"shard_count", options_.shard.count},
                            {"messages_in", c.messages_in},
                            {"frames_in", c.frames_in},
                            {"frames_processed", c.frames_processed},
                            {"frames_skipped", c.frames_skipped},
                            {"session_messages", c.session_messages},
                            {"sessions_started", c.sessions_started},
                            {"sessions_ended", c.sessions_ended},
                            {"sessions_active", c.sessions_active},
                            {"other_shard_hellos", c.other_shard_hellos},
                            {"other_shard_messages", c.other_shard_messages},
                            {"groups_created", c.groups_created},
                            {"groups_refused", c.groups_refused},
                            {"groups", groups},
                            {"authenticated", authenticated},
                            {"drops_total", c.total_drops()},
                            {"drops", drops}};
  return j.dump(2) + "\n";
}

server_stats_t SessionManager::StatsMessage() const {
  const ServerCounters c = Counters();
  std::vector<float> times;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    times = tracking_ms_ring_;
  }
  server_stats_t m;
  m.version = server_stats_t::VERSION;
  m.server_instance = server_instance();
  m.wall_us = wire::WallClockMicros();
  m.sessions_active = c.sessions_active;
  m.frames_in = c.frames_in;
  m.frames_processed = c.frames_processed;
  m.frames_skipped = c.frames_skipped;
  for (int r = 0; r < wire::kNumDropReasons; ++r) {
    m.drop_reasons.push_back(wire::ToString(static_cast<wire::DropReason>(r)));
    m.drop_counts.push_back(c.drops[r]);
  }
  m.num_drop_reasons = static_cast<int32_t>(m.drop_reasons.size());
  m.tracking_ms_p50 = Percentile(times, 0.5, PercentileMethod::kRoundedRank);
  m.tracking_ms_p95 = Percentile(times, 0.95, PercentileMethod::kRoundedRank);
  return m;
}

std::string SessionManager::StatsLine() const {
  const server_stats_t m = StatsMessage();
  std::ostringstream line;
  line << "sessions " << m.sessions_active << ", frames in " << m.frames_in << ", processed "
       << m.frames_processed << ", skipped " << m.frames_skipped << ", tracking p50 "
       << m.tracking_ms_p50 << " ms p95 " << m.tracking_ms_p95 << " ms";
  for (int r = 0; r < m.num_drop_reasons; ++r) {
    if (m.drop_counts[r] > 0) line << ", " << m.drop_reasons[r] << " " << m.drop_counts[r];
  }
  return line.str();
}

}  // namespace m2s::server_app
