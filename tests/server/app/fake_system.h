// A stand-in slam::System for testing the server's session logic without SLAM: every frame is
// "tracked" at its ground-truth pose and adds one map point (id = seq) at a known position.
// FakeMapGroup stands in for slam::MapGroup: its agents are FakeSystems that report every
// frame they track to the group, which records them.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "m2s/slam/system.h"

namespace m2s::testing {

class FakeSystem final : public slam::System {
 public:
  static Expected<std::unique_ptr<slam::System>> Create(const slam::Options& options) {
    if (Status s = options.Check(); !s) return s;
    return std::unique_ptr<slam::System>(new FakeSystem(options));
  }
  // A FakeSystem that calls `on_track` with every frame it tracks.
  static std::unique_ptr<slam::System> Observed(std::function<void(const slam::Frame&)> on_track) {
    auto system = std::unique_ptr<FakeSystem>(new FakeSystem(slam::Options()));
    system->on_track_ = std::move(on_track);
    return system;
  }
  slam::TrackResult Track(const slam::Frame& frame) override {
    if (on_track_) on_track_(frame);
    std::lock_guard<std::mutex> lock(mutex_);
    slam::TrackResult r;
    r.seq = frame.seq;
    r.timestamp = frame.timestamp;
    r.state = slam::TrackingState::kOk;
    r.world_from_camera = frame.ground_truth_world_from_camera.value_or(Pose3());
    r.num_features = static_cast<int>(frame.features.size());
    r.num_inliers = r.num_features;
    r.tracking_ms = 0.1;
    const auto id = static_cast<VertexId>(frame.seq);
    points_[id] = Eigen::Vector3f(static_cast<float>(frame.seq), 1.f, 2.f);
    pending_.point_ids.push_back(id);
    pending_.point_positions.push_back(points_[id]);
    trajectory_.push_back({frame.seq, frame.timestamp, r.state, r.world_from_camera, false, {}});
    return r;
  }
  void Submit(slam::Frame) override {}
  bool WaitForResult(slam::TrackResult*, double) override { return false; }
  slam::MapDelta TakeMapDelta() override {
    std::lock_guard<std::mutex> lock(mutex_);
    slam::MapDelta delta = std::move(pending_);
    pending_ = {};
    return delta;
  }
  slam::MapDelta FullMap() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    slam::MapDelta full;
    full.full = true;
    for (const auto& [id, p] : points_) {
      full.point_ids.push_back(id);
      full.point_positions.push_back(p);
    }
    return full;
  }
  std::vector<slam::TrajectoryEntry> Trajectory() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    return trajectory_;
  }
  slam::SystemStats Stats() const override { return {}; }
  void Reset() override {
    std::lock_guard<std::mutex> lock(mutex_);
    points_.clear();
    pending_ = {};
  }
  Status SaveMap(const std::string&) const override { return Status::Ok(); }
  Status LoadMap(const std::string&) override { return Status::Error("not supported"); }
  void Shutdown() override {}

 private:
  explicit FakeSystem(const slam::Options&) {}
  std::function<void(const slam::Frame&)> on_track_;
  mutable std::mutex mutex_;
  std::map<VertexId, Eigen::Vector3f> points_;
  slam::MapDelta pending_;
  std::vector<slam::TrajectoryEntry> trajectory_;
};

class FakeMapGroup final : public slam::MapGroup {
 public:
  explicit FakeMapGroup(const slam::Options& options) : options_(options) {}

  Expected<std::unique_ptr<slam::System>> Join() override {
    std::lock_guard<std::mutex> lock(mutex_);
    ++joined_;
    return FakeSystem::Observed([this](const slam::Frame& frame) {
      std::lock_guard<std::mutex> lock(mutex_);
      tracked_.push_back(frame.timestamp);
    });
  }
  // Fixed figures besides the joins, so that reports can be checked.
  slam::GroupStats Stats() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    slam::GroupStats stats;
    stats.agents_joined = joined_;
    stats.merges = 2;
    stats.merge_ms = {12.5, 40.0};
    stats.keyframes = 3;
    stats.map_points = 70;
    stats.localization_only = !loaded_.empty();
    return stats;
  }
  const slam::Options& options() const override { return options_; }
  // Records the path and writes an empty map file there (with the group's camera).
  Status SaveMap(const std::string& path) const override {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      saved_.push_back(path);
    }
    auto empty = slam::MapGroup::Create(options_);
    if (!empty) return empty.status();
    return (*empty)->SaveMap(path);
  }
  // Refuses any path with "bad" in it.
  Status LoadMap(const std::string& path) override {
    if (path.find("bad") != std::string::npos) return Status::Error("not a map file");
    std::lock_guard<std::mutex> lock(mutex_);
    loaded_ = path;
    return Status::Ok();
  }
  Status ResumeMap(const std::string& path) override {
    if (path.find("bad") != std::string::npos) return Status::Error("not a map file");
    std::lock_guard<std::mutex> lock(mutex_);
    resumed_ = path;
    return Status::Ok();
  }

  int joined() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return joined_;
  }
  // Timestamps of the frames the group's agents tracked.
  std::vector<double> tracked() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return tracked_;
  }
  std::vector<std::string> saved() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return saved_;
  }
  std::string resumed() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return resumed_;
  }

 private:
  const slam::Options options_;
  mutable std::mutex mutex_;
  int joined_ = 0;
  std::vector<double> tracked_;
  mutable std::vector<std::string> saved_;
  std::string loaded_;
  std::string resumed_;
};

}  // namespace m2s::testing
