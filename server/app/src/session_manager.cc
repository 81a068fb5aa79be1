#include "m2s/server_app/session_manager.h"

#include <algorithm>
#include <chrono>
#include <random>

#include "m2s/common/check.h"
#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "m2s/server_app/messages.h"
#include "session.h"

namespace m2s::server_app {
namespace {

constexpr size_t kTrackingRingSize = 2048;

int64_t RandomInstance() {
  std::random_device device;
  std::mt19937_64 rng((static_cast<uint64_t>(device()) << 32) ^ device() ^
                      static_cast<uint64_t>(wire::WallClockMicros()));
  int64_t value = 0;
  while (value == 0) value = static_cast<int64_t>(rng() >> 1);
  return value;
}

double NowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

ServerOptions WithInstance(ServerOptions options) {
  if (options.server_instance == 0) options.server_instance = RandomInstance();
  return options;
}

}  // namespace

Status ServerOptions::Check() const {
  if (max_sessions <= 0) return Status::Error("max_sessions must be positive");
  if (!(session_timeout_s > 0)) return Status::Error("session_timeout_s must be positive");
  if (max_features <= 0) return Status::Error("max_features must be positive");
  if (!(map_rate_hz > 0) || map_rate_hz > 1000)
    return Status::Error("map_rate_hz must be in (0, 1000]");
  if (queue_capacity <= 0) return Status::Error("queue_capacity must be positive");
  if (max_seq_jump <= 0) return Status::Error("max_seq_jump must be positive");
  if (max_ended_sessions <= 0) return Status::Error("max_ended_sessions must be positive");
  if (!(drop_log_period_s >= 0)) return Status::Error("drop_log_period_s must be >= 0");
  if (max_groups <= 0) return Status::Error("max_groups must be positive");
  if (!(save_period_s >= 0.0)) return Status::Error("save_period_s must be >= 0");
  if (Status s = shard.Check(); !s) return s;
  return Status::Ok();
}

int64_t ServerCounters::total_drops() const {
  int64_t total = 0;
  for (int64_t d : drops) total += d;
  return total;
}

Expected<std::unique_ptr<slam::System>> SessionManager::DefaultSystemFactory(
    const slam::Options& options) {
  return slam::System::Create(options);
}

Expected<std::shared_ptr<slam::MapGroup>> SessionManager::DefaultMapGroupFactory(
    const slam::Options& options) {
  return slam::MapGroup::Create(options);
}

SessionManager::SessionManager(ServerOptions options, PublishFn publish, SystemFactory factory,
                               MapGroupFactory group_factory)
    : options_(WithInstance(std::move(options))),
      publish_(std::move(publish)),
      factory_(std::move(factory)),
      group_factory_(std::move(group_factory)) {
  const Status valid = options_.Check();
  M2S_CHECK(valid) << valid.message();
  M2S_CHECK(publish_ && factory_ && group_factory_) << "publish and factories must be set";
  tracking_ms_ring_.reserve(kTrackingRingSize);
  last_drop_log_s_.fill(-1e9);
  reaper_ = std::thread([this] { ReaperLoop(); });
}

SessionManager::~SessionManager() { Shutdown(); }

void SessionManager::HandleMessage(const std::string& channel, const void* data, size_t size,
                                   uint64_t sender) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counters_.messages_in;
  }
  if (channel == wire::kFrameChannel) {
    HandleFrame(data, size, sender);
  } else if (channel == wire::kSessionChannel) {
    HandleSessionControl(data, size, sender);
  } else {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counters_.ignored;
  }
}

void SessionManager::HandleFrame(const void* data, size_t size, uint64_t sender) {
  auto frame = wire::DecodeFeatureFrame(data, size, {options_.max_features});
  if (!frame) return Drop(frame.reason(), frame.error());
  wire::DropReason reason{};
  bool not_ours = false;
  auto session = FindOrCreate({.session_id = frame->session_id,
                               .sender = sender,
                               .camera = frame->camera,
                               .flags = 0,
                               .from_hello = false,
                               .group = {}},
                              &reason, &not_ours);
  if (not_ours) return;
  if (!session) return Drop(reason, "frame for session " + std::to_string(frame->session_id));
  std::string detail;
  if (!session->Accept(std::move(*frame), &reason, &detail)) return Drop(reason, detail);
  std::lock_guard<std::mutex> lock(mutex_);
  ++counters_.frames_in;
}

