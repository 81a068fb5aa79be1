// ClientSession: one client's conversation with a SLAM server over any Transport.
//
// Start() opens the transport and says HELLO (with the camera, the map group to join if any
// and, for reproducible runs, the FLAG_DETERMINISTIC flag). The HELLO is repeated every
// hello_resend_s until a HELLO_ACK or a REJECTED arrives (Start() waits up to hello_timeout_s
// for it, Send() keeps repeating it): a sharded server (m2s_server --shard) opens sessions only
// from a HELLO and ignores frames that come before it, and only the server of the session's
// shard answers. A session with a map group sends no frame before the acknowledgement (such
// frames are recorded, never answered: frames_held).
//
// Send() stamps and publishes encoded frames (sequence numbers restart at 1 in every session);
// pose estimates are matched to the frames by sequence number (latency = pose received - frame
// sent, both on this client's steady clock); map deltas keep a MapReplica current, a revision
// gap triggers a rate-limited RESYNC_REQUEST.
//
// Trust: the session belongs to the server instance whose HELLO_ACK answered it. Poses, map
// deltas, SESSION_ENDED and REJECTED from any other instance are counted
// (foreign_server_messages) and ignored, so a stray publisher cannot feed or end the session
// without knowing the instance (and, on a keyed bus, without the key). A server that stops
// answering (no pose for unanswered_timeout_s while frames are outstanding, e.g. it restarted)
// and SESSION_ENDED from the owning server start a new session (new id, HELLO, empty replica)
// at the next Send(). Undecodable or invalid messages on any channel are counted and ignored.
//
// Thread-safety: Send(), the Wait*() calls and the accessors may be called from any thread;
// messages arrive on the transport's thread. No lock is held while publishing.
//
//   LcmTransport transport(url);
//   ClientSession session(&transport, {.camera = camera});
//   if (Status s = session.Start(); !s) return s;
//   auto seq = session.Send(frame);
//   session.WaitForPose(*seq, 1.0);
//   session.End();
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "m2s/client/map_replica.h"
#include "m2s/client/transport.h"
#include "m2s/common/status.h"
#include "m2s/common/wire_format.h"

namespace m2s::client {

struct ClientSessionOptions {
  Camera camera;
  // Ask the server for deterministic SLAM (HELLO flag), for --fast runs and their replays.
  bool deterministic = false;
  std::string client_name = "m2s_client";
  // The map group the session joins (empty: none); wire::CheckMapGroupName must accept it.
  std::string map_group;
  // How long Start() waits for HELLO_ACK (an unsharded server also opens the session from
  // frames, so this is not fatal), and the period of HELLO repeats until it arrives.
  double hello_timeout_s = 2.0;
  double hello_resend_s = 0.25;
  // Least time between two resync requests while the replica has a gap.
  double resync_min_interval_s = 0.25;
  // Seed for session ids (0: random).
  uint64_t session_seed = 0;
  // With frames outstanding and no pose from the owning server for this long, the session is
  // given up and a new one started at the next Send().
  double unanswered_timeout_s = 3.0;
  // Seconds on the clock of the timeouts above (empty: std::chrono::steady_clock); tests
  // inject one to step time instead of sleeping. Latencies always use the steady clock.
  std::function<double()> clock_s;
};

// What happened to one sent frame.
struct FrameRecord {
  int64_t seq = 0;  // client-wide: records[seq - 1]
  int64_t session_id = 0;
  int64_t wire_seq = 0;  // the sequence number in its session (what the server sees)
  int64_t capture_time_us = 0;
  std::optional<Pose3> ground_truth_world_from_camera;
  int64_t send_wall_us = 0;
  int64_t send_steady_us = 0;  // this client's steady clock (latency)
  int num_features = 0;
  size_t encoded_bytes = 0;
  bool answered = false;  // a pose estimate arrived
  int8_t state = pose_estimate_t::STATE_NOT_INITIALIZED;
  Pose3 world_from_camera;
  int num_inliers = 0;
  bool keyframe_created = false;
  float tracking_ms = 0.f;
  double latency_ms = 0.0;
  int map_id = 0;  // the SLAM map the pose is in (pose_estimate_t::map_id)
};

struct ClientCounters {
  int64_t sessions_started = 0;
  int64_t server_restarts = 0;  // sessions given up: the server stopped answering
  int64_t sessions_ended_by_server = 0;
  int64_t rejected = 0;      // REJECTED by the server (e.g. full)
  int64_t acks = 0;          // HELLO_ACKs received for our sessions
  int64_t hellos_sent = 0;   // first HELLOs and repeats
  int64_t servers_seen = 0;  // distinct server instances that acknowledged a HELLO
  int64_t frames_held = 0;   // with a map group, not sent: the HELLO was not acknowledged yet
  int64_t foreign_server_messages = 0;  // for our session, from another server instance
  int64_t poses_received = 0;
  int64_t deltas_applied = 0;
  int64_t full_maps = 0;
  int64_t map_gaps = 0;
  int64_t resync_requests = 0;
  int64_t stats_received = 0;
  int64_t other_session_messages = 0;
  int64_t bad_messages = 0;          // failed to decode or validate, any channel
  int64_t refused_by_transport = 0;  // failed authentication / replay checks (keyed bus)
};

class ClientSession {
 public:
  ClientSession(Transport* transport, ClientSessionOptions options);
  ~ClientSession();  // End()

