#include "m2s/reporting/run_outputs.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "m2s/common/evaluation.h"
#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "m2s/common/trajectory.h"
#include "map_image.h"

namespace m2s::reporting {
namespace {

bool Tracked(int8_t state) {
  return state == pose_estimate_t::STATE_OK || state == pose_estimate_t::STATE_RELOCALIZED;
}

double Seconds(int64_t micros) { return static_cast<double>(micros) * 1e-6; }

Expected<Trajectory> MakeTrajectory(std::vector<TimedPose> poses) {
  return Trajectory::FromPoses(std::move(poses));
}

// Top view (x, y; the world is z up) of the ground truth and the aligned estimate.
Status WriteTrajectoryPng(const std::string& path, const std::vector<Eigen::Vector3d>& truth,
                          const std::vector<Eigen::Vector3d>& estimate, double ate_rmse) {
  constexpr int kSize = 900;
  constexpr int kMargin = 40;
  cv::Mat image(kSize, kSize, CV_8UC3, cv::Scalar(255, 255, 255));
  Eigen::AlignedBox2d box;
  for (const auto& p : truth) box.extend(p.head<2>());
  for (const auto& p : estimate) box.extend(p.head<2>());
  if (box.isEmpty()) box.extend(Eigen::Vector2d(-1, -1)).extend(Eigen::Vector2d(1, 1));
  const double extent = std::max(box.sizes().maxCoeff(), 1e-3);
  const double scale = (kSize - 2 * kMargin) / extent;
  const Eigen::Vector2d centre = box.center();
  auto pixel = [&](const Eigen::Vector3d& p) {
    return cv::Point(static_cast<int>(std::lround(kSize / 2 + (p.x() - centre.x()) * scale)),
                     static_cast<int>(std::lround(kSize / 2 - (p.y() - centre.y()) * scale)));
  };
  // Metre grid.
  for (double x = std::floor(box.min().x()); x <= box.max().x(); x += 1.0) {
    cv::line(image, pixel({x, box.min().y(), 0}), pixel({x, box.max().y(), 0}),
             cv::Scalar(230, 230, 230), 1);
  }
  for (double y = std::floor(box.min().y()); y <= box.max().y(); y += 1.0) {
    cv::line(image, pixel({box.min().x(), y, 0}), pixel({box.max().x(), y, 0}),
             cv::Scalar(230, 230, 230), 1);
  }
  for (size_t i = 1; i < truth.size(); ++i) {
    cv::line(image, pixel(truth[i - 1]), pixel(truth[i]), cv::Scalar(60, 60, 60), 2, cv::LINE_AA);
  }
  for (size_t i = 1; i < estimate.size(); ++i) {
    cv::line(image, pixel(estimate[i - 1]), pixel(estimate[i]), cv::Scalar(40, 40, 230), 1,
             cv::LINE_AA);
  }
  std::ostringstream legend;
  legend << "top view: ground truth (grey), Sim3-aligned estimate (red), ATE "
         << std::setprecision(3) << ate_rmse << " m; grid 1 m";
  cv::putText(image, legend.str(), cv::Point(10, 24), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  try {
    if (!cv::imwrite(path, image)) return Status::Error("cannot write " + path);
  } catch (const cv::Exception& e) {
    return Status::Error("cannot write " + path + ": " + e.what());
  }
  return Status::Ok();
}

Status WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  if (!out) return Status::Error("cannot write " + path);
  return Status::Ok();
}

// Sim3-aligned evaluation of tracked poses; nullopt with fewer than 3 or when it fails.
std::optional<TrajectoryEvaluation> EvaluateTracked(const Trajectory& truth,
                                                    const Trajectory& estimate) {
  if (estimate.size() < 3) return std::nullopt;
  EvaluationOptions evaluation;
  evaluation.alignment = Alignment::kSim3;
  evaluation.association.max_dt = 1e-4;
  auto result = EvaluateTrajectory(truth, estimate, evaluation);
  if (!result) {
    M2S_LOG(kWarning) << "evaluation failed: " << result.error();
    return std::nullopt;
  }
  return std::move(*result);
}

// The SLAM map of each session's last tracked frame: poses in other maps are in other worlds.
std::map<int64_t, int> FinalMaps(const std::vector<client::FrameRecord>& records) {
  std::map<int64_t, int> final_map;
  for (const auto& r : records) {
    if (r.answered && Tracked(r.state)) final_map[r.session_id] = r.map_id;
  }
  return final_map;
}

// Every session of the run in the order it started, each evaluated in its own frame.
std::vector<SessionMetrics> SummariseSessions(const std::vector<client::FrameRecord>& records,
                                              const Trajectory& truth) {
  std::vector<SessionMetrics> sessions;
  for (const auto& r : records) {
    if (sessions.empty() || sessions.back().id != r.session_id) {
      sessions.push_back(SessionMetrics{});
      sessions.back().id = r.session_id;
    }
    SessionMetrics& s = sessions.back();
    ++s.frames_sent;
    if (!r.answered) continue;
    ++s.frames_processed;
    s.frames_lost += r.state == pose_estimate_t::STATE_LOST;
    s.frames_tracked += Tracked(r.state);
  }
  const std::map<int64_t, int> final_map = FinalMaps(records);
  for (SessionMetrics& s : sessions) {
    std::vector<TimedPose> poses;
    for (const auto& r : TrackedFrames(records, s.id)) {
      if (r.map_id != final_map.at(s.id)) {
        ++s.frames_in_unmerged_maps;
        continue;
      }
      poses.push_back({Seconds(r.capture_time_us), r.world_from_camera});
    }
    auto estimate = MakeTrajectory(poses);
    if (!estimate) continue;
    if (auto result = EvaluateTracked(truth, *estimate)) {
      s.ate_rmse = result->ate.rmse;
      s.world_from_estimate = result->reference_from_estimate;
    }
  }
  return sessions;
}

// The front-end figures of RunMetrics from the per-frame times (records[seq - 1]).
void SummariseFrontEnd(const std::vector<client::FrameRecord>& records, const RunInfo& info,
                       RunMetrics* m) {
  m->front_end = info.front_end;
  const std::vector<FrontEndTime>& times = info.front_end_times;
  if (times.empty()) return;
  std::vector<double> total, projection, render, extract, match, per_frame;
  double tracked = 0, reidentified = 0, new_ids = 0;
  for (const FrontEndTime& t : times) {
    total.push_back(t.total_ms());
    projection.push_back(t.projection_ms);
    render.push_back(t.render_ms);
    extract.push_back(t.extract_ms);
    match.push_back(t.match_ms);
    tracked += t.tracked;
    reidentified += t.reidentified;
    new_ids += t.new_ids;
    const size_t index = static_cast<size_t>(t.seq - 1);
    if (t.seq >= 1 && index < records.size() && records[index].answered) {
      per_frame.push_back(t.total_ms() + records[index].tracking_ms);
    }
  }
  m->front_end_ms_p50 = Percentile(total, 0.5);
  m->front_end_ms_p95 = Percentile(total, 0.95);
  m->projection_ms_p50 = Percentile(projection, 0.5);
  m->render_ms_p50 = Percentile(render, 0.5);
  m->extract_ms_p50 = Percentile(extract, 0.5);
  m->match_ms_p50 = Percentile(match, 0.5);
  m->time_per_frame_ms_p50 = Percentile(per_frame, 0.5);
  m->time_per_frame_ms_p95 = Percentile(per_frame, 0.95);
  const double n = static_cast<double>(times.size());
  m->tracked_ids_per_frame = tracked / n;
  m->reidentified_per_frame = reidentified / n;
  m->new_ids_per_frame = new_ids / n;
}

}  // namespace

std::vector<client::FrameRecord> TrackedFrames(const std::vector<client::FrameRecord>& records,
                                               int64_t session_id) {
  std::vector<client::FrameRecord> out;
  for (const auto& r : records) {
    if (r.answered && r.session_id == session_id && Tracked(r.state)) out.push_back(r);
  }
  return out;
}

std::optional<double> FirstPoseInGroupMapSeconds(const std::vector<client::FrameRecord>& records) {
  if (records.empty()) return std::nullopt;
  int64_t first_sent_us = records.front().send_steady_us;
  std::optional<double> first_in_group_us;
  for (const auto& r : records) {
    first_sent_us = std::min(first_sent_us, r.send_steady_us);
    if (!r.answered || !Tracked(r.state) || r.map_id != 0) continue;
    const double received_us = static_cast<double>(r.send_steady_us) + r.latency_ms * 1e3;
    if (!first_in_group_us || received_us < *first_in_group_us) first_in_group_us = received_us;
  }
  if (!first_in_group_us) return std::nullopt;
  return (*first_in_group_us - static_cast<double>(first_sent_us)) * 1e-6;
}

Expected<RunMetrics> WriteRunOutputs(const std::string& out_dir,
                                     const std::vector<client::FrameRecord>& records,
                                     const client::MapSnapshot& map, const Scene* scene,
                                     const Camera& camera, const RunInfo& info) {
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) return Status::Error("cannot create " + out_dir + ": " + ec.message());
  const auto path = [&out_dir](const char* name) {
    return (std::filesystem::path(out_dir) / name).string();
  };

