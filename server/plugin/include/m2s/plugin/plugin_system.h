// A plug-in instance served as a slam::System, so the session manager, the metrics, the
// trajectories, the map deltas to the client and the evaluation work unchanged; and the
// factories that pick a localisation method by name (m2s_server / m2s_client --method).
//
// The PluginSystem validates each frame as the built-in SLAM does (plug-ins get the same
// features: sorted by id, within Options::feature_budget) and hands it to process_frame.
// A frame the plug-in fails on is rejected (reason "plugin_error"), a pose that is not finite
// or not a rotation counts the frame lost; both are logged at most once a second, never fatal.
// Map deltas come from map_points (the difference with what was last handed out; no
// keyframes), the trajectory from the plug-in's trajectory() or else each frame's result.
// SaveMap / LoadMap are refused; Reset calls the plug-in's reset (or recreates the instance).
// Shutdown / the destructor destroy the instance exactly once.
//
// Thread-safety: as slam::System (calls into the instance are serialised).
//
//   auto method = plugin::LoadMethod("pnp_odometry", "{}");   // Expected<MethodFactories>
//   server_app::SessionManager manager(options, publish, method->system, method->group);
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "m2s/plugin/loader.h"
#include "m2s/slam/system.h"

namespace m2s::plugin {

// The built-in SLAM's name; "" means it too. It is linked in, never loaded.
inline constexpr const char* kBuiltinMethod = "vertex_slam";
bool IsBuiltinMethod(const std::string& method);

// An instance of `plugin` for options.camera, with the plug-in's config (a JSON object's text).
Expected<std::unique_ptr<slam::System>> CreatePluginSystem(
    std::shared_ptr<const LoadedPlugin> plugin, const slam::Options& options,
    const std::string& config_json);

// What a server needs to serve a method (types as server_app::SystemFactory / MapGroupFactory).
struct MethodFactories {
  std::string name;  // kBuiltinMethod or the plug-in's name
  std::string path;  // the plug-in's file; empty for the built-in SLAM
  std::function<Expected<std::unique_ptr<slam::System>>(const slam::Options&)> system;
  // The built-in SLAM's map groups; with a plug-in every map group is refused (the session's
  // HELLO gets REJECTED: "map groups need the built-in SLAM ...").
  std::function<Expected<std::shared_ptr<slam::MapGroup>>(const slam::Options&)> group;
};

// Loads method `method` (a plug-in name or path; "" or kBuiltinMethod: the built-in SLAM) once;
// its factory makes an instance per session. The plug-in's config is checked by creating one
// instance for a 640x480 camera (so a bad config fails here, not at the first session). A
// config with the built-in SLAM is refused (its options are the server's).
Expected<MethodFactories> LoadMethod(const std::string& method, const std::string& config_json);

// The text of a --method-config file; it must hold a JSON object.
Expected<std::string> ReadMethodConfig(const std::string& path);

}  // namespace m2s::plugin
