// A C++ plug-in (m2s/plugin/plugin.h) for the tests of the ABI boundary: its factory throws on
// a config other than "{}", ProcessFrame throws a two-line message on seq 3 and an int on seq
// 4, and Reset() is left to the default (the instance is recreated: the frame count restarts).
#include <stdexcept>
#include <string>

#include "m2s/plugin/plugin.h"

namespace {

class Throwing final : public m2s::plugin::Method {
 public:
  m2s::plugin::FrameResult ProcessFrame(const m2s_frame& frame) override {
    if (frame.seq == 3) throw std::runtime_error("bad frame 3\nsecond line");
    if (frame.seq == 4) throw 4;
    ++frames_;
    m2s::plugin::FrameResult r;
    r.state = m2s::plugin::TrackState::kOk;
    r.world_from_camera.translation[0] = static_cast<double>(frames_);
    return r;
  }
  std::optional<m2s_pose> CurrentPose() const override { return std::nullopt; }
  std::vector<m2s_map_point> MapPoints() const override { return {}; }

 private:
  int frames_ = 0;
};

std::unique_ptr<Throwing> MakeThrowing(const m2s_camera&, const std::string& config_json) {
  if (config_json != "{}") throw std::invalid_argument("config: no options here");
  return std::make_unique<Throwing>();
}

}  // namespace

M2S_DEFINE_PLUGIN("throwing", "throws", MakeThrowing)
