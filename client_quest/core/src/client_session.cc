#include "m2s/client/client_session.h"

#include <algorithm>
#include <chrono>

#include "m2s/common/logging.h"

namespace m2s::client {
namespace {

double NowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

int64_t SteadyMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

std::chrono::steady_clock::time_point Deadline(double timeout_s) {
  return std::chrono::steady_clock::now() +
         std::chrono::duration_cast<std::chrono::steady_clock::duration>(
             std::chrono::duration<double>(timeout_s));
}

uint64_t RandomSeed() {
  std::random_device device;
  return (static_cast<uint64_t>(device()) << 32) ^ device() ^
         static_cast<uint64_t>(wire::WallClockMicros());
}

}  // namespace

double ClientSession::Now() const { return options_.clock_s ? options_.clock_s() : NowSeconds(); }

ClientSession::ClientSession(Transport* transport, ClientSessionOptions options)
    : transport_(transport),
      options_(std::move(options)),
      rng_(options_.session_seed != 0 ? options_.session_seed : RandomSeed()) {}

ClientSession::~ClientSession() { End(); }

Status ClientSession::Start() {
  if (Status name = wire::CheckMapGroupName(options_.map_group); !name) return name;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (started_) return Status::Error("session already started");
    started_ = true;
  }
  Status started = transport_->Start([this](const std::string& channel, const uint8_t* data,
                                            size_t size) { OnMessage(channel, data, size); });
  if (!started) return started;
  BeginSession();
  const auto deadline = Deadline(options_.hello_timeout_s);
  std::unique_lock<std::mutex> lock(mutex_);
  while (!acked_ && !rejected_ && std::chrono::steady_clock::now() < deadline) {
    cv_.wait_until(lock, std::min(deadline, Deadline(options_.hello_resend_s)),
                   [this] { return acked_ || rejected_; });
    if (acked_ || rejected_) break;
    lock.unlock();
    ResendHelloIfDue();
    lock.lock();
  }
  if (!acked_ && !rejected_) {
    M2S_LOG(kWarning) << "no HELLO_ACK within " << options_.hello_timeout_s
                      << " s; the HELLO is repeated while frames are sent";
  }
  return Status::Ok();
}

void ClientSession::BeginSession() {
  int64_t id = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    while (id == 0) id = static_cast<int64_t>(rng_() >> 1);
    session_id_ = id;
    server_instance_ = 0;
    acked_ = false;
    rejected_ = false;
    new_session_pending_ = false;
    session_first_seq_ = next_seq_;
    last_answer_s_ = Now();
    outstanding_ = false;
    ++counters_.sessions_started;
  }
  replica_.Reset(id);
  SendHello();
}

void ClientSession::SendHello() {
  int64_t id = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    id = session_id_;
    last_hello_s_ = Now();
    ++counters_.hellos_sent;
  }
  // Best effort: HELLO is repeated until answered (and unsharded servers open the session from
  // frames too).
  PublishControl(session_control_t::HELLO, id, 0);
}

bool ClientSession::ResendHelloIfDue() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (acked_ || rejected_ || ended_ || new_session_pending_ ||
        Now() - last_hello_s_ < options_.hello_resend_s) {
      return false;
    }
  }
  SendHello();
  return true;
}

void ClientSession::PublishControl(int8_t type, int64_t session_id, int64_t last_revision) {
  session_control_t m = {};
  m.version = session_control_t::VERSION;
  m.type = type;
  m.session_id = session_id;
  m.server_instance = 0;
  m.wall_us = wire::WallClockMicros();
  m.last_revision = last_revision;
  m.client_name = options_.client_name;
  m.camera = wire::ToMessage(options_.camera);
  m.flags = 0;
  if (type == session_control_t::HELLO) {
    m.flags = options_.deterministic ? session_control_t::FLAG_DETERMINISTIC : 0;
    m.map_group = options_.map_group;
  }
  if (Status sent = transport_->Publish(wire::kSessionChannel, wire::Encode(m)); !sent) {
    M2S_LOG(kWarning) << "session message " << static_cast<int>(type)
                      << " not sent: " << sent.message();
  }
}

