#include "sim_config.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "interaction_profiles.h"

namespace m2s::xrsim {
namespace {

const char* Env(const char* name) {
  const char* value = std::getenv(name);
  return (value != nullptr && value[0] != '\0') ? value : nullptr;
}

bool ParseDouble(const std::string& text, double* out) {
  char* end = nullptr;
  *out = std::strtod(text.c_str(), &end);
  return end != text.c_str() && *end == '\0' && std::isfinite(*out);
}

bool ParseInt(const std::string& text, int64_t* out) {
  char* end = nullptr;
  *out = std::strtoll(text.c_str(), &end, 10);
  return end != text.c_str() && *end == '\0';
}

std::vector<std::string> Split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream stream(text);
  std::string part;
  while (std::getline(stream, part, separator)) {
    if (!part.empty()) parts.push_back(part);
  }
  return parts;
}

bool ParseScriptEvent(const std::string& item, ScriptEvent* event, std::string* why) {
  constexpr int64_t kDefaultDurationFrames = 30;
  const size_t at = item.find('@');
  if (at == std::string::npos) {
    *why = "M2S_XR_SIM_SCRIPT: '" + item + "' is not NAME@FRAME";
    return false;
  }
  const std::string name = item.substr(0, at);
  std::string when = item.substr(at + 1);
  event->duration = kDefaultDurationFrames;
  const size_t colon = when.find(':');
  if (colon != std::string::npos) {
    if (!ParseInt(when.substr(colon + 1), &event->duration) || event->duration <= 0) {
      *why = "M2S_XR_SIM_SCRIPT: bad duration in '" + item + "'";
      return false;
    }
    when = when.substr(0, colon);
  }
  if (!ParseInt(when, &event->frame) || event->frame < 0) {
    *why = "M2S_XR_SIM_SCRIPT: bad frame in '" + item + "'";
    return false;
  }
  using Kind = ScriptEvent::Kind;
  if (name == "focus_loss") {
    event->kind = Kind::kFocusLoss;
  } else if (name == "hide") {
    event->kind = Kind::kHide;
  } else if (name == "exit") {
    event->kind = Kind::kExit;
  } else if (name == "session_loss") {
    event->kind = Kind::kSessionLoss;
  } else if (name == "instance_loss") {
    event->kind = Kind::kInstanceLoss;
  } else {
    *why = "M2S_XR_SIM_SCRIPT: unknown event '" + name +
           "' (focus_loss, hide, exit, session_loss, instance_loss)";
    return false;
  }
  return true;
}

}  // namespace

bool ReadConfigFromEnvironment(SimConfig* config, std::string* why) {
  *config = SimConfig();
  if (const char* v = Env("M2S_XR_SIM_TRAJECTORY")) config->trajectory_path = v;
  if (const char* v = Env("M2S_XR_SIM_RATE_HZ")) {
    if (!ParseDouble(v, &config->rate_hz) || config->rate_hz < 1.0 || config->rate_hz > 1000.0) {
      *why = std::string("M2S_XR_SIM_RATE_HZ must be in [1, 1000], got '") + v + "'";
      return false;
    }
  }
  if (const char* v = Env("M2S_XR_SIM_REALTIME")) config->realtime = std::string(v) == "1";
  if (const char* v = Env("M2S_XR_SIM_VERBOSE")) config->verbose = std::string(v) == "1";
  if (const char* v = Env("M2S_XR_SIM_EYE_SIZE")) {
    const std::vector<std::string> parts = Split(v, 'x');
    int64_t w = 0, h = 0;
    if (parts.size() != 2 || !ParseInt(parts[0], &w) || !ParseInt(parts[1], &h) || w < 16 ||
        h < 16 || w > 4096 || h > 4096) {
      *why = std::string("M2S_XR_SIM_EYE_SIZE must be WIDTHxHEIGHT in [16, 4096], got '") + v + "'";
      return false;
    }
    config->eye_width = static_cast<int>(w);
    config->eye_height = static_cast<int>(h);
  }
  if (const char* v = Env("M2S_XR_SIM_FOV_DEG")) {
    if (!ParseDouble(v, &config->hfov_deg) || config->hfov_deg < 10 || config->hfov_deg > 170) {
      *why = std::string("M2S_XR_SIM_FOV_DEG must be in [10, 170], got '") + v + "'";
      return false;
    }
  }
  if (const char* v = Env("M2S_XR_SIM_IPD_M")) {
    if (!ParseDouble(v, &config->ipd_m) || config->ipd_m < 0 || config->ipd_m > 0.2) {
      *why = std::string("M2S_XR_SIM_IPD_M must be in [0, 0.2], got '") + v + "'";
      return false;
    }
  }
  if (const char* v = Env("M2S_XR_SIM_STAGE_OFFSET")) {
    const std::vector<std::string> parts = Split(v, ',');
    bool ok = parts.size() == 3;
    for (int i = 0; ok && i < 3; ++i) ok = ParseDouble(parts[i], &config->stage_offset[i]);
    if (!ok) {
      *why = std::string("M2S_XR_SIM_STAGE_OFFSET must be x,y,z, got '") + v + "'";
      return false;
    }
  }
  if (const char* v = Env("M2S_XR_SIM_SCRIPT")) {
    for (const std::string& item : Split(v, ',')) {
      ScriptEvent event;
      if (!ParseScriptEvent(item, &event, why)) return false;
      config->script.push_back(event);
    }
  }
  if (const char* v = Env("M2S_XR_SIM_CAPTURE_DIR")) config->capture_dir = v;
  if (const char* v = Env("M2S_XR_SIM_CAPTURE_FRAMES")) {
    const std::string frames = v;
    int64_t n = 0;
    if (frames == "all") {
      config->capture_all = true;
    } else if (frames.rfind("every:", 0) == 0) {
      if (!ParseInt(frames.substr(6), &config->capture_every) || config->capture_every <= 0) {
        *why = "M2S_XR_SIM_CAPTURE_FRAMES: bad 'every:N'";
        return false;
      }
    } else {
      for (const std::string& item : Split(frames, ',')) {
        if (!ParseInt(item, &n) || n < 0) {
          *why = "M2S_XR_SIM_CAPTURE_FRAMES: bad frame '" + item + "'";
          return false;
        }
        config->capture_frames.insert(n);
      }
    }
  }
  if (const char* v = Env("M2S_XR_SIM_REPORT")) config->report_path = v;
  if (const char* v = Env("M2S_XR_SIM_CONTROLLER")) {
    if (!KnownProfile(v)) {
      *why = std::string("M2S_XR_SIM_CONTROLLER must be ") + kTouchController + " or " +
             kSimpleController + ", got '" + v + "'";
      return false;
    }
    config->interaction_profile = v;
  }
  if (const char* v = Env("M2S_XR_SIM_INPUT")) {
    config->input_path = v;
    if (!config->input.Load(v, config->interaction_profile, why)) return false;
  }
  return true;
}