  RunMetrics m;
  m.projector = info.projector;
  m.fps = info.fps;
  m.frames_total = std::max<int64_t>(info.frames_total, static_cast<int64_t>(records.size()));
  std::vector<double> tracking_ms, latency_ms;
  std::map<int64_t, int64_t> tracked_per_session;
  size_t feature_bytes = 0, features = 0;
  for (const auto& r : records) {
    features += static_cast<size_t>(r.num_features);
    feature_bytes += r.encoded_bytes - wire::FeatureFrameEncodedSize(0);
    if (!r.answered) continue;
    ++m.frames_processed;
    if (r.state == pose_estimate_t::STATE_LOST) ++m.frames_lost;
    if (Tracked(r.state)) {
      ++m.frames_tracked;
      ++tracked_per_session[r.session_id];
    }
    tracking_ms.push_back(r.tracking_ms);
    latency_ms.push_back(r.latency_ms);
  }
  m.frames_skipped = m.frames_total - m.frames_processed;
  m.tracking_ms_p50 = Percentile(tracking_ms, 0.5);
  m.tracking_ms_p95 = Percentile(tracking_ms, 0.95);
  m.latency_ms_p50 = Percentile(latency_ms, 0.5);
  m.latency_ms_p99 = Percentile(latency_ms, 0.99);
  SummariseFrontEnd(records, info, &m);
  m.bytes_per_feature = features > 0 ? static_cast<double>(feature_bytes) / features : 0.0;
  m.features_per_frame = records.empty() ? 0.0 : static_cast<double>(features) / records.size();
  m.keyframes = static_cast<int64_t>(map.keyframes.size());
  m.map_points = static_cast<int64_t>(map.points.size());
  m.servers_seen = info.servers_seen;
  if (!info.map_group.empty()) {
    m.map_group = info.map_group;
    m.merged_at_s = FirstPoseInGroupMapSeconds(records);
  }