Expected<int64_t> ClientSession::Send(wire::FeatureFrame frame) {
  int64_t old_session = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!started_ || ended_) return Status::Error("session not running");
    CheckAnsweredLocked(Now());
    if (new_session_pending_) old_session = session_id_;
  }
  if (old_session != 0) {
    PublishControl(session_control_t::BYE, old_session, 0);
    BeginSession();
  } else {
    ResendHelloIfDue();
  }
  std::vector<uint8_t> bytes;
  int64_t seq = 0;
  bool hold = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // A group session's frames wait for the acknowledgement: an unsharded server would open a
    // session without the group from a frame that overtook the HELLO.
    hold = !acked_ && !options_.map_group.empty();
    if (hold) ++counters_.frames_held;
    seq = next_seq_++;
    frame.session_id = session_id_;
    frame.seq = seq - session_first_seq_ + 1;
    outstanding_ = true;
    frame.camera = options_.camera;
    frame.send_wall_us = wire::WallClockMicros();
    bytes = wire::EncodeFeatureFrame(frame);
    FrameRecord record;
    record.seq = seq;
    record.session_id = session_id_;
    record.wire_seq = frame.seq;
    record.send_steady_us = SteadyMicros();
    record.capture_time_us = frame.capture_time_us;
    if (frame.ground_truth_world_from_camera) {  // as the server sees it (wire round trip)
      auto wire_pose = wire::FromMessage(wire::ToMessage(*frame.ground_truth_world_from_camera));
      if (wire_pose) record.ground_truth_world_from_camera = *wire_pose;
    }
    record.send_wall_us = frame.send_wall_us;
    record.num_features = static_cast<int>(frame.features.size());
    record.encoded_bytes = bytes.size();
    records_.push_back(record);
  }
  if (hold) return seq;  // recorded, never answered
  Status published = transport_->Publish(wire::kFrameChannel, bytes);
  if (!published) return published;
  return seq;
}

bool ClientSession::WaitForPose(int64_t seq, double timeout_s) {
  std::unique_lock<std::mutex> lock(mutex_);
  return cv_.wait_until(lock, Deadline(timeout_s), [&] {
    return seq >= 1 && seq <= static_cast<int64_t>(records_.size()) && records_[seq - 1].answered;
  });
}

bool ClientSession::SyncMap(double timeout_s) {
  int64_t id = 0;
  int64_t full_before = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    id = session_id_;
    full_before = counters_.full_maps;
    ++counters_.resync_requests;
    last_resync_s_ = Now();
  }
  PublishControl(session_control_t::RESYNC_REQUEST, id, replica_.revision());
  std::unique_lock<std::mutex> lock(mutex_);
  return cv_.wait_until(lock, Deadline(timeout_s),
                        [&] { return counters_.full_maps > full_before; });
}

void ClientSession::End() {
  int64_t id = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!started_ || ended_) return;
    ended_ = true;
    id = session_id_;
  }
  PublishControl(session_control_t::BYE, id, 0);
  transport_->Stop();
}

void ClientSession::CheckAnsweredLocked(double now_s) {
  if (!outstanding_ || new_session_pending_ ||
      now_s - last_answer_s_ <= options_.unanswered_timeout_s) {
    return;
  }
  ++counters_.server_restarts;
  new_session_pending_ = true;
  M2S_LOG(kWarning) << "no answer from the server for " << now_s - last_answer_s_ << " s (session "
                    << session_id_ << "); starting a new session";
}

