#include "m2s/plugin/plugin_system.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <utility>
#include <vector>

#include "m2s/common/logging.h"
#include "system/frame_runner.h"
#include "system/system_common.h"

namespace m2s::plugin {
namespace {

using slam::TrackingState;

constexpr size_t kErrorSize = 512;
constexpr double kLogPeriodS = 1.0;

m2s_camera ToC(const Camera& c) {
  return {c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.near, c.far};
}

// A pose from the plug-in, or nullopt when it is not finite or its quaternion is not a
// rotation (zero).
std::optional<Pose3> FromC(const m2s_pose& p) {
  const double* q = p.rotation_wxyz;
  const double* t = p.translation;
  for (int i = 0; i < 4; ++i)
    if (!std::isfinite(q[i])) return std::nullopt;
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(t[i])) return std::nullopt;
  const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(norm > 1e-6)) return std::nullopt;
  return Pose3(Eigen::Quaterniond(q[0], q[1], q[2], q[3]), Eigen::Vector3d(t[0], t[1], t[2]));
}

std::optional<TrackingState> StateFromC(int32_t state) {
  if (state < M2S_TRACK_NOT_INITIALIZED || state > M2S_TRACK_REJECTED) return std::nullopt;
  return static_cast<TrackingState>(state);
}

class PluginSystem final : public slam::System {
 public:
  PluginSystem(std::shared_ptr<const LoadedPlugin> plugin, const slam::Options& options,
               std::string config_json, void* instance)
      : plugin_(std::move(plugin)),
        table_(plugin_->table()),
        options_(options),
        config_json_(std::move(config_json)),
        instance_(instance),
        validator_(options.camera, options.max_features_per_frame, options.image_margin_px),
        grid_(FeatureGrid::ForImage(options.camera.width, options.camera.height)),
        runner_(static_cast<size_t>(options.input_queue_capacity),
                [this](const slam::Frame& frame) { return TrackLocked(frame); }) {}
  ~PluginSystem() override { Shutdown(); }

  slam::TrackResult Track(const slam::Frame& frame) override { return runner_.Track(frame); }
  void Submit(slam::Frame frame) override { runner_.Submit(std::move(frame)); }
  bool WaitForResult(slam::TrackResult* result, double timeout_s) override {
    return runner_.WaitForResult(result, timeout_s);
  }

  slam::MapDelta TakeMapDelta() override {
    std::vector<m2s_map_point> points = QueryMapPoints();
    std::lock_guard<std::mutex> lock(mutex_);
    slam::MapDelta delta;
    delta.base_revision = revision_;
    std::map<VertexId, Eigen::Vector3f> now;
    for (const m2s_map_point& p : points) {
      const Eigen::Vector3f xyz(p.x, p.y, p.z);
      if (!xyz.allFinite()) continue;
      now[p.id] = xyz;
      auto it = sent_.find(p.id);
      if (it == sent_.end() || it->second != xyz) {
        delta.point_ids.push_back(p.id);
        delta.point_positions.push_back(xyz);
      }
    }
    for (const auto& [id, xyz] : sent_)
      if (!now.count(id)) delta.removed_points.push_back(id);
    sent_ = std::move(now);
    if (!delta.empty()) ++revision_;
    delta.revision = revision_;
    return delta;
  }

