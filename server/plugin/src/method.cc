#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "m2s/plugin/plugin_system.h"

namespace m2s::plugin {

Expected<MethodFactories> LoadMethod(const std::string& method, const std::string& config_json) {
  const bool has_config = !config_json.empty() && config_json != "{}";
  if (IsBuiltinMethod(method)) {
    if (has_config) {
      return Status::Error("a method config is for plug-ins; the built-in SLAM (" +
                           std::string(kBuiltinMethod) + ") takes the server's options");
    }
    MethodFactories factories;
    factories.name = kBuiltinMethod;
    factories.system = &slam::System::Create;
    factories.group = &slam::MapGroup::Create;
    return factories;
  }
  auto loaded = LoadPlugin(method);
  if (!loaded) return loaded.status();
  std::shared_ptr<const LoadedPlugin> plugin = *loaded;
  const std::string config = has_config ? config_json : "{}";
  {
    // The config is checked now: one instance for a default camera, shut down at once.
    slam::Options probe;
    auto instance = CreatePluginSystem(plugin, probe, config);
    if (!instance) return instance.status();
  }
  MethodFactories factories;
  factories.name = plugin->name();
  factories.path = plugin->path();
  factories.system = [plugin, config](const slam::Options& options) {
    return CreatePluginSystem(plugin, options, config);
  };
  factories.group =
      [name = plugin->name()](const slam::Options&) -> Expected<std::shared_ptr<slam::MapGroup>> {
    return Status::Error("map groups need the built-in SLAM (" + std::string(kBuiltinMethod) +
                         "); this server runs plug-in " + name);
  };
  return factories;
}

Expected<std::string> ReadMethodConfig(const std::string& path) {
  std::ifstream file(path);
  if (!file) return Status::Error("cannot open method config " + path);
  std::stringstream text;
  text << file.rdbuf();
  try {
    if (!nlohmann::json::parse(text.str()).is_object()) {
      return Status::Error("method config " + path + ": not a JSON object");
    }
  } catch (const nlohmann::json::exception& e) {
    return Status::Error("method config " + path + ": " + e.what());
  }
  return text.str();
}

}  // namespace m2s::plugin