  // Ground truth at every frame time. The run's trajectory is every tracked frame of every
  // session, evaluated as one (a run split over sessions shows as such); each session is also
  // evaluated on its own.
  std::vector<TimedPose> truth_poses;
  for (const auto& r : records) {
    if (r.ground_truth_world_from_camera) {
      truth_poses.push_back({Seconds(r.capture_time_us), *r.ground_truth_world_from_camera});
    }
  }
  auto truth = MakeTrajectory(truth_poses);
  if (!truth) return Status::Error("ground truth: " + truth.error());
  std::vector<TimedPose> estimate_poses;
  const std::map<int64_t, int> final_map = FinalMaps(records);
  for (const auto& r : records) {
    if (r.answered && Tracked(r.state) && r.map_id == final_map.at(r.session_id)) {
      estimate_poses.push_back({Seconds(r.capture_time_us), r.world_from_camera});
    }
  }
  auto estimate = MakeTrajectory(estimate_poses);
  if (!estimate) return Status::Error("estimate: " + estimate.error());
  if (Status s = WriteTum(path("groundtruth.tum"), *truth); !s) return s;
  if (Status s = WriteTum(path("trajectory.tum"), *estimate); !s) return s;
  std::vector<TimedPose> keyframe_poses;
  for (const auto& k : map.keyframes) keyframe_poses.push_back({k.timestamp, k.world_from_camera});
  auto keyframes = MakeTrajectory(keyframe_poses);
  if (keyframes) {
    if (Status s = WriteTum(path("keyframes.tum"), *keyframes); !s) return s;
  }