bool InputScript::Load(const std::string& path, const std::string& profile, std::string* why) {
  changes_.clear();
  std::ifstream file(path);
  if (!file) {
    *why = "M2S_XR_SIM_INPUT: cannot open '" + path + "'";
    return false;
  }
  std::string line;
  for (int line_number = 1; std::getline(file, line); ++line_number) {
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream fields(line);
    std::string frame_text, input, value_text, extra;
    int64_t frame = 0;
    double value = 0.0;
    const std::string where = path + ":" + std::to_string(line_number) + ": ";
    if (!(fields >> frame_text >> input >> value_text) || (fields >> extra) ||
        !ParseInt(frame_text, &frame) || frame < 0 || !ParseDouble(value_text, &value) ||
        value < 0.0 || value > 1.0) {
      *why = where + "expected '<frame >= 0> <input path> <value in [0, 1]>'";
      return false;
    }
    if (!ScriptableInput(profile, input)) {
      *why = where + "'" + input + "' is not a /click, /touch or /value input of " + profile;
      return false;
    }
    changes_[input].emplace_back(frame, static_cast<float>(value));
  }
  for (auto& [input, changes] : changes_) {
    // Stable: of two lines for one frame, the later one wins.
    std::stable_sort(changes.begin(), changes.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
  }
  return true;
}

float InputScript::ValueAt(const std::string& input_path, int64_t frame) const {
  const auto it = changes_.find(input_path);
  if (it == changes_.end()) return 0.f;
  float value = 0.f;
  for (const auto& [at, v] : it->second) {
    if (at > frame) break;
    value = v;
  }
  return value;
}

bool HeadTrajectory::Load(const std::string& path, std::string* why) {
  std::ifstream file(path);
  if (!file) {
    *why = "cannot open trajectory '" + path + "'";
    return false;
  }
  // camera (x right, y down, z forward) -> OpenXR view (x right, y up, z backward).
  const Eigen::Quaterniond camera_from_view(0.0, 1.0, 0.0, 0.0);  // w x y z: 180 deg about x
  std::string line;
  int line_number = 0;
  while (std::getline(file, line)) {
    ++line_number;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    double t, tx, ty, tz, qx, qy, qz, qw;
    if (!(fields >> t >> tx >> ty >> tz >> qx >> qy >> qz >> qw)) {
      *why = path + ":" + std::to_string(line_number) + ": expected 't tx ty tz qx qy qz qw'";
      return false;
    }
    const Eigen::Quaterniond q(qw, qx, qy, qz);
    if (!std::isfinite(q.norm()) || std::abs(q.norm() - 1.0) > 1e-2 ||
        (!stamps_.empty() && t <= stamps_.back())) {
      *why = path + ":" + std::to_string(line_number) + ": bad quaternion or unsorted stamp";
      return false;
    }
    stamps_.push_back(t);
    local_from_view_.push_back({(q.normalized() * camera_from_view).normalized(), {tx, ty, tz}});
  }
  if (stamps_.empty()) {
    *why = "trajectory '" + path + "' has no poses";
    return false;
  }
  return true;
}

SimPose HeadTrajectory::Sample(double t) const {
  if (stamps_.empty()) return {};
  if (t <= stamps_.front()) return local_from_view_.front();
  if (t >= stamps_.back()) return local_from_view_.back();
  const size_t i = std::upper_bound(stamps_.begin(), stamps_.end(), t) - stamps_.begin();
  const double alpha = (t - stamps_[i - 1]) / (stamps_[i] - stamps_[i - 1]);
  const SimPose& a = local_from_view_[i - 1];
  const SimPose& b = local_from_view_[i];
  return {a.rotation.slerp(alpha, b.rotation).normalized(),
          (1.0 - alpha) * a.translation + alpha * b.translation};
}

}  // namespace m2s::xrsim
