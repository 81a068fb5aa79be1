// Configuration of the simulated runtime, read from the environment once per xrCreateInstance,
// and the played head trajectory.
//
// Environment (all optional):
//   M2S_XR_SIM_TRAJECTORY  TUM file "t tx ty tz qx qy qz qw": world_from_camera of the centre eye
//                          in the project's camera axes (x right, y down, z forward). The LOCAL
//                          reference space is that world; the VIEW pose is the camera pose with
//                          OpenXR axes (x right, y up, z backward). Without it the head is still
//                          at the LOCAL origin, looking down -z.
//   M2S_XR_SIM_RATE_HZ     display rate (default 72); simulated time advances 1/rate per frame.
//   M2S_XR_SIM_REALTIME    1: xrWaitFrame also sleeps until the frame's wall-clock slot.
//   M2S_XR_SIM_EYE_SIZE    recommended eye image "WIDTHxHEIGHT" (default 512x512).
//   M2S_XR_SIM_FOV_DEG     horizontal field of view of each eye (default 90; square pixels).
//   M2S_XR_SIM_IPD_M       inter-pupillary distance (default 0.064): eyes at -+IPD/2 along x.
//   M2S_XR_SIM_STAGE_OFFSET "x,y,z": STAGE origin in LOCAL coordinates (default 0,0,0).
//   M2S_XR_SIM_SCRIPT      comma-separated events at frame indices (frame = xrWaitFrame count
//                          since xrCreateInstance, from 0):
//                            focus_loss@N[:D]  FOCUSED -> VISIBLE for D frames (default 30)
//                            hide@N[:D]        -> SYNCHRONIZED (shouldRender false) for D frames
//                            exit@N            runtime asks the session to stop (-> STOPPING,
//                                              then EXITING after xrEndSession)
//                            session_loss@N    LOSS_PENDING; the system is unavailable for the
//                                              next 2 xrGetSystem calls, then a new session can
//                                              be created
//                            instance_loss@N   XrEventDataInstanceLossPending, then every call
//                                              but the destroy functions returns
//                                              XR_ERROR_INSTANCE_LOST
//   M2S_XR_SIM_CAPTURE_DIR + M2S_XR_SIM_CAPTURE_FRAMES ("100,200", "all" or "every:50"): on
//                          xrEndFrame the left-eye image of the first projection layer is
//                          written to DIR/left_<frame>.png (upright, RGBA) with
//                          DIR/left_<frame>.json (the submitted view pose in the layer's space,
//                          fov, rect, display time, the played head pose in LOCAL).
//   M2S_XR_SIM_CONTROLLER  the interaction profile both hands hold (default
//                          /interaction_profiles/oculus/touch_controller; or
//                          /interaction_profiles/khr/simple_controller). It becomes the session's
//                          current profile on xrAttachSessionActionSets if the app suggested
//                          bindings for it; otherwise actions have no bindings (inactive).
//   M2S_XR_SIM_INPUT       a file of scripted button states, one change per line:
//                            <frame> <input path> <value>
//                          e.g. "120 /user/hand/right/input/a/click 1": from frame 120 (the
//                          xrWaitFrame count, as in M2S_XR_SIM_SCRIPT) the input reads 1 until a
//                          later line changes it. Values are in [0, 1] (buttons 0 or 1); an
//                          input reads 0 before its first line. Paths are the /click, /touch and
//                          /value inputs of M2S_XR_SIM_CONTROLLER; '#' starts a comment line.
//                          xrSyncActions samples the inputs at the last waited frame.
//   M2S_XR_SIM_REPORT      path of a JSON report written on xrDestroyInstance (misuse count and
//                          messages, handles left alive, frames, state transitions).
//   M2S_XR_SIM_VERBOSE     1: log every state change and event to stderr.
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace m2s::xrsim {

struct ScriptEvent {
  enum class Kind { kFocusLoss, kHide, kExit, kSessionLoss, kInstanceLoss };
  Kind kind = Kind::kExit;
  int64_t frame = 0;
  int64_t duration = 0;  // frames, for kFocusLoss and kHide
};

// Scripted input values: for each input path, (frame, value) changes sorted by frame.
class InputScript {
 public:
  // Loads the file (format in the header comment). False with "path:line: reason".
  bool Load(const std::string& path, const std::string& profile, std::string* why);
  // The input's value at a frame: that of its last change at or before it (0 before any).
  float ValueAt(const std::string& input_path, int64_t frame) const;

 private:
  std::map<std::string, std::vector<std::pair<int64_t, float>>> changes_;
};

struct SimConfig {
  std::string trajectory_path;
  double rate_hz = 72.0;
  bool realtime = false;
  int eye_width = 512;
  int eye_height = 512;
  double hfov_deg = 90.0;
  double ipd_m = 0.064;
  Eigen::Vector3d stage_offset = Eigen::Vector3d::Zero();
  std::vector<ScriptEvent> script;
  std::string capture_dir;
  std::set<int64_t> capture_frames;
  bool capture_all = false;
  int64_t capture_every = 0;
  std::string report_path;
  bool verbose = false;
  std::string interaction_profile = "/interaction_profiles/oculus/touch_controller";
  std::string input_path;
  InputScript input;

  bool ShouldCapture(int64_t frame) const {
    if (capture_dir.empty()) return false;
    return capture_all || capture_frames.count(frame) > 0 ||
           (capture_every > 0 && frame % capture_every == 0);
  }
};

// Reads the environment; false with a one-line reason on a malformed variable.
bool ReadConfigFromEnvironment(SimConfig* config, std::string* why);

// A rigid pose with OpenXR-style members, double precision.
struct SimPose {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  SimPose operator*(const SimPose& o) const {
    return {rotation * o.rotation, rotation * o.translation + translation};
  }
  SimPose Inverse() const {
    const Eigen::Quaterniond inv = rotation.conjugate();
    return {inv, -(inv * translation)};
  }
};

// The played head trajectory: poses of the VIEW space (OpenXR axes) in LOCAL, linearly
// interpolated in time (slerp for rotations), clamped to the first/last sample outside.
class HeadTrajectory {
 public:
  // Loads a TUM file (camera axes x right, y down, z forward) and converts each pose to OpenXR
  // view axes. False with a reason on a missing or malformed file or unsorted stamps.
  bool Load(const std::string& path, std::string* why);
  bool empty() const { return stamps_.empty(); }
  double first_stamp() const { return stamps_.empty() ? 0.0 : stamps_.front(); }
  SimPose Sample(double t) const;

 private:
  std::vector<double> stamps_;
  std::vector<SimPose> local_from_view_;
};

}  // namespace m2s::xrsim