  Sim3 world_from_estimate;
  std::vector<Eigen::Vector3d> truth_xyz, estimate_xyz;
  for (const auto& p : truth->poses()) truth_xyz.push_back(p.world_from_camera.translation());
  if (auto run = EvaluateTracked(*truth, *estimate)) {
    m.ate_rmse = run->ate.rmse;
    m.ate_scale = run->scale;
    world_from_estimate = run->reference_from_estimate;
    for (const auto& p : estimate->poses()) {
      estimate_xyz.push_back(world_from_estimate * p.world_from_camera.translation());
    }
  }
  m.sessions = SummariseSessions(records, *truth);
  for (const SessionMetrics& session : m.sessions) {
    m.frames_in_unmerged_maps += session.frames_in_unmerged_maps;
  }
  for (const SessionMetrics& session : m.sessions) {
    if (session.id != map.session_id || !session.world_from_estimate) continue;
    // The map is in the frame of its session.
    world_from_estimate = *session.world_from_estimate;
    if (scene && info.ids_are_vertices && !map.points.empty()) {
      std::vector<MapPoint> points;
      for (size_t i = 0; i < map.points.size(); ++i) {
        points.push_back({map.point_ids[i], map.points[i].cast<double>()});
      }
      auto map_error = EvaluateMap(points, scene->positions, world_from_estimate);
      if (map_error) {
        m.map_rmse = map_error->rmse;
        m.map_median = map_error->median;
        m.map_p95 = map_error->p95;
      }
    }
  }

  m.trajectory_png = path("trajectory.png");
  if (Status s = WriteTrajectoryPng(m.trajectory_png, truth_xyz, estimate_xyz, m.ate_rmse); !s) {
    return s;
  }
  if (info.render_map && scene) {
    MapImageInput input;
    input.scene = scene;
    input.camera = camera;
    for (const auto& p : map.points) input.points.push_back(world_from_estimate * p.cast<double>());
    for (const auto& k : map.keyframes) {
      input.keyframes.push_back(world_from_estimate.TransformPose(k.world_from_camera));
    }
    if (!truth->empty()) input.ground_truth_last = truth->poses().back().world_from_camera;
    m.map_png = path("map.png");
    if (Status s = WriteMapPng(m.map_png, input); !s) {
      M2S_LOG(kWarning) << "map.png: " << s.message();
      m.map_png.clear();
    }
  }

