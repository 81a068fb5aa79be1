#include "m2s/common/camera_io.h"

#include <fstream>

#include <nlohmann/json.hpp>

namespace m2s {

Expected<Camera> ReadCameraJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Expected<Camera>::Error("cannot open camera file " + path);
  Camera camera;
  try {
    const nlohmann::json j = nlohmann::json::parse(in);
    camera.width = j.at("width").get<int>();
    camera.height = j.at("height").get<int>();
    camera.fx = j.at("fx").get<double>();
    camera.fy = j.at("fy").get<double>();
    camera.cx = j.at("cx").get<double>();
    camera.cy = j.at("cy").get<double>();
    camera.near = j.value("near", camera.near);
    camera.far = j.value("far", camera.far);
  } catch (const nlohmann::json::exception& e) {
    return Expected<Camera>::Error("bad camera file " + path + ": " + e.what());
  }
  if (Status s = camera.Check(); !s) return s.Prefixed("bad camera file " + path + ": ");
  return camera;
}

}  // namespace m2s
