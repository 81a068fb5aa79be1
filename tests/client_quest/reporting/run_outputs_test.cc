// metrics.json's map group keys: map_group, servers_seen and merged_at_s (seconds from the
// first frame sent to the first tracked pose in the group's map, map_id 0), and the front
// end's times, from synthetic frame records with known send times, latencies and times.
#include "m2s/reporting/run_outputs.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace m2s::reporting {
namespace {

namespace fs = std::filesystem;

// Ten frames 0.1 s apart, each answered after 5 ms; frames 0-3 tracked in the agent's own map
// (map_id 1), frame 1 lost, frames 4-9 in the group's map (map_id 0).
std::vector<client::FrameRecord> Records() {
  std::vector<client::FrameRecord> records;
  for (int k = 0; k < 10; ++k) {
    client::FrameRecord r;
    r.seq = k + 1;
    r.session_id = 7;
    r.wire_seq = k + 1;
    r.capture_time_us = k * 100000;
    r.send_steady_us = 1000000 + k * 100000;
    r.ground_truth_world_from_camera =
        Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * k, 0.01 * k * k, 0));
    r.world_from_camera = *r.ground_truth_world_from_camera;
    r.answered = true;
    r.state = k == 1 ? pose_estimate_t::STATE_LOST : pose_estimate_t::STATE_OK;
    r.latency_ms = 5.0;
    r.map_id = k < 4 ? 1 : 0;
    r.num_features = 10;
    records.push_back(r);
  }
  return records;
}

TEST(RunOutputsTest, MergedAtIsTheFirstTrackedPoseInTheGroupsMap) {
  std::vector<client::FrameRecord> records = Records();
  ASSERT_TRUE(FirstPoseInGroupMapSeconds(records).has_value());
  EXPECT_NEAR(*FirstPoseInGroupMapSeconds(records), 0.405, 1e-12);  // frame 4 + 5 ms
  records[1].map_id = 0;  // lost: not a pose in the group's map
  EXPECT_NEAR(*FirstPoseInGroupMapSeconds(records), 0.405, 1e-12);
  for (auto& r : records) r.map_id = 2;
  EXPECT_FALSE(FirstPoseInGroupMapSeconds(records).has_value());
  EXPECT_FALSE(FirstPoseInGroupMapSeconds({}).has_value());
}

TEST(RunOutputsTest, MetricsJsonHoldsTheMapGroupKeys) {
  const fs::path dir =
      fs::temp_directory_path() / ("m2s_run_outputs_test_" + std::to_string(::getpid()));
  client::MapSnapshot map;
  map.session_id = 7;
  RunInfo info;
  info.render_map = false;
  info.frames_total = 10;
  info.servers_seen = 1;
  auto read_metrics = [&](const RunInfo& run) {
    auto metrics = WriteRunOutputs(dir.string(), Records(), map, nullptr, Camera(), run);
    EXPECT_TRUE(metrics.ok()) << metrics.error();
    std::ifstream in(dir / "metrics.json");
    return nlohmann::json::parse(in);
  };
  const nlohmann::json alone = read_metrics(info);
  EXPECT_TRUE(alone.at("map_group").is_null());
  EXPECT_TRUE(alone.at("merged_at_s").is_null());
  EXPECT_EQ(alone.at("servers_seen"), 1);
  info.map_group = "room-a";
  info.servers_seen = 2;
  const nlohmann::json grouped = read_metrics(info);
  EXPECT_EQ(grouped.at("map_group"), "room-a");
  EXPECT_EQ(grouped.at("servers_seen"), 2);
  EXPECT_NEAR(grouped.at("merged_at_s").get<double>(), 0.405, 1e-12);
  fs::remove_all(dir);
}

TEST(RunOutputsTest, TrackingTimePerFrameAddsTheFrontEndToTheTracking) {
  const fs::path dir =
      fs::temp_directory_path() / ("m2s_run_outputs_front_end_" + std::to_string(::getpid()));
  std::vector<client::FrameRecord> records = Records();
  RunInfo info;
  info.render_map = false;
  info.front_end = "orb";
  info.ids_are_vertices = false;
  // Frame k: tracking k ms; front end 10 + k ms (render 4, extract 3 + k, match 3). Frame 9 is
  // never answered: its front end counts, its time per frame does not.
  for (int k = 0; k < 10; ++k) {
    records[k].tracking_ms = static_cast<float>(k);
    FrontEndTime t;
    t.seq = records[k].seq;
    t.render_ms = 4.0;
    t.extract_ms = 3.0 + k;
    t.match_ms = 3.0;
    t.tracked = 2 * k;
    info.front_end_times.push_back(t);
  }
  records[9].answered = false;
  auto m = WriteRunOutputs(dir.string(), records, client::MapSnapshot(), nullptr, Camera(), info);
  ASSERT_TRUE(m.ok()) << m.error();
  EXPECT_EQ(m->front_end, "orb");
  EXPECT_DOUBLE_EQ(m->render_ms_p50, 4.0);
  EXPECT_DOUBLE_EQ(m->extract_ms_p50, 7.5);          // median of 3..12
  EXPECT_DOUBLE_EQ(m->front_end_ms_p50, 14.5);       // median of 10..19
  EXPECT_DOUBLE_EQ(m->time_per_frame_ms_p50, 18.0);  // median of 10 + 2k, k = 0..8
  EXPECT_DOUBLE_EQ(m->tracked_ids_per_frame, 9.0);
  EXPECT_DOUBLE_EQ(m->projection_ms_p50, 0.0);
  std::ifstream in(dir / "metrics.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("front_end"), "orb");
  EXPECT_DOUBLE_EQ(j.at("time_per_frame_ms_p50").get<double>(), 18.0);
  EXPECT_DOUBLE_EQ(j.at("match_ms_p50").get<double>(), 3.0);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace m2s::reporting