  nlohmann::json j;
  j["frames_total"] = m.frames_total;
  j["frames_processed"] = m.frames_processed;
  j["frames_skipped"] = m.frames_skipped;
  j["frames_skipped_client"] = info.frames_skipped_client;
  j["frames_lost"] = m.frames_lost;
  j["frames_tracked"] = m.frames_tracked;
  j["frames_in_unmerged_maps"] = m.frames_in_unmerged_maps;
  j["ate_rmse"] = m.ate_rmse;
  j["ate_scale"] = m.ate_scale;
  j["map_rmse"] = m.map_rmse;
  j["map_median"] = m.map_median;
  j["map_p95"] = m.map_p95;
  j["tracking_ms_p50"] = m.tracking_ms_p50;
  j["tracking_ms_p95"] = m.tracking_ms_p95;
  j["latency_ms_p50"] = m.latency_ms_p50;
  j["latency_ms_p99"] = m.latency_ms_p99;
  j["front_end"] = m.front_end;
  j["front_end_ms_p50"] = m.front_end_ms_p50;
  j["front_end_ms_p95"] = m.front_end_ms_p95;
  j["projection_ms_p50"] = m.projection_ms_p50;
  j["render_ms_p50"] = m.render_ms_p50;
  j["extract_ms_p50"] = m.extract_ms_p50;
  j["match_ms_p50"] = m.match_ms_p50;
  j["time_per_frame_ms_p50"] = m.time_per_frame_ms_p50;
  j["time_per_frame_ms_p95"] = m.time_per_frame_ms_p95;
  j["tracked_ids_per_frame"] = m.tracked_ids_per_frame;
  j["reidentified_per_frame"] = m.reidentified_per_frame;
  j["new_ids_per_frame"] = m.new_ids_per_frame;
  j["bytes_per_feature"] = m.bytes_per_feature;
  j["features_per_frame"] = m.features_per_frame;
  j["keyframes"] = m.keyframes;
  j["map_points"] = m.map_points;
  j["projector"] = m.projector;
  j["transport"] = info.transport;
  j["fps"] = m.fps;
  j["fast"] = info.fast;
  j["sessions"] = info.sessions;
  j["server_restarts"] = info.server_restarts;
  j["resync_requests"] = info.resync_requests;
  j["bus_refused"] = info.bus_refused;
  j["foreign_server_messages"] = info.foreign_server_messages;
  j["wall_s"] = info.wall_s;
  j["map_group"] = m.map_group ? nlohmann::json(*m.map_group) : nlohmann::json(nullptr);
  j["servers_seen"] = m.servers_seen;
  j["merged_at_s"] = m.merged_at_s ? nlohmann::json(*m.merged_at_s) : nlohmann::json(nullptr);
  nlohmann::json sessions = nlohmann::json::array();
  for (const SessionMetrics& session : m.sessions) {
    sessions.push_back({{"session_id", session.id},
                        {"frames_sent", session.frames_sent},
                        {"frames_processed", session.frames_processed},
                        {"frames_tracked", session.frames_tracked},
                        {"frames_lost", session.frames_lost},
                        {"frames_in_unmerged_maps", session.frames_in_unmerged_maps},
                        {"ate_rmse", session.ate_rmse}});
  }
  j["session_list"] = sessions;
  if (Status s = WriteText(path("metrics.json"), j.dump(2) + "\n"); !s) return s;
  return m;
}

std::string SummaryLine(const RunMetrics& m, const std::string& out_dir) {
  std::ostringstream line;
  line << std::fixed << std::setprecision(3) << "frames " << m.frames_processed << "/"
       << m.frames_total << " processed (" << m.frames_skipped << " skipped, " << m.frames_lost
       << " lost, " << m.frames_in_unmerged_maps << " in unmerged maps), ATE " << m.ate_rmse * 1e3
       << " mm, map error " << m.map_rmse * 1e3 << " mm (p95 " << m.map_p95 * 1e3 << " mm), "
       << m.keyframes << " keyframes, " << m.map_points << " points, latency p50 "
       << std::setprecision(2) << m.latency_ms_p50 << " ms p99 " << m.latency_ms_p99
       << " ms, tracking p50 " << m.tracking_ms_p50 << " ms, ";
  if (m.time_per_frame_ms_p50 > 0) {
    line << "tracking time per frame p50 " << m.time_per_frame_ms_p50 << " ms (" << m.front_end
         << " front end " << m.front_end_ms_p50 << " ms), ";
  }
  line << m.bytes_per_feature << " B/feature, " << m.projector << " projector -> " << out_dir;
  return line.str();
}

}  // namespace m2s::reporting
