#include "m2s/plugin/loader.h"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>
#include <system_error>

namespace m2s::plugin {
namespace {

constexpr size_t kMaxNameLength = 64;

std::string ExecutableDir() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::string() : exe.parent_path().string();
}

// The first required function missing from the table, or nullptr.
const char* MissingRequired(const m2s_plugin& t) {
  if (t.create == nullptr) return "create";
  if (t.process_frame == nullptr) return "process_frame";
  if (t.current_pose == nullptr) return "current_pose";
  if (t.map_points == nullptr) return "map_points";
  if (t.destroy == nullptr) return "destroy";
  return nullptr;
}

Expected<std::shared_ptr<const LoadedPlugin>> Open(const std::string& path) {
  dlerror();
  void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (handle == nullptr) {
    const char* why = dlerror();
    return Status::Error("plug-in " + path + ": cannot load: " + (why ? why : "dlopen failed"));
  }
  auto fail = [&](const std::string& why) {
    dlclose(handle);
    return Status::Error("plug-in " + path + ": " + why);
  };
  void* symbol = dlsym(handle, M2S_PLUGIN_ENTRY_SYMBOL);
  if (symbol == nullptr) {
    return fail("no " + std::string(M2S_PLUGIN_ENTRY_SYMBOL) +
                " symbol (not a Mesh2SLAM plug-in, or the entry is not exported with "
                "M2S_PLUGIN_EXPORT / extern \"C\")");
  }
  const m2s_plugin* table = reinterpret_cast<m2s_plugin_entry_fn>(symbol)();
  if (table == nullptr) return fail(std::string(M2S_PLUGIN_ENTRY_SYMBOL) + "() returned NULL");
  if (table->abi_version != M2S_PLUGIN_ABI_VERSION) {
    return fail("ABI version " + std::to_string(table->abi_version) + ", this host needs " +
                std::to_string(M2S_PLUGIN_ABI_VERSION) + " (rebuild it against this m2s_plugin.h)");
  }
  if (const char* missing = MissingRequired(*table)) {
    return fail("required function " + std::string(missing) + " is NULL");
  }
  if (table->name == nullptr || !IsPluginName(table->name)) {
    return fail("its name must be [a-z0-9_]+ (at most 64 characters)");
  }
  return std::shared_ptr<const LoadedPlugin>(std::make_shared<LoadedPlugin>(handle, table, path));
}

}  // namespace

LoadedPlugin::LoadedPlugin(void* handle, const m2s_plugin* table, std::string path)
    : handle_(handle), table_(table), name_(table->name), path_(std::move(path)) {}

LoadedPlugin::~LoadedPlugin() {
  if (handle_ != nullptr) dlclose(handle_);
}

bool IsPluginName(const std::string& name) {
  if (name.empty() || name.size() > kMaxNameLength) return false;
  for (char c : name) {
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_')) return false;
  }
  return true;
}

std::string PluginFileName(const std::string& name) { return "libm2s_plugin_" + name + ".so"; }

std::vector<std::string> PluginSearchPath() {
  std::vector<std::string> dirs;
  if (const char* env = std::getenv("M2S_PLUGIN_PATH")) {
    const std::string path = env;
    size_t begin = 0;
    while (begin <= path.size()) {
      const size_t end = std::min(path.find(':', begin), path.size());
      if (end > begin) dirs.push_back(path.substr(begin, end - begin));
      begin = end + 1;
    }
  }
  if (const std::string exe_dir = ExecutableDir(); !exe_dir.empty()) {
    dirs.push_back((std::filesystem::path(exe_dir).parent_path() / "plugins").string());
  }
#ifdef M2S_INSTALL_PLUGIN_DIR
  dirs.push_back(M2S_INSTALL_PLUGIN_DIR);
#endif
  return dirs;
}

Expected<std::shared_ptr<const LoadedPlugin>> LoadPlugin(const std::string& name_or_path) {
  const bool is_path =
      name_or_path.find('/') != std::string::npos ||
      (name_or_path.size() > 3 && name_or_path.compare(name_or_path.size() - 3, 3, ".so") == 0);
  if (is_path) {
    std::error_code ec;
    if (!std::filesystem::exists(name_or_path, ec)) {
      return Status::Error("plug-in " + name_or_path + ": no such file");
    }
    return Open(name_or_path);
  }
  if (!IsPluginName(name_or_path)) {
    return Status::Error("plug-in name \"" + name_or_path +
                         "\" is not valid: a name is [a-z0-9_]+ (at most 64 characters), a path "
                         "contains a '/'");
  }
  const std::string file = PluginFileName(name_or_path);
  std::string searched;
  for (const std::string& dir : PluginSearchPath()) {
    const std::filesystem::path candidate = std::filesystem::path(dir) / file;
    std::error_code ec;
    if (std::filesystem::exists(candidate, ec)) {
      auto loaded = Open(candidate.string());
      if (loaded && (*loaded)->name() != name_or_path) {
        return Status::Error("plug-in " + candidate.string() + ": its name is \"" +
                             (*loaded)->name() + "\", not \"" + name_or_path + "\"");
      }
      return loaded;
    }
    searched += (searched.empty() ? "" : ", ") + dir;
  }
  return Status::Error("plug-in " + name_or_path + ": " + file + " not found (searched " +
                       (searched.empty() ? std::string("nothing") : searched) +
                       "; set M2S_PLUGIN_PATH)");
}

}  // namespace m2s::plugin