void SessionManager::HandleSessionControl(const void* data, size_t size, uint64_t sender) {
  auto message = wire::DecodeSessionControl(data, size);
  if (!message) return Drop(message.reason(), message.error());
  const session_control_t& m = *message;
  switch (m.type) {
    case session_control_t::HELLO: {
      const uint64_t key =
          m.map_group.empty() ? ShardKeyOfSession(m.session_id) : ShardKeyOfGroup(m.map_group);
      if (!options_.shard.Owns(key)) {
        std::lock_guard<std::mutex> lock(mutex_);
        ++counters_.other_shard_hellos;
        return;
      }
      auto camera = wire::FromMessage(m.camera);  // checked by the decoder
      wire::DropReason reason{};
      bool not_ours = false;
      auto session = FindOrCreate({.session_id = m.session_id,
                                   .sender = sender,
                                   .camera = *camera,
                                   .flags = m.flags,
                                   .from_hello = true,
                                   .group = m.map_group},
                                  &reason, &not_ours);
      if (!session) return Drop(reason, "HELLO for session " + std::to_string(m.session_id));
      session->Touch();
      session_control_t ack =
          MakeSessionMessage(session_control_t::HELLO_ACK, m.session_id, server_instance());
      ack.camera = wire::ToMessage(session->camera());
      ack.flags = m.flags;
      ack.map_group = m.map_group;
      Publish(wire::kSessionChannel, wire::Encode(ack));
      break;
    }
    case session_control_t::RESET:
    case session_control_t::RESYNC_REQUEST:
    case session_control_t::BYE: {
      std::shared_ptr<Session> session;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        auto it = sessions_.find(m.session_id);
        if (it != sessions_.end()) session = it->second;
      }
      if (!session && options_.shard.sharded()) {
        std::lock_guard<std::mutex> lock(mutex_);
        ++counters_.other_shard_messages;  // most likely another server's session
        return;
      }
      if (!session) {
        return Drop(wire::DropReason::kUnknownSession,
                    "session message type " + std::to_string(m.type) + " for unknown session " +
                        std::to_string(m.session_id));
      }
      if (session->owner() != sender) {
        return Drop(wire::DropReason::kSpoofedSession,
                    "session message type " + std::to_string(m.type) + " for session " +
                        std::to_string(m.session_id) + " from sender " + std::to_string(sender));
      }
      if (m.type == session_control_t::RESET) session->RequestReset();
      if (m.type == session_control_t::RESYNC_REQUEST) session->RequestResync();
      if (m.type == session_control_t::BYE) EndSession(m.session_id, "bye");
      break;
    }
    default: {  // server -> client types (our own replies come back on the same channel)
      std::lock_guard<std::mutex> lock(mutex_);
      ++counters_.ignored;
      return;
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ++counters_.session_messages;
}

std::shared_ptr<Session> SessionManager::FindOrCreate(const Opening& opening,
                                                      wire::DropReason* refused, bool* not_ours) {
  const int64_t session_id = opening.session_id;
  std::unique_lock<std::mutex> lock(mutex_);
  auto it = sessions_.find(session_id);
  if (it != sessions_.end()) {
    if (it->second->owner() == opening.sender) return it->second;
    *refused = wire::DropReason::kSpoofedSession;
    return nullptr;
  }
  if (shutting_down_ || ended_.count(session_id)) {
    *refused = wire::DropReason::kEndedSession;
    return nullptr;
  }
  if (!opening.from_hello && options_.shard.sharded()) {
    *not_ours = true;  // sharded servers open sessions from HELLOs only
    ++counters_.other_shard_messages;
    return nullptr;
  }
  std::unique_ptr<slam::System> system;
  std::string why;
  if (static_cast<int>(sessions_.size()) >= options_.max_sessions) {
    *refused = wire::DropReason::kMaxSessions;
    why = "server full: " + std::to_string(options_.max_sessions) + " sessions";
  } else {
    CreateSystemLocked(opening, &system, refused, &why);
  }
  if (!system) {
    // A session refused for good (its camera is not its group's) takes no frames either.
    if (*refused == wire::DropReason::kGroupCamera) RememberEndedLocked(session_id);
    lock.unlock();
    if (!why.empty()) PublishRejected(session_id, why);
    return nullptr;
  }
  auto session = std::make_shared<Session>(this, session_id, opening.sender, opening.camera,
                                           std::move(system));
  sessions_[session_id] = session;
  ++counters_.sessions_started;
  const Camera& camera = opening.camera;
  M2S_LOG(kInfo) << "session " << session_id << " started (" << camera.width << "x" << camera.height
                 << (opening.from_hello ? ", hello" : ", first frame")
                 << (opening.group.empty() ? "" : ", map group " + opening.group)
                 << ((opening.flags & session_control_t::FLAG_DETERMINISTIC) ? ", deterministic"
                                                                             : "")
                 << ")";
  return session;
}

bool SessionManager::CreateSystemLocked(const Opening& opening,
                                        std::unique_ptr<slam::System>* system,
                                        wire::DropReason* refused, std::string* why) {
  slam::Options slam_options = options_.slam;
  slam_options.camera = opening.camera;
  slam_options.max_features_per_frame = options_.max_features;
  // A session never calls System::RefineMap(): its frames keep no observations for it.
  slam_options.frame_observations_kept = 0;
  if (opening.flags & session_control_t::FLAG_DETERMINISTIC) slam_options.deterministic = true;
  Expected<std::unique_ptr<slam::System>> created = Status::Error("no system");
  if (opening.group.empty()) {
    created = factory_(slam_options);
  } else {
    auto it = groups_.find(opening.group);
    if (it == groups_.end()) {
      if (static_cast<int>(groups_.size()) >= options_.max_groups) {
        ++counters_.groups_refused;
        *refused = wire::DropReason::kMaxGroups;
        *why = "server full: " + std::to_string(options_.max_groups) + " map groups";
        return false;
      }
      auto group = group_factory_(slam_options);
      if (!group) {
        *refused = wire::DropReason::kBadCamera;
        *why = "map group " + opening.group + " not created: " + group.error();
        M2S_LOG(kWarning) << "session " << opening.session_id << ": " << *why;
        return false;
      }
      it = groups_.emplace(opening.group, std::move(*group)).first;
      ++counters_.groups_created;
      M2S_LOG(kInfo) << "map group " << opening.group << " created";
    }
    if (!SameCamera(opening.camera, it->second->options().camera)) {
      *refused = wire::DropReason::kGroupCamera;
      *why = "camera differs from map group " + opening.group + "'s";
      return false;
    }
    created = it->second->Join();
  }
  if (!created) {
    *refused = wire::DropReason::kBadCamera;
    *why = "SLAM refused the session: " + created.error();
    M2S_LOG(kWarning) << "session " << opening.session_id << ": " << *why;
    return false;
  }
  *system = std::move(*created);
  return true;
}

void SessionManager::PublishRejected(int64_t session_id, const std::string& why) {
  session_control_t reply =
      MakeSessionMessage(session_control_t::REJECTED, session_id, server_instance());
  reply.reason = why;
  Publish(wire::kSessionChannel, wire::Encode(reply));
}

void SessionManager::RememberEndedLocked(int64_t session_id) {
  ended_[session_id] = true;
  ended_order_.push_back(session_id);
  while (static_cast<int>(ended_order_.size()) > options_.max_ended_sessions) {
    ended_.erase(ended_order_.front());
    ended_order_.pop_front();
  }
}

void SessionManager::EndSession(int64_t session_id, const std::string& reason) {
  std::shared_ptr<Session> session;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = sessions_.find(session_id);
    if (it == sessions_.end()) return;
    session = it->second;
    sessions_.erase(it);
    RememberEndedLocked(session_id);
    ++counters_.sessions_ended;
  }
  session->Stop();  // outside mutex_: the session calls back into the counters
  {
    std::lock_guard<std::mutex> lock(mutex_);
    to_reap_.push_back(session);
    reap_cv_.notify_all();
  }
  M2S_LOG(kInfo) << "session " << session_id << " ended (" << reason << ")";
  session_control_t m =
      MakeSessionMessage(session_control_t::SESSION_ENDED, session_id, server_instance());
  m.reason = reason;
  Publish(wire::kSessionChannel, wire::Encode(m));
}

