// Finds and loads a plug-in (a shared library exporting m2s_plugin_entry, m2s_plugin.h) by
// name or path, and checks its table.
//
// A name ([a-z0-9_]+) is looked up as libm2s_plugin_<name>.so in the search path: each
// folder of the environment variable M2S_PLUGIN_PATH (colon-separated), then plugins/ next to
// the running executable's folder (<build>/plugins for <build>/bin/m2s_server), then the
// install's lib/m2s/plugins. Anything else (containing a '/' or ending in .so) is a path, opened
// as given. Every failure is one line naming the file: not found (with the folders searched),
// the dlopen error, no m2s_plugin_entry symbol, the entry returned NULL, an ABI version
// mismatch (both numbers), a required function missing, a bad name.
//
// The library stays loaded as long as a LoadedPlugin refers to it (instances keep theirs).
// Thread-safety: LoadPlugin may be called from any thread; a LoadedPlugin is immutable.
//
//   auto plugin = plugin::LoadPlugin("pnp_odometry");   // Expected<shared_ptr<...>>
//   if (!plugin) { std::cerr << plugin.error() << "\n"; return 2; }
//   const m2s_plugin& table = (*plugin)->table();
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "m2s/common/status.h"
#include "m2s/plugin/m2s_plugin.h"

namespace m2s::plugin {

class LoadedPlugin {
 public:
  LoadedPlugin(void* handle, const m2s_plugin* table, std::string path);
  ~LoadedPlugin();  // dlclose
  LoadedPlugin(const LoadedPlugin&) = delete;
  LoadedPlugin& operator=(const LoadedPlugin&) = delete;

  const m2s_plugin& table() const { return *table_; }
  // The plug-in's own name (table().name) and the file it was loaded from.
  const std::string& name() const { return name_; }
  const std::string& path() const { return path_; }

 private:
  void* handle_;
  const m2s_plugin* table_;
  std::string name_;
  std::string path_;
};

// True for a plug-in name: [a-z0-9_]+, at most 64 characters.
bool IsPluginName(const std::string& name);
// The folders a name is looked up in, in order.
std::vector<std::string> PluginSearchPath();
// The file name of plug-in `name`: libm2s_plugin_<name>.so.
std::string PluginFileName(const std::string& name);

Expected<std::shared_ptr<const LoadedPlugin>> LoadPlugin(const std::string& name_or_path);

}  // namespace m2s::plugin
