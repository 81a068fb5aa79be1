// mesh2slam.System: the SLAM library (slam::System) frame by frame.
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "bindings.h"
#include "convert.h"
#include "m2s/slam/system.h"

namespace m2s::python {
namespace {

// Features from a dict with "id", "u", "v" (what project() returns) or an (ids, u, v) tuple.
std::vector<VertexFeature> FeaturesFrom(const py::handle& features) {
  py::object ids, us, vs;
  if (py::isinstance<py::dict>(features)) {
    const py::dict dict = py::reinterpret_borrow<py::dict>(features);
    for (const char* key : {"id", "u", "v"}) {
      if (!dict.contains(key)) {
        throw py::value_error(std::string("features: missing key '") + key + "'");
      }
    }
    ids = dict["id"];
    us = dict["u"];
    vs = dict["v"];
  } else if (py::isinstance<py::tuple>(features) && py::len(features) == 3) {
    const py::tuple tuple = py::reinterpret_borrow<py::tuple>(features);
    ids = tuple[0];
    us = tuple[1];
    vs = tuple[2];
  } else {
    throw py::value_error("features must be a dict with 'id', 'u', 'v' or an (ids, u, v) tuple");
  }
  const auto id = Vector<uint32_t>(ids, "features id");
  const auto u = Vector<float>(us, "features u", id.shape(0));
  const auto v = Vector<float>(vs, "features v", id.shape(0));
  std::vector<VertexFeature> out(static_cast<size_t>(id.shape(0)));
  for (size_t i = 0; i < out.size(); ++i) {
    out[i].id = id.at(i);
    out[i].uv = Eigen::Vector2f(u.at(i), v.at(i));
  }
  return out;
}

py::object PoseOrNone(slam::TrackingState state, const Pose3& pose) {
  const bool has_pose =
      state == slam::TrackingState::kOk || state == slam::TrackingState::kRelocalized;
  return has_pose ? py::object(PoseToArray(pose)) : py::none();
}

// The Python face of slam::System. Tracking releases the GIL; a mutex keeps Track() and
// Reset() to one thread at a time (the System's single-producer contract) when several Python
// threads share one System.
class PySystem {
 public:
  explicit PySystem(const slam::Options& options) {
    Expected<std::unique_ptr<slam::System>> system = slam::System::Create(options);
    if (!system) RaiseValueError(system.status());
    system_ = std::move(*system);
  }

  py::dict Track(int64_t seq, double timestamp, const py::handle& features,
                 const py::object& ground_truth) {
    slam::Frame frame;
    frame.seq = seq;
    frame.timestamp = timestamp;
    frame.features = FeaturesFrom(features);
    if (!ground_truth.is_none()) {
      frame.ground_truth_world_from_camera = PoseFromArray(ground_truth, "ground_truth");
    }
    slam::TrackResult result;
    {
      py::gil_scoped_release release;
      std::lock_guard<std::mutex> lock(track_mutex_);
      result = system_->Track(frame);
    }
    py::dict dict;
    dict["seq"] = result.seq;
    dict["timestamp"] = result.timestamp;
    dict["state"] = slam::ToString(result.state);
    dict["pose"] = PoseOrNone(result.state, result.world_from_camera);
    dict["num_features"] = result.num_features;
    dict["num_inliers"] = result.num_inliers;
    dict["keyframe_created"] = result.keyframe_created;
    dict["map_id"] = result.map_id;
    dict["tracking_ms"] = result.tracking_ms;
    dict["reject_reason"] = result.reject_reason;
    return dict;
  }

  // The refined trajectory: arrays over every processed frame; poses of frames without one
  // (not initialised, lost, rejected) are NaN.
  py::dict Trajectory() const {
    std::vector<slam::TrajectoryEntry> entries;
    {
      py::gil_scoped_release release;
      entries = system_->Trajectory();
    }
    const auto n = static_cast<py::ssize_t>(entries.size());
    py::array_t<int64_t> seq(n);
    py::array_t<double> timestamp(n);
    py::array_t<bool> is_keyframe(n), has_pose(n);
    py::array_t<int32_t> map_id(n);
    py::list states;
    std::vector<Pose3> poses;
    for (py::ssize_t i = 0; i < n; ++i) {
      const slam::TrajectoryEntry& e = entries[i];
      seq.mutable_at(i) = e.seq;
      timestamp.mutable_at(i) = e.timestamp;
      is_keyframe.mutable_at(i) = e.is_keyframe;
      map_id.mutable_at(i) = e.map_id;
      const bool valid =
          e.state == slam::TrackingState::kOk || e.state == slam::TrackingState::kRelocalized;
      has_pose.mutable_at(i) = valid;
      states.append(slam::ToString(e.state));
      poses.push_back(e.world_from_camera);
    }
    py::array_t<double> pose_array = PosesToArray(poses);
    auto p = pose_array.mutable_unchecked<3>();
    for (py::ssize_t i = 0; i < n; ++i) {
      if (has_pose.at(i)) continue;
      for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) p(i, r, c) = std::numeric_limits<double>::quiet_NaN();
      }
    }
    py::dict dict;
    dict["seq"] = seq;
    dict["timestamp"] = timestamp;
    dict["state"] = states;
    dict["has_pose"] = has_pose;
    dict["pose"] = pose_array;
    dict["is_keyframe"] = is_keyframe;
    dict["map_id"] = map_id;
    return dict;
  }