std::chrono::steady_clock::time_point SessionManager::Now() const {
  return options_.clock ? options_.clock() : std::chrono::steady_clock::now();
}

void SessionManager::Tick() {
  const auto now = Now();
  std::vector<std::shared_ptr<Session>> sessions;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& entry : sessions_) sessions.push_back(entry.second);
  }
  std::vector<int64_t> expired;
  for (const auto& session : sessions) {
    if (session->IdleSeconds(now) > options_.session_timeout_s) expired.push_back(session->id());
  }
  for (int64_t id : expired) EndSession(id, "timeout");
  if (options_.save_period_s > 0.0 && !options_.save_maps_dir.empty()) {
    bool due = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!last_group_save_) last_group_save_ = now;
      if (std::chrono::duration<double>(now - *last_group_save_).count() >=
          options_.save_period_s) {
        last_group_save_ = now;
        due = true;
      }
    }
    if (due) SaveGroupMaps(/*final=*/false);
  }
}

void SessionManager::Shutdown() {
  std::vector<int64_t> ids;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (shutting_down_ && !reaper_.joinable()) return;
    for (const auto& entry : sessions_) ids.push_back(entry.first);
  }
  for (int64_t id : ids) EndSession(id, "server shutdown");
  {
    std::lock_guard<std::mutex> lock(mutex_);
    shutting_down_ = true;
    reap_cv_.notify_all();
  }
  if (reaper_.joinable()) reaper_.join();
  SaveGroupMaps(/*final=*/true);  // after every agent finished
}

