#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "m2s/workbench/sweep.h"

namespace m2s::workbench {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

bool ValidName(const std::string& name) {
  static const std::regex kName("[A-Za-z0-9_.-]{1,64}");
  return std::regex_match(name, kName);
}

// Refuses keys outside `allowed`, naming the first one and where it was.
Status CheckKeys(const json& object, const std::set<std::string>& allowed,
                 const std::string& where) {
  if (!object.is_object()) return Status::Error(where + " must be a JSON object");
  for (const auto& [key, value] : object.items()) {
    if (!allowed.count(key)) return Status::Error("unknown key \"" + key + "\" in " + where);
  }
  return Status::Ok();
}

std::string Resolve(const std::string& path, const std::string& base_dir) {
  if (path.empty() || fs::path(path).is_absolute()) return path;
  return (fs::path(base_dir) / path).lexically_normal().string();
}

template <typename T>
Status Get(const json& object, const char* key, const std::string& where, T* out) {
  if (!object.contains(key)) return Status::Ok();
  try {
    *out = object.at(key).get<T>();
  } catch (const json::exception&) {
    return Status::Error(std::string("\"") + key + "\" in " + where + " has the wrong type");
  }
  return Status::Ok();
}

Expected<MethodSpec> ParseMethod(const json& object, const std::string& base_dir, size_t i) {
  const std::string where = "methods[" + std::to_string(i) + "]";
  if (Status s = CheckKeys(object, {"name", "front_end", "plugin", "plugin_config", "args"}, where);
      !s)
    return s;
  MethodSpec method;
  for (Status s : {Get(object, "name", where, &method.name),
                   Get(object, "front_end", where, &method.front_end),
                   Get(object, "plugin", where, &method.plugin),
                   Get(object, "plugin_config", where, &method.plugin_config),
                   Get(object, "args", where, &method.args)}) {
    if (!s) return s;
  }
  method.plugin_config = Resolve(method.plugin_config, base_dir);
  // A plug-in given as a path (it has a slash) is resolved like the other paths.
  if (method.plugin.find('/') != std::string::npos)
    method.plugin = Resolve(method.plugin, base_dir);
  return method;
}

Expected<SceneSpec> ParseScene(const json& object, const std::string& base_dir, size_t i) {
  const std::string where = "scenes[" + std::to_string(i) + "]";
  if (Status s =
          CheckKeys(object, {"name", "mesh", "trajectory", "camera", "duration_s", "args"}, where);
      !s)
    return s;
  SceneSpec scene;
  for (Status s : {Get(object, "name", where, &scene.name), Get(object, "mesh", where, &scene.mesh),
                   Get(object, "trajectory", where, &scene.trajectory),
                   Get(object, "camera", where, &scene.camera),
                   Get(object, "duration_s", where, &scene.duration_s),
                   Get(object, "args", where, &scene.args)}) {
    if (!s) return s;
  }
  scene.mesh = Resolve(scene.mesh, base_dir);
  scene.trajectory = Resolve(scene.trajectory, base_dir);
  scene.camera = Resolve(scene.camera, base_dir);
  return scene;
}

// "0.5" rather than "0.500000"; integers without a point.
std::string Short(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

}  // namespace

Status SweepConfig::Check() const {
  if (methods.empty()) return Status::Error("a sweep needs at least one method");
  if (scenes.empty()) return Status::Error("a sweep needs at least one scene");
  std::set<std::string> names;
  for (const MethodSpec& m : methods) {
    if (!ValidName(m.name))
      return Status::Error("method name \"" + m.name + "\" must be 1-64 of [A-Za-z0-9_.-]");
    if (!names.insert(m.name).second) return Status::Error("method \"" + m.name + "\" twice");
    if (m.front_end != "vertex" && m.front_end != "orb")
      return Status::Error("method \"" + m.name + "\": front_end must be vertex or orb");
  }
  names.clear();
  for (const SceneSpec& s : scenes) {
    if (!ValidName(s.name))
      return Status::Error("scene name \"" + s.name + "\" must be 1-64 of [A-Za-z0-9_.-]");
    if (!names.insert(s.name).second) return Status::Error("scene \"" + s.name + "\" twice");
    if (!(s.duration_s >= 0)) return Status::Error("scene \"" + s.name + "\": duration_s < 0");
  }
  if (fps.empty() || noise_px.empty() || outlier_ids.empty())
    return Status::Error("fps, noise_px and outlier_ids must not be empty");
  for (double f : fps)
    if (!(f > 0 && f <= 1000)) return Status::Error("fps must be in (0, 1000]");
  for (double n : noise_px)
    if (!(n >= 0 && n <= 100)) return Status::Error("noise_px must be in [0, 100]");
  for (double o : outlier_ids)
    if (!(o >= 0 && o <= 1)) return Status::Error("outlier_ids must be in [0, 1]");
  if (!(duration_s >= 0)) return Status::Error("duration_s must be >= 0");
  if (!(timeout_s > 0)) return Status::Error("timeout_s must be positive");
  return Status::Ok();
}

Expected<SweepConfig> ParseSweepConfig(const json& json, const std::string& base_dir) {
  if (Status s = CheckKeys(json,
                           {"methods", "scenes", "fps", "noise_px", "outlier_ids", "occlusion",
                            "duration_s", "timeout_s", "client_args"},
                           "the sweep");
      !s)
    return s;
  SweepConfig config;
  if (!json.contains("methods") || !json.at("methods").is_array())
    return Status::Error("the sweep needs a \"methods\" array");
  if (!json.contains("scenes") || !json.at("scenes").is_array())
    return Status::Error("the sweep needs a \"scenes\" array");
  for (size_t i = 0; i < json.at("methods").size(); ++i) {
    Expected<MethodSpec> method = ParseMethod(json.at("methods")[i], base_dir, i);
    if (!method) return method.status();
    config.methods.push_back(std::move(*method));
  }
  for (size_t i = 0; i < json.at("scenes").size(); ++i) {
    Expected<SceneSpec> scene = ParseScene(json.at("scenes")[i], base_dir, i);
    if (!scene) return scene.status();
    config.scenes.push_back(std::move(*scene));
  }
  for (Status s : {Get(json, "fps", "the sweep", &config.fps),
                   Get(json, "noise_px", "the sweep", &config.noise_px),
                   Get(json, "outlier_ids", "the sweep", &config.outlier_ids),
                   Get(json, "occlusion", "the sweep", &config.occlusion),
                   Get(json, "duration_s", "the sweep", &config.duration_s),
                   Get(json, "timeout_s", "the sweep", &config.timeout_s),
                   Get(json, "client_args", "the sweep", &config.client_args)}) {
    if (!s) return s;
  }
  if (Status s = config.Check(); !s) return s;
  return config;
}

Expected<SweepConfig> ReadSweepConfig(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::Error("cannot open sweep file " + path);
  nlohmann::json json = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (json.is_discarded()) return Status::Error(path + " is not valid JSON");
  Expected<SweepConfig> config = ParseSweepConfig(json, fs::absolute(path).parent_path().string());
  if (!config) return Status::Error(path + ": " + config.error());
  return config;
}

std::string Cell::Name(const SweepConfig& config) const {
  return config.methods[method].name + "__" + config.scenes[scene].name + "__" + Short(fps) +
         "fps__n" + Short(noise_px) + "__o" + Short(outlier_ids);
}

std::vector<Cell> ExpandCells(const SweepConfig& config) {
  std::vector<Cell> cells;
  for (size_t m = 0; m < config.methods.size(); ++m)
    for (size_t s = 0; s < config.scenes.size(); ++s)
      for (double fps : config.fps)
        for (double noise : config.noise_px)
          for (double outliers : config.outlier_ids) cells.push_back({m, s, fps, noise, outliers});
  return cells;
}

std::string SkipReason(const SweepConfig& config, const Cell& cell) {
  const MethodSpec& method = config.methods[cell.method];
  if (!method.takes_feature_noise() && (cell.noise_px > 0 || cell.outlier_ids > 0))
    return "feature noise does not apply to the " + method.front_end + " front end";
  return "";
}

std::vector<std::string> ClientArguments(const SweepConfig& config, const Cell& cell,
                                         const std::string& out_dir) {
  const MethodSpec& method = config.methods[cell.method];
  const SceneSpec& scene = config.scenes[cell.scene];
  std::vector<std::string> args = {"--on-device",   "--fast", "--projector", "cpu",         "--fps",
                                   Short(cell.fps), "--out",  out_dir,       "--no-map-png"};
  args.push_back(config.occlusion ? "--occlusion" : "--no-occlusion");
  auto add = [&args](const char* flag, const std::string& value) {
    if (value.empty()) return;
    args.push_back(flag);
    args.push_back(value);
  };
  add("--mesh", scene.mesh);
  add("--trajectory", scene.trajectory);
  add("--camera", scene.camera);
  const double duration_s = scene.duration_s > 0 ? scene.duration_s : config.duration_s;
  if (duration_s > 0) add("--duration", Short(duration_s));
  if (method.front_end != "vertex") add("--front-end", method.front_end);
  add("--method", method.plugin);
  add("--method-config", method.plugin_config);
  if (method.takes_feature_noise()) {
    if (cell.noise_px > 0) add("--noise-px", Short(cell.noise_px));
    if (cell.outlier_ids > 0) add("--outlier-ids", Short(cell.outlier_ids));
  }
  for (const auto* extra : {&scene.args, &method.args, &config.client_args})
    args.insert(args.end(), extra->begin(), extra->end());
  return args;
}

}  // namespace m2s::workbench
