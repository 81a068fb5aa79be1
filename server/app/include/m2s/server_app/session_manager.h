// The server's session logic, independent of the transport: raw message bytes in (frames and
// session control), encoded pose estimates, map deltas and session replies out. The LCM server
// (lcm_server.h), the on-device client transport and the replay tool all run this same code.
//
// Each session owns one slam::System (its own, or an agent of a map group: a HELLO naming a
// group makes the session an agent of this server's slam::MapGroup of that name, created on the
// group's first session and kept when its sessions end; a session whose camera is not the
// group's is REJECTED and its id served no more) and a worker thread fed by a bounded
// latest-wins queue: HandleMessage() only decodes, validates and queues, so the caller (the IO
// thread) never waits for SLAM. With Options::synchronous the frame is tracked in the caller's
// thread instead (replay: every frame, deterministic). Everything that cannot be used is counted
// per wire::DropReason and dropped with a rate-limited log line. Memory is bounded: at most
// max_sessions sessions, queue_capacity frames each, max_groups map groups, a bounded set of
// ended session ids.
//
// Scale-out (ServerOptions::shard, common/shard.h): a server answers only the HELLOs whose
// shard key (the group's name, or the session id) it owns; when sharded it creates sessions
// only from HELLOs, and what belongs to other servers is ignored and counted (other_shard_*),
// not dropped.
//
// Thread-safety: every public method may be called from any thread. `publish` is called from
// the session workers (or the caller in synchronous mode) without any internal lock held, so
// it may call back into HandleMessage().
//
//   SessionManager manager(options, [&](const std::string& channel, std::vector<uint8_t> bytes) {
//     lcm.publish(channel, bytes.data(), bytes.size()); });
//   manager.HandleMessage(wire::kFrameChannel, data, size);
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "m2s/common/shard.h"
#include "m2s/common/wire_format.h"
#include "m2s/slam/system.h"

namespace m2s::server_app {

using PublishFn = std::function<void(const std::string& channel, std::vector<uint8_t> bytes)>;
using SystemFactory =
    std::function<Expected<std::unique_ptr<slam::System>>(const slam::Options& options)>;
using MapGroupFactory =
    std::function<Expected<std::shared_ptr<slam::MapGroup>>(const slam::Options& options)>;

// The file extension of saved maps: DIR/session_<id>.m2smap, DIR/group-<name>.m2smap.
inline constexpr const char* kMapFileExtension = ".m2smap";

struct ServerOptions {
  // SLAM options of every session; the camera comes from the session's HELLO / first frame
  // and `deterministic` is also set by the HELLO flag FLAG_DETERMINISTIC.
  slam::Options slam;
  int max_sessions = 8;
  // A session without any message for this long is ended.
  double session_timeout_s = 10.0;
  // Frames with more features are dropped (wire::DropReason::kTooManyFeatures).
  int max_features = 200000;
  // Map deltas are published at most this often per session.
  double map_rate_hz = 15.0;
  // Frames waiting per session; when full the oldest is dropped (counted as skipped). Three
  // frames absorb the longest single tracking steps (a map's two-view initialisation with its
  // bundle adjustment, a keyframe: 15-25 ms on 2 cores) at 120 fps without dropping a frame;
  // a tracker slower than the frame rate still drops, and waits at most three frames.
  int queue_capacity = 3;
  // Track in the caller's thread (replay, deterministic tests) instead of a worker.
  bool synchronous = false;
  // When not empty, each session's map is saved there when it ends, and each map group's map
  // every save_period_s (0: never) and when the manager shuts down (ResumeGroupMaps() reads
  // them back after a restart).
  std::string save_maps_dir;
  double save_period_s = 10.0;
  // Map groups held at most (groups outlive their sessions); a HELLO naming a new group beyond
  // is refused (REJECTED, counted as groups_refused and dropped as kMaxGroups).
  int max_groups = 64;
  // The share of the sessions this server serves (default: all).
  ShardSpec shard;
  // A frame's sequence number may exceed its session's last one (0 before the first frame) by
  // at most this much (a stray frame with a huge seq must not freeze the session).
  int64_t max_seq_jump = 1 << 16;
  // Ended session ids remembered (frames for them are dropped as kEndedSession).
  int max_ended_sessions = 4096;
  // At most one log line per drop reason per this period.
  double drop_log_period_s = 1.0;
  // Random id of this server instance (0: chosen at random).
  int64_t server_instance = 0;
  // The clock of session activity and timeouts (empty: std::chrono::steady_clock); tests
  // inject a manual one.
  std::function<std::chrono::steady_clock::time_point()> clock;

  Status Check() const;
};

struct ServerCounters {
  int64_t messages_in = 0;       // every message handed to HandleMessage
  int64_t frames_in = 0;         // feature frames that decoded and validated
  int64_t frames_processed = 0;  // tracked frames (a pose was published)
  int64_t frames_skipped = 0;    // dropped by a latest-wins queue
  int64_t session_messages = 0;  // valid session control messages handled
  int64_t ignored = 0;           // valid messages not meant for the server (its own replies)
  int64_t sessions_started = 0;
  int64_t sessions_ended = 0;
  int sessions_active = 0;
  int64_t other_shard_hellos = 0;    // HELLOs another shard serves (ignored)
  int64_t other_shard_messages = 0;  // sharded: frames and requests for sessions not held here
  int64_t groups_created = 0;
  int64_t groups_refused = 0;  // HELLOs naming a new group while max_groups are held
  int groups = 0;              // map groups held now
  std::array<int64_t, wire::kNumDropReasons> drops{};
  int64_t total_drops() const;
};

// A map group held by the server, as reported in the stats.
struct GroupReport {
  std::string name;
  slam::GroupStats stats;
};

class Session;

class SessionManager {
 public:
  static Expected<std::unique_ptr<slam::System>> DefaultSystemFactory(const slam::Options& options);
  static Expected<std::shared_ptr<slam::MapGroup>> DefaultMapGroupFactory(
      const slam::Options& options);