  py::tuple MapPoints() const {
    slam::MapDelta map;
    {
      py::gil_scoped_release release;
      map = system_->FullMap();
    }
    const auto n = static_cast<py::ssize_t>(map.point_ids.size());
    py::array_t<uint32_t> ids(n);
    py::array_t<float> positions({n, py::ssize_t{3}});
    auto out = positions.mutable_unchecked<2>();
    for (py::ssize_t i = 0; i < n; ++i) {
      ids.mutable_at(i) = map.point_ids[i];
      for (int k = 0; k < 3; ++k) out(i, k) = map.point_positions[i][k];
    }
    return py::make_tuple(ids, positions);
  }

  py::dict Stats() const {
    const slam::SystemStats s = system_->Stats();
    py::dict dict;
    dict["frames_processed"] = s.frames_processed;
    dict["frames_tracked"] = s.frames_tracked;
    dict["frames_rejected"] = s.frames_rejected;
    dict["frames_lost"] = s.frames_lost;
    dict["features_over_budget"] = s.features_over_budget;
    dict["relocalisations"] = s.relocalisations;
    dict["loop_corrections"] = s.loop_corrections;
    dict["maps_created"] = s.maps_created;
    dict["map_merges"] = s.map_merges;
    dict["current_map"] = s.current_map;
    dict["keyframes"] = s.keyframes;
    dict["map_points"] = s.map_points;
    dict["map_revision"] = s.map_revision;
    py::dict rejected;
    for (const auto& [reason, count] : s.rejected_by_reason) rejected[py::str(reason)] = count;
    dict["rejected_by_reason"] = rejected;
    return dict;
  }

  void Reset() {
    py::gil_scoped_release release;
    std::lock_guard<std::mutex> lock(track_mutex_);
    system_->Reset();
  }
  void RefineMap() {
    py::gil_scoped_release release;
    std::lock_guard<std::mutex> lock(track_mutex_);
    system_->RefineMap();
  }
  void SaveMap(const std::string& path) const {
    if (Status s = system_->SaveMap(path); !s) RaiseRuntimeError(s);
  }
  void LoadMap(const std::string& path) {
    if (Status s = system_->LoadMap(path); !s) RaiseRuntimeError(s);
  }
  void Shutdown() {
    py::gil_scoped_release release;
    system_->Shutdown();
  }

 private:
  std::unique_ptr<slam::System> system_;
  std::mutex track_mutex_;
};

}  // namespace

void RegisterSlam(py::module_& m) {
  py::class_<PySystem>(m, "System",
                       "The SLAM system (slam::System): vertex-feature frames in, poses and a "
                       "sparse map out. Poses are in the world of the monocular initialisation "
                       "(first keyframe at the origin, median depth 1).")
      .def(py::init([](const py::object& camera, bool deterministic, int feature_budget,
                       double pixel_sigma, int min_inliers, bool multi_map, bool drift_correction) {
             slam::Options options;
             options.camera = CameraFromDict(camera);
             options.deterministic = deterministic;
             options.feature_budget = feature_budget;
             options.pixel_sigma = pixel_sigma;
             options.tracker.min_inliers = min_inliers;
             options.multi_map.enabled = multi_map;
             options.drift.enabled = drift_correction;
             if (Status s = options.Check(); !s) RaiseValueError(s);
             return std::make_unique<PySystem>(options);
           }),
           py::arg("camera"), py::arg("deterministic") = true,
           py::arg("feature_budget") = slam::Options{}.feature_budget,
           py::arg("pixel_sigma") = slam::Options{}.pixel_sigma,
           py::arg("min_inliers") = slam::TrackerOptions{}.min_inliers,
           py::arg("multi_map") = slam::MultiMapOptions{}.enabled,
           py::arg("drift_correction") = slam::DriftOptions{}.enabled,
           "camera: a dict with CAMERA.json's keys. deterministic: mapping runs inline in "
           "track() (bit-identical runs); False: in its own thread.")
      .def("track", &PySystem::Track, py::arg("seq"), py::arg("timestamp"), py::arg("features"),
           py::arg("ground_truth") = py::none(),
           "Tracks one frame (features: project()'s dict or (ids, u, v)); returns a dict with "
           "state, pose (4x4 world_from_camera or None), num_inliers, keyframe_created, map_id.")
      .def("trajectory", &PySystem::Trajectory,
           "Every processed frame's latest estimate: dict of seq, timestamp, state, has_pose, "
           "pose (N,4,4; NaN without a pose), is_keyframe, map_id.")
      .def("map_points", &PySystem::MapPoints,
           "The well-constrained map points (those sent to clients, FullMap()): (ids (N,) "
           "uint32, positions (N,3) float32).")
      .def("stats", &PySystem::Stats)
      .def("reset", &PySystem::Reset)
      .def("refine_map", &PySystem::RefineMap,
           "A global bundle adjustment of the whole map, as at the end of a session, then "
           "every other tracked frame re-solved on the refined map and frames without a pose "
           "solved on it where it determines them (System::RefineMap): trajectory() and "
           "map_points() follow it.")
      .def("save_map", &PySystem::SaveMap, py::arg("path"))
      .def("load_map", &PySystem::LoadMap, py::arg("path"))
      .def("shutdown", &PySystem::Shutdown);
}

}  // namespace m2s::python