void ClientSession::OnMessage(const std::string& channel, const uint8_t* data, size_t size) {
  if (channel == wire::kPoseChannel) {
    auto pose = wire::DecodePoseEstimate(data, size);
    if (pose) return OnPose(*pose);
  } else if (channel == wire::kMapChannel) {
    auto delta = wire::DecodeMapDelta(data, size);
    if (delta) return OnMap(*delta);
  } else if (channel == wire::kSessionChannel) {
    auto message = wire::DecodeSessionControl(data, size);
    if (message) return OnSession(*message);
  } else if (channel == wire::kStatsChannel) {
    auto stats = wire::DecodeServerStats(data, size);
    if (stats) {
      std::lock_guard<std::mutex> lock(mutex_);
      ++counters_.stats_received;
      last_stats_ = std::move(*stats);
      return;
    }
  } else {
    return;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ++counters_.bad_messages;
}

bool ClientSession::FromOwnerLocked(int64_t instance) {
  if (acked_ && instance == server_instance_) return true;
  ++counters_.foreign_server_messages;
  return false;
}

void ClientSession::OnPose(const pose_estimate_t& pose) {
  const int64_t now_us = SteadyMicros();
  std::lock_guard<std::mutex> lock(mutex_);
  if (pose.session_id != session_id_) {
    ++counters_.other_session_messages;
    return;
  }
  if (!FromOwnerLocked(pose.server_instance)) return;
  const int64_t sent = static_cast<int64_t>(records_.size()) - session_first_seq_ + 1;
  if (pose.seq < 1 || pose.seq > sent) {
    ++counters_.bad_messages;
    return;
  }
  FrameRecord& record = records_[pose.seq + session_first_seq_ - 2];
  if (record.answered || record.session_id != pose.session_id) {
    ++counters_.bad_messages;
    return;
  }
  auto estimate = wire::FromMessage(pose.world_from_camera);
  record.answered = true;
  record.state = pose.state;
  record.map_id = pose.map_id;
  record.world_from_camera = estimate ? *estimate : Pose3();
  record.num_inliers = pose.num_inliers;
  record.keyframe_created = pose.keyframe_created;
  record.tracking_ms = pose.tracking_ms;
  record.latency_ms = static_cast<double>(now_us - record.send_steady_us) * 1e-3;
  ++counters_.poses_received;
  last_answer_s_ = Now();
  outstanding_ = false;
  cv_.notify_all();
}

void ClientSession::OnMap(const map_delta_t& delta) {
  int64_t resync_for = 0;
  int64_t revision = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (delta.session_id != session_id_) {
      ++counters_.other_session_messages;
      return;
    }
    if (!FromOwnerLocked(delta.server_instance)) return;
    const MapReplica::ApplyResult result = replica_.Apply(delta);
    switch (result) {
      case MapReplica::ApplyResult::kApplied:
        ++counters_.deltas_applied;
        break;
      case MapReplica::ApplyResult::kFull:
        ++counters_.full_maps;
        last_resync_s_ = -1e9;
        cv_.notify_all();
        break;
      case MapReplica::ApplyResult::kGap: {
        ++counters_.map_gaps;
        const double now = Now();
        if (now - last_resync_s_ >= options_.resync_min_interval_s) {
          last_resync_s_ = now;
          ++counters_.resync_requests;
          resync_for = session_id_;
          revision = replica_.revision();
        }
        break;
      }
      case MapReplica::ApplyResult::kStale:
      case MapReplica::ApplyResult::kOtherSession:
        break;
    }
  }
  if (resync_for != 0) PublishControl(session_control_t::RESYNC_REQUEST, resync_for, revision);
}

void ClientSession::OnSession(const session_control_t& message) {
  std::lock_guard<std::mutex> lock(mutex_);
  switch (message.type) {
    case session_control_t::HELLO_ACK:
      if (message.session_id != session_id_) return;
      ++counters_.acks;
      if (acked_ && message.server_instance != server_instance_) {
        ++counters_.foreign_server_messages;  // a second server claims the session
        return;
      }
      server_instance_ = message.server_instance;
      acked_ = true;
      servers_seen_.insert(message.server_instance);
      last_answer_s_ = Now();
      cv_.notify_all();
      return;
    case session_control_t::SESSION_ENDED:
      if (message.session_id != session_id_ || ended_) return;
      if (!FromOwnerLocked(message.server_instance)) return;
      ++counters_.sessions_ended_by_server;
      new_session_pending_ = true;
      M2S_LOG(kWarning) << "server ended session " << session_id_ << " (" << message.reason
                        << "); starting a new one";
      return;
    case session_control_t::REJECTED:
      // A full server never acknowledged the session: its refusal is believed only before
      // an acknowledgement, and it does not end anything (the HELLO is repeated when the
      // session is renewed after unanswered_timeout_s).
      if (message.session_id != session_id_ || acked_) return;
      ++counters_.rejected;
      rejected_ = true;  // no more HELLO repeats for this session
      last_rejection_ = message.reason;
      cv_.notify_all();
      M2S_LOG(kWarning) << "server rejected session " << session_id_ << ": " << message.reason;
      return;
    default:  // client -> server messages (ours or other clients') echo back on this channel
      return;
  }
}

std::vector<FrameRecord> ClientSession::Records() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return records_;
}

ClientCounters ClientSession::Counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  ClientCounters counters = counters_;
  counters.servers_seen = static_cast<int64_t>(servers_seen_.size());
  counters.refused_by_transport = transport_->refused_messages();
  return counters;
}

int64_t ClientSession::session_id() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return session_id_;
}

int64_t ClientSession::server_instance() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return server_instance_;
}

std::string ClientSession::LastRejection() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_rejection_;
}

std::optional<server_stats_t> ClientSession::LastStats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_stats_;
}

}  // namespace m2s::client