  // options must pass Check() (programmer error otherwise).
  SessionManager(ServerOptions options, PublishFn publish,
                 SystemFactory factory = &SessionManager::DefaultSystemFactory,
                 MapGroupFactory group_factory = &SessionManager::DefaultMapGroupFactory);
  ~SessionManager();  // ends every session
  SessionManager(const SessionManager&) = delete;
  SessionManager& operator=(const SessionManager&) = delete;

  // Decodes, validates and routes one message received on `channel` (frame or session
  // channel; other channels are ignored). `sender` is the authenticated bus sender
  // (wire::BusOpener; 0 on an open bus or in-process): a session belongs to the sender that
  // opened it, and frames or requests for it from another sender are dropped
  // (kSpoofedSession).
  void HandleMessage(const std::string& channel, const void* data, size_t size,
                     uint64_t sender = 0);
  // Counts a message the transport refused before decoding (authentication, replay).
  void Drop(wire::DropReason reason, const std::string& detail);
  // Ends the sessions that timed out; call periodically (the LCM server does, every 100 ms).
  void Tick();
  // Creates map group `name` with ServerOptions::slam (its camera is the group's) and loads its
  // map from `path` (the group becomes localisation-only). Fails on an invalid or existing
  // name, a full group table, or a map the group refuses; call before sessions arrive.
  Status LoadGroupMap(const std::string& name, const std::string& path);
  // Resumes the group maps saved in save_maps_dir (DIR/group-<name>.m2smap, this shard's
  // groups only): each group is created with its map's camera and keeps mapping into it (a
  // restarted server). Returns how many; call before sessions arrive.
  Expected<int> ResumeGroupMaps();
  // Ends every session (maps saved when asked, then the groups' maps), e.g. on SIGTERM.
  // Idempotent.
  void Shutdown();
  // Blocks until every queued frame has been tracked (tests, replay).
  void Drain();

  ServerCounters Counters() const;
  // The map groups held, by name.
  std::vector<GroupReport> Groups() const;
  // Counters, groups and drops (by reason name) as one JSON object (m2s_server --stats-out).
  std::string StatsJson(bool authenticated) const;
  server_stats_t StatsMessage() const;
  // One human-readable line of the counters (non-zero drop reasons only).
  std::string StatsLine() const;
  int64_t server_instance() const { return options_.server_instance; }
  std::chrono::steady_clock::time_point Now() const;
  const ServerOptions& options() const { return options_; }

 private:
  friend class Session;
  void HandleFrame(const void* data, size_t size, uint64_t sender);
  void HandleSessionControl(const void* data, size_t size, uint64_t sender);
  // What opens a session: a HELLO (with its flags and map group) or, unsharded, a frame.
  struct Opening {
    int64_t session_id = 0;
    uint64_t sender = 0;
    Camera camera;
    int32_t flags = 0;
    bool from_hello = false;
    std::string group;
  };
  // Returns the session (created when needed); nullptr when refused (reason set) or, sharded,
  // when a frame is for a session this server does not hold (*not_ours set, nothing dropped).
  std::shared_ptr<Session> FindOrCreate(const Opening& opening, wire::DropReason* refused,
                                        bool* not_ours);
  // The session's System: its own, or an agent of its map group (created when new).
  // mutex_ held; false with the reason and a message for the client when refused.
  bool CreateSystemLocked(const Opening& opening, std::unique_ptr<slam::System>* system,
                          wire::DropReason* refused, std::string* why);
  void PublishRejected(int64_t session_id, const std::string& why);
  // Saves every group's map that can change to save_maps_dir (atomically: written aside, then
  // renamed); `final` (at shutdown): once.
  void SaveGroupMaps(bool final);
  Status AddGroupFromFile(const std::string& name, const std::string& path, bool resume);
  void EndSession(int64_t session_id, const std::string& reason);
  // Frames and HELLOs for the id are dropped from now on (kEndedSession). mutex_ held.
  void RememberEndedLocked(int64_t session_id);
  void Publish(const std::string& channel, std::vector<uint8_t> bytes);
  void RecordTrackingTime(double ms);
  void CountProcessed();
  void CountSkipped();
  void ReaperLoop();

  const ServerOptions options_;
  const PublishFn publish_;
  const SystemFactory factory_;
  const MapGroupFactory group_factory_;

  mutable std::mutex mutex_;  // guards the members below
  std::map<int64_t, std::shared_ptr<Session>> sessions_;
  std::map<std::string, std::shared_ptr<slam::MapGroup>> groups_;
  bool groups_saved_ = false;
  std::optional<std::chrono::steady_clock::time_point> last_group_save_;
  std::deque<int64_t> ended_order_;
  std::map<int64_t, bool> ended_;
  std::deque<std::shared_ptr<Session>> to_reap_;
  std::condition_variable reap_cv_;
  bool shutting_down_ = false;
  ServerCounters counters_;
  std::array<double, wire::kNumDropReasons> last_drop_log_s_{};
  std::array<int64_t, wire::kNumDropReasons> drops_since_log_{};
  std::atomic<int64_t> frames_processed_{0};
  std::atomic<int64_t> frames_skipped_{0};
  std::vector<float> tracking_ms_ring_;
  size_t tracking_ms_next_ = 0;

  std::thread reaper_;
};

}  // namespace m2s::server_app
