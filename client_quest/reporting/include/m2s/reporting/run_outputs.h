// The outputs of a run (live headless client or replay), computed from the client's frame
// records and map replica: trajectory.tum, keyframes.tum, groundtruth.tum, metrics.json,
// trajectory.png (top view: ground truth vs the Sim3-aligned estimate) and map.png (the mesh
// with the aligned map points and keyframes, rendered with GLES by MapRenderer; drawn with
// OpenCV when no EGL display is available).
//
// Estimates are stamped with the frames' capture times, the ground-truth times, so the
// evaluation associates them exactly. When the run spans several sessions (the server ended
// one, or stopped answering), the run's trajectory is every session's tracked frames
// evaluated as one, and metrics.json also lists each session evaluated on its own.
//
//   RunInfo info{.projector = "gpu", .fps = 75};
//   Expected<RunMetrics> m = WriteRunOutputs("out", records, replica.Snapshot(), &scene, info);
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "m2s/client/client_session.h"

#include "m2s/client/map_replica.h"
#include "m2s/common/scene.h"
#include "m2s/common/status.h"

namespace m2s::reporting {

// The client's front end on one sent frame (wall clock, milliseconds): projection for vertex
// features; rendering, extraction and matching for an image front end.
struct FrontEndTime {
  int64_t seq = 0;             // the frame's FrameRecord::seq
  double projection_ms = 0.0;  // vertex: projection, noise and send budget
  double render_ms = 0.0;      // image: rendering the frame
  double extract_ms = 0.0;     // image: grey conversion, keypoints and descriptors
  double match_ms = 0.0;       // image: track ids (frame to frame, re-identification)
  // Image: keypoints whose id came from the previous frame, from the map, or was new.
  int tracked = 0, reidentified = 0, new_ids = 0;
  double total_ms() const { return projection_ms + render_ms + extract_ms + match_ms; }
};

struct RunInfo {
  std::string projector = "cpu";
  std::string transport = "on-device";
  double fps = 75.0;
  bool fast = false;
  int64_t frames_total = 0;           // frames of the resampled trajectory
  int64_t frames_skipped_client = 0;  // not sent: the client fell behind real time
  int64_t sessions = 1;
  int64_t server_restarts = 0;
  int64_t resync_requests = 0;
  int64_t bus_refused = 0;              // refused by the bus checks (forged, replayed, stale)
  int64_t foreign_server_messages = 0;  // for our session from another server instance
  double wall_s = 0.0;
  bool render_map = true;            // write map.png
  std::string map_group;             // the map group the client joined (empty: none)
  int64_t servers_seen = 0;          // distinct server instances that acknowledged the client
  std::string front_end = "vertex";  // "vertex" or "orb"
  // Feature ids are scene vertex ids (false for an image front end's track ids: then there is
  // no map error, map_rmse stays -1).
  bool ids_are_vertices = true;
  std::vector<FrontEndTime> front_end_times;  // per sent frame; empty when not measured
};

// One client session of a run (a run has several when the server ended or stopped answering
// one), evaluated in its own frame.
struct SessionMetrics {
  int64_t id = 0;
  int64_t frames_sent = 0;
  int64_t frames_processed = 0;
  int64_t frames_tracked = 0;
  int64_t frames_lost = 0;
  // Tracked in a SLAM map other than the session's final one (a map the server started after
  // losing track and had not merged when it sent the pose): counted as tracked, left out of
  // ate_rmse (their poses are in another world).
  int64_t frames_in_unmerged_maps = 0;
  double ate_rmse = -1.0;  // metres, Sim3-aligned; -1 when fewer than 3 tracked frames
  std::optional<Sim3> world_from_estimate;
};

struct RunMetrics {
  int64_t frames_total = 0;
  int64_t frames_processed = 0;  // a pose arrived
  int64_t frames_skipped = 0;    // never processed (skipped by the client or the server queue)
  int64_t frames_lost = 0;       // processed, state LOST
  int64_t frames_tracked = 0;    // processed, state OK or RELOCALIZED
  int64_t frames_in_unmerged_maps = 0;  // over the sessions (SessionMetrics)
  // Metres: every tracked frame of every session in its session's final map, one Sim3
  // alignment (a run split over sessions in different frames shows here); -1 when fewer than 3
  // tracked frames.
  double ate_rmse = -1.0;
  double ate_scale = 0.0;
  double map_rmse = -1.0;  // metres, map points aligned by the trajectory's Sim3
  double map_median = -1.0;
  double map_p95 = -1.0;
  double tracking_ms_p50 = 0.0, tracking_ms_p95 = 0.0;
  double latency_ms_p50 = 0.0, latency_ms_p99 = 0.0;
  // The front end per sent frame (FrontEndTime; 0 when not measured), and the tracking time
  // per frame: front end + the back end's tracking_ms, over the processed frames.
  std::string front_end = "vertex";
  double front_end_ms_p50 = 0.0, front_end_ms_p95 = 0.0;
  double projection_ms_p50 = 0.0, render_ms_p50 = 0.0, extract_ms_p50 = 0.0, match_ms_p50 = 0.0;
  double time_per_frame_ms_p50 = 0.0, time_per_frame_ms_p95 = 0.0;
  // Image front end, per sent frame: keypoints with the previous frame's id, the map's, a new.
  double tracked_ids_per_frame = 0.0, reidentified_per_frame = 0.0, new_ids_per_frame = 0.0;
  double bytes_per_feature = 0.0;
  double features_per_frame = 0.0;
  int64_t keyframes = 0;
  int64_t map_points = 0;
  std::string projector;
  double fps = 0.0;
  std::optional<std::string> map_group;  // null in metrics.json without a group
  int64_t servers_seen = 0;
  // With a map group: seconds from the first frame sent to the first tracked pose in the
  // group's map (map_id 0), on the client's steady clock; null without a group or never.
  std::optional<double> merged_at_s;
  std::string map_png;         // path, empty when not written
  std::string trajectory_png;  // path
  std::vector<SessionMetrics> sessions;
};

Expected<RunMetrics> WriteRunOutputs(const std::string& out_dir,
                                     const std::vector<client::FrameRecord>& records,
                                     const client::MapSnapshot& map, const Scene* scene,
                                     const Camera& camera, const RunInfo& info);

// Seconds from the first frame sent to the arrival of the first tracked pose whose map_id is 0
// (the map group's map); nullopt when there is none.
std::optional<double> FirstPoseInGroupMapSeconds(const std::vector<client::FrameRecord>& records);

// One line: frames, ATE, map error, latency, tracking time (and with front-end times, the
// tracking time per frame), output folder.
std::string SummaryLine(const RunMetrics& metrics, const std::string& out_dir);

// The trajectory (world_from_camera at capture times) of the tracked frames of `session_id`.
std::vector<client::FrameRecord> TrackedFrames(const std::vector<client::FrameRecord>& records,
                                               int64_t session_id);

}  // namespace m2s::reporting