  slam::MapDelta FullMap() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    slam::MapDelta delta;
    delta.full = true;
    delta.revision = revision_;
    for (const auto& [id, xyz] : sent_) {
      delta.point_ids.push_back(id);
      delta.point_positions.push_back(xyz);
    }
    return delta;
  }

  std::vector<slam::TrajectoryEntry> Trajectory() const override {
    std::vector<m2s_trajectory_entry> own;
    bool has_own = false;
    {
      std::lock_guard<std::mutex> lock(instance_mutex_);
      if (instance_ != nullptr && table_.trajectory != nullptr) {
        has_own = true;
        own = QueryAll<m2s_trajectory_entry>(table_.trajectory);
      }
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (!has_own) return records_;
    std::map<int64_t, const slam::TrajectoryEntry*> by_seq;
    for (const slam::TrajectoryEntry& r : records_) by_seq[r.seq] = &r;
    std::vector<slam::TrajectoryEntry> out;
    out.reserve(own.size());
    for (const m2s_trajectory_entry& e : own) {
      slam::TrajectoryEntry entry;
      entry.seq = e.seq;
      entry.timestamp = e.timestamp;
      const auto state = StateFromC(e.state);
      const auto pose = FromC(e.world_from_camera);
      entry.state = state && (pose || !slam::HasPose(*state)) ? *state : TrackingState::kLost;
      if (pose) entry.world_from_camera = *pose;
      if (auto it = by_seq.find(e.seq); it != by_seq.end()) {
        entry.is_keyframe = it->second->is_keyframe;
        entry.ground_truth_world_from_camera = it->second->ground_truth_world_from_camera;
      }
      out.push_back(std::move(entry));
    }
    return out;
  }

  slam::SystemStats Stats() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    slam::SystemStats stats = stats_;
    stats.frames_submitted = runner_.submitted();
    stats.frames_dropped_queue = runner_.dropped();
    stats.map_points = static_cast<int>(sent_.size());
    stats.map_revision = revision_;
    return stats;
  }

  void Reset() override {
    runner_.Exclusive([this] {
      {
        std::lock_guard<std::mutex> lock(instance_mutex_);
        if (instance_ != nullptr) {
          char error[kErrorSize] = "";
          if (table_.reset == nullptr || table_.reset(instance_, error, sizeof(error)) != 0) {
            if (table_.reset != nullptr)
              Log("reset failed (" + std::string(error) + "), recreating");
            table_.destroy(instance_);
            const m2s_camera camera = ToC(options_.camera);
            instance_ = table_.create(&camera, config_json_.c_str(), error, sizeof(error));
            if (instance_ == nullptr) Log("could not recreate the instance: " + std::string(error));
          }
        }
      }
      std::lock_guard<std::mutex> lock(mutex_);
      records_.clear();
      validator_.Reset();
    });
  }

  Status SaveMap(const std::string&) const override { return NotSupported("saving maps"); }
  Status LoadMap(const std::string&) override { return NotSupported("loading maps"); }

  void Shutdown() override {
    runner_.Stop();
    std::lock_guard<std::mutex> lock(instance_mutex_);
    shut_down_ = true;
    if (instance_ != nullptr) table_.destroy(instance_);
    instance_ = nullptr;
  }

 private:
  Status NotSupported(const std::string& what) const {
    return Status::Error(what + " is not supported by plug-in " + plugin_->name());
  }

  // At most one line per kLogPeriodS; the lines left out are counted in the next one.
  void Log(const std::string& message) {
    const auto now = std::chrono::steady_clock::now();
    std::lock_guard<std::mutex> lock(log_mutex_);
    if (last_log_ && now - *last_log_ < std::chrono::duration<double>(kLogPeriodS)) {
      ++suppressed_;
      return;
    }
    M2S_LOG(kWarning) << "plug-in " << plugin_->name() << ": " << message
                      << (suppressed_ > 0 ? " (" + std::to_string(suppressed_) + " more since)"
                                          : "");
    last_log_ = now;
    suppressed_ = 0;
  }

  // Calls a "fill up to capacity, return the total" function until everything fits.
  // instance_mutex_ held.
  template <typename T, typename Fn>
  std::vector<T> QueryAll(Fn fn) const {
    std::vector<T> items(last_size_hint_);
    for (int attempt = 0; attempt < 3; ++attempt) {
      const size_t total = fn(instance_, items.data(), items.size());
      if (total <= items.size()) {
        items.resize(total);
        return items;
      }
      items.resize(total + total / 4);
    }
    return {};
  }

  std::vector<m2s_map_point> QueryMapPoints() {
    std::lock_guard<std::mutex> lock(instance_mutex_);
    if (instance_ == nullptr) return {};
    std::vector<m2s_map_point> points = QueryAll<m2s_map_point>(table_.map_points);
    last_size_hint_ = points.size() + points.size() / 4 + 16;
    return points;
  }

  // The tracking function (FrameRunner: one frame at a time).
  slam::TrackResult TrackLocked(const slam::Frame& frame) {
    const auto t0 = std::chrono::steady_clock::now();
    slam::TrackResult result;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!slam::TakeFrame(frame, shut_down_, options_.feature_budget, grid_, &validator_,
                           &features_, &result, &stats_)) {
        return result;
      }
    }
    c_features_.resize(features_.size());
    for (size_t i = 0; i < features_.size(); ++i) {
      c_features_[i] = {features_.ids[i], static_cast<float>(features_.uvs[i].x()),
                        static_cast<float>(features_.uvs[i].y())};
    }
    const m2s_frame c_frame{frame.seq, frame.timestamp, c_features_.data(),
                            static_cast<uint32_t>(c_features_.size())};
    m2s_track_result out{};
    char error[kErrorSize] = "";
    int rc = 1;
    {
      std::lock_guard<std::mutex> lock(instance_mutex_);
      if (instance_ == nullptr) {
        std::snprintf(error, sizeof(error), "no instance (it could not be recreated)");
      } else {
        rc = table_.process_frame(instance_, &c_frame, &out, error, sizeof(error));
      }
    }
    error[kErrorSize - 1] = '\0';
    std::string reject;
    const auto state = StateFromC(out.state);
    std::optional<Pose3> pose;
    if (rc != 0) {
      reject = "plugin_error";
      Log("frame " + std::to_string(frame.seq) + ": " + error);
    } else if (!state) {
      reject = "plugin_bad_state";
      Log("frame " + std::to_string(frame.seq) + ": state " + std::to_string(out.state) +
          " is not an m2s_track_state");
    } else if (slam::HasPose(*state)) {
      pose = FromC(out.world_from_camera);
      if (!pose) Log("frame " + std::to_string(frame.seq) + ": pose not finite, counted lost");
    }
    result.tracking_ms = slam::MsSince(t0);
    std::lock_guard<std::mutex> lock(mutex_);
    if (!reject.empty()) {
      result.state = TrackingState::kRejected;
      result.reject_reason = reject;
      ++stats_.frames_rejected;
      ++stats_.rejected_by_reason[reject];
      return result;
    }
    result.state = *state;
    if (slam::HasPose(*state) && !pose) result.state = TrackingState::kLost;
    if (pose) result.world_from_camera = *pose;
    result.num_inliers = out.num_inliers;
    result.keyframe_created = out.keyframe_created != 0;
    stats_.frames_tracked += slam::HasPose(result.state) ? 1 : 0;
    stats_.frames_lost += result.state == TrackingState::kLost ? 1 : 0;
    stats_.relocalisations += result.state == TrackingState::kRelocalized ? 1 : 0;
    stats_.keyframes += result.keyframe_created ? 1 : 0;
    if (slam::HasPose(result.state)) stats_.maps_created = 1;
    slam::TrajectoryEntry entry;
    entry.seq = frame.seq;
    entry.timestamp = frame.timestamp;
    entry.state = result.state;
    entry.world_from_camera = result.world_from_camera;
    entry.is_keyframe = result.keyframe_created;
    entry.ground_truth_world_from_camera = frame.ground_truth_world_from_camera;
    records_.push_back(std::move(entry));
    return result;
  }

  const std::shared_ptr<const LoadedPlugin> plugin_;  // keeps the library loaded
  const m2s_plugin& table_;
  const slam::Options options_;
  const std::string config_json_;

  mutable std::mutex instance_mutex_;  // every call into the instance
  void* instance_;
  mutable size_t last_size_hint_ = 0;

  mutable std::mutex mutex_;  // guards the members below
  std::atomic<bool> shut_down_{false};
  slam::FrameValidator validator_;
  const FeatureGrid grid_;
  slam::SortedFeatures features_;
  slam::SystemStats stats_;
  std::vector<slam::TrajectoryEntry> records_;
  std::map<VertexId, Eigen::Vector3f> sent_;
  uint64_t revision_ = 0;

  std::vector<m2s_feature> c_features_;  // tracking thread only

  std::mutex log_mutex_;
  std::optional<std::chrono::steady_clock::time_point> last_log_;
  int64_t suppressed_ = 0;

  slam::FrameRunner runner_;  // last: stopped first
};

}  // namespace

bool IsBuiltinMethod(const std::string& method) {
  return method.empty() || method == kBuiltinMethod;
}

Expected<std::unique_ptr<slam::System>> CreatePluginSystem(
    std::shared_ptr<const LoadedPlugin> plugin, const slam::Options& options,
    const std::string& config_json) {
  if (Status valid = options.Check(); !valid) return valid.Prefixed("invalid SLAM options: ");
  const m2s_camera camera = ToC(options.camera);
  const std::string config = config_json.empty() ? "{}" : config_json;
  char error[kErrorSize] = "";
  void* instance = plugin->table().create(&camera, config.c_str(), error, sizeof(error));
  error[kErrorSize - 1] = '\0';
  if (instance == nullptr) {
    return Status::Error("plug-in " + plugin->name() + " refused to start: " +
                         (error[0] != '\0' ? std::string(error) : "create returned NULL"));
  }
  return std::unique_ptr<slam::System>(
      std::make_unique<PluginSystem>(std::move(plugin), options, config, instance));
}

}  // namespace m2s::plugin
