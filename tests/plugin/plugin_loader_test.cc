// The plug-in loader: each way a library can fail to be a plug-in gives its own one-line
// message naming the file; a plug-in is found by name through M2S_PLUGIN_PATH.
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>

#include <gtest/gtest.h>

#include "m2s/plugin/loader.h"

namespace m2s::plugin {
namespace {

const std::string kTestPlugins = std::string(M2S_BINARY_DIR) + "/test_plugins";

std::string TestPlugin(const std::string& name) {
  return kTestPlugins + "/" + PluginFileName(name);
}

// The error of loading `name_or_path`, which must fail; one line.
std::string LoadError(const std::string& name_or_path) {
  auto loaded = LoadPlugin(name_or_path);
  EXPECT_FALSE(loaded.ok()) << name_or_path << " loaded";
  if (loaded.ok()) return "";
  EXPECT_EQ(loaded.error().find('\n'), std::string::npos) << loaded.error();
  return loaded.error();
}

// Sets an environment variable for one scope.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::string& value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    setenv(name, value.c_str(), 1);
  }
  ~ScopedEnv() {
    if (old_) {
      setenv(name_, old_->c_str(), 1);
    } else {
      unsetenv(name_);
    }
  }

 private:
  const char* name_;
  std::optional<std::string> old_;
};

TEST(PluginLoader, LoadsAWorkingPluginByPath) {
  auto loaded = LoadPlugin(TestPlugin("faulty"));
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ((*loaded)->name(), "faulty");
  EXPECT_EQ((*loaded)->path(), TestPlugin("faulty"));
  EXPECT_EQ((*loaded)->table().abi_version, M2S_PLUGIN_ABI_VERSION);
  EXPECT_STREQ((*loaded)->table().description, "a plug-in for the tests");
}

TEST(PluginLoader, RefusesALibraryWithoutTheEntrySymbol) {
  const std::string error = LoadError(TestPlugin("no_entry"));
  EXPECT_NE(error.find(TestPlugin("no_entry")), std::string::npos) << error;
  EXPECT_NE(error.find("no m2s_plugin_entry symbol"), std::string::npos) << error;
}

TEST(PluginLoader, RefusesAnotherAbiVersionNamingBoth) {
  const std::string error = LoadError(TestPlugin("abi999"));
  EXPECT_NE(error.find(TestPlugin("abi999")), std::string::npos) << error;
  EXPECT_NE(error.find("ABI version 999, this host needs 1"), std::string::npos) << error;
}

TEST(PluginLoader, RefusesATableWithoutARequiredFunction) {
  const std::string error = LoadError(TestPlugin("null_fn"));
  EXPECT_NE(error.find(TestPlugin("null_fn")), std::string::npos) << error;
  EXPECT_NE(error.find("required function process_frame is NULL"), std::string::npos) << error;
}

TEST(PluginLoader, RefusesAnEntryReturningNull) {
  const std::string error = LoadError(TestPlugin("null_table"));
  EXPECT_NE(error.find("m2s_plugin_entry() returned NULL"), std::string::npos) << error;
}

TEST(PluginLoader, ReportsTheDlopenErrorOfAFileThatIsNoLibrary) {
  const auto dir = std::filesystem::temp_directory_path() / "m2s_plugin_loader_test";
  std::filesystem::create_directories(dir);
  const std::string junk = (dir / "libm2s_plugin_junk.so").string();
  std::ofstream(junk) << "not an ELF file\n";
  const std::string error = LoadError(junk);
  EXPECT_NE(error.find("plug-in " + junk + ": cannot load: "), std::string::npos) << error;
  EXPECT_NE(error.find("libm2s_plugin_junk.so"), std::string::npos) << error;  // dlerror's text
  std::filesystem::remove_all(dir);
}

TEST(PluginLoader, FindsAPluginByNameThroughM2sPluginPath) {
  ScopedEnv env("M2S_PLUGIN_PATH", "/nonexistent/m2s:" + kTestPlugins);
  auto loaded = LoadPlugin("faulty");
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ((*loaded)->path(), TestPlugin("faulty"));
  // The search path: the variable's folders first, then the others.
  const auto dirs = PluginSearchPath();
  ASSERT_GE(dirs.size(), 3u);
  EXPECT_EQ(dirs[0], "/nonexistent/m2s");
  EXPECT_EQ(dirs[1], kTestPlugins);
}

TEST(PluginLoader, ListsWhereItLookedForAMissingName) {
  ScopedEnv env("M2S_PLUGIN_PATH", "/nonexistent/m2s");
  const std::string error = LoadError("no_such_method");
  EXPECT_NE(error.find("libm2s_plugin_no_such_method.so not found"), std::string::npos) << error;
  EXPECT_NE(error.find("searched /nonexistent/m2s, "), std::string::npos) << error;
}

TEST(PluginLoader, RefusesABadNameAndAMissingPath) {
  EXPECT_NE(LoadError("Bad-Name").find("is not valid: a name is [a-z0-9_]+"), std::string::npos);
  EXPECT_NE(LoadError("/nonexistent/libm2s_plugin_x.so").find("no such file"), std::string::npos);
  EXPECT_TRUE(IsPluginName("pnp_odometry"));
  EXPECT_FALSE(IsPluginName(""));
  EXPECT_FALSE(IsPluginName(std::string(65, 'a')));
}

TEST(PluginLoader, RefusesALibraryWhoseNameIsNotTheOneAskedFor) {
  // libm2s_plugin_faulty.so copied as libm2s_plugin_other.so still calls itself "faulty".
  const auto dir = std::filesystem::temp_directory_path() / "m2s_plugin_name_test";
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(TestPlugin("faulty"), dir / PluginFileName("other"),
                             std::filesystem::copy_options::overwrite_existing);
  ScopedEnv env("M2S_PLUGIN_PATH", dir.string());
  const std::string error = LoadError("other");
  EXPECT_NE(error.find("its name is \"faulty\", not \"other\""), std::string::npos) << error;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace m2s::plugin
