// A stand-in slam::System for testing the server's session logic without SLAM: every frame is
// "tracked" at its ground-truth pose and adds one map point (id = seq) at a known position.
#pragma once

#include <map>
#include <memory>
#include <mutex>

#include "m2s/slam/system.h"

namespace m2s::testing {

class FakeSystem final : public slam::System {
 public:
  static Expected<std::unique_ptr<slam::System>> Create(const slam::Options& options) {
    if (Status s = options.Check(); !s) return s;
    return std::unique_ptr<slam::System>(new FakeSystem(options));
  }
  slam::TrackResult Track(const slam::Frame& frame) override {
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
  mutable std::mutex mutex_;
  std::map<VertexId, Eigen::Vector3f> points_;
  slam::MapDelta pending_;
  std::vector<slam::TrajectoryEntry> trajectory_;
};

}  // namespace m2s::testing