void SessionManager::Drain() {
  std::vector<std::shared_ptr<Session>> sessions;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& entry : sessions_) sessions.push_back(entry.second);
  }
  for (const auto& session : sessions) session->Drain();
}

void SessionManager::ReaperLoop() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (true) {
    reap_cv_.wait(lock, [this] { return shutting_down_ || !to_reap_.empty(); });
    if (to_reap_.empty()) {
      if (shutting_down_) break;
      continue;
    }
    std::shared_ptr<Session> session = std::move(to_reap_.front());
    to_reap_.pop_front();
    lock.unlock();
    session->Finish(options_.save_maps_dir);
    session.reset();
    lock.lock();
  }
}

void SessionManager::Drop(wire::DropReason reason, const std::string& detail) {
  const int r = static_cast<int>(reason);
  int64_t suppressed = 0;
  bool log = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counters_.drops[r];
    ++drops_since_log_[r];
    const double now = NowSeconds();
    if (now - last_drop_log_s_[r] >= options_.drop_log_period_s) {
      log = true;
      suppressed = drops_since_log_[r] - 1;
      drops_since_log_[r] = 0;
      last_drop_log_s_[r] = now;
    }
  }
  if (log) {
    M2S_LOG(kWarning) << "dropped (" << wire::ToString(reason) << "): " << detail
                      << (suppressed > 0 ? " (+" + std::to_string(suppressed) + " more)" : "");
  }
}

void SessionManager::Publish(const std::string& channel, std::vector<uint8_t> bytes) {
  publish_(channel, std::move(bytes));
}

void SessionManager::RecordTrackingTime(double ms) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (tracking_ms_ring_.size() < kTrackingRingSize) {
    tracking_ms_ring_.push_back(static_cast<float>(ms));
  } else {
    tracking_ms_ring_[tracking_ms_next_] = static_cast<float>(ms);
  }
  tracking_ms_next_ = (tracking_ms_next_ + 1) % kTrackingRingSize;
}

void SessionManager::CountProcessed() { frames_processed_.fetch_add(1); }

void SessionManager::CountSkipped() { frames_skipped_.fetch_add(1); }

ServerCounters SessionManager::Counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  ServerCounters counters = counters_;
  counters.frames_processed = frames_processed_.load();
  counters.frames_skipped = frames_skipped_.load();
  counters.sessions_active = static_cast<int>(sessions_.size());
  counters.groups = static_cast<int>(groups_.size());
  return counters;
}

}  // namespace m2s::server_app