  Status Start();
  // Publishes the frame with session_id, seq and send_wall_us filled in; returns its seq.
  Expected<int64_t> Send(wire::FeatureFrame frame);
  // Waits until the pose for `seq` arrived; false on timeout.
  bool WaitForPose(int64_t seq, double timeout_s);
  // Asks for the whole map and waits until it has been applied; false on timeout.
  bool SyncMap(double timeout_s);
  // Says BYE and stops the transport. Idempotent.
  void End();

  std::vector<FrameRecord> Records() const;
  const MapReplica& replica() const { return replica_; }
  ClientCounters Counters() const;
  int64_t session_id() const;
  int64_t server_instance() const;
  std::optional<server_stats_t> LastStats() const;
  // The reason of the last REJECTED the session believed (empty: none).
  std::string LastRejection() const;
  Transport* transport() { return transport_; }

 private:
  void OnMessage(const std::string& channel, const uint8_t* data, size_t size);
  void OnPose(const pose_estimate_t& pose);
  void OnMap(const map_delta_t& delta);
  void OnSession(const session_control_t& message);
  // True when `instance` owns the current session; counts the message as foreign otherwise.
  bool FromOwnerLocked(int64_t instance);
  // Marks the session for renewal when the server has not answered for too long.
  void CheckAnsweredLocked(double now_s);
  void BeginSession();
  void PublishControl(int8_t type, int64_t session_id, int64_t last_revision);
  // Publishes the current session's HELLO.
  void SendHello();
  // Repeats the HELLO when unacknowledged for hello_resend_s; returns whether it did.
  bool ResendHelloIfDue();

  Transport* const transport_;
  const ClientSessionOptions options_;
  // Now on options_.clock_s, or the steady clock.
  double Now() const;
  MapReplica replica_;

  mutable std::mutex mutex_;  // guards the members below
  std::condition_variable cv_;
  std::mt19937_64 rng_;
  bool started_ = false;
  bool ended_ = false;
  int64_t session_id_ = 0;
  int64_t server_instance_ = 0;
  bool acked_ = false;
  bool rejected_ = false;  // REJECTED before an acknowledgement
  std::string last_rejection_;
  bool new_session_pending_ = false;
  int64_t next_seq_ = 1;
  int64_t session_first_seq_ = 1;  // client-wide seq of the session's first frame
  double last_answer_s_ = 0.0;     // HELLO or the last answer of the owning server
  double last_hello_s_ = 0.0;
  std::set<int64_t> servers_seen_;    // instances that acknowledged a HELLO of ours
  bool outstanding_ = false;          // frames sent since that answer
  std::vector<FrameRecord> records_;  // records_[seq - 1]
  ClientCounters counters_;
  double last_resync_s_ = -1e9;
  std::optional<server_stats_t> last_stats_;
};

}  // namespace m2s::client
