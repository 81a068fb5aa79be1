// The scene cache (SceneLoadOptions::use_cache): a cached load gives exactly the parsed scene,
// an unchanged entry is reused, and edited sources, other transforms and damaged entries never
// give a stale scene.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

#include <gtest/gtest.h>

#include "m2s/common/scene.h"

namespace m2s {
namespace {

namespace fs = std::filesystem;

class SceneCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("m2s_scene_cache_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "cache");
    options_.cache_dir = (dir_ / "cache").string();
    options_.cache_min_bytes = 0;  // every file, however small
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A wavy grid of n x n vertices as an OBJ (quads, so triangulation runs too).
  fs::path WriteGrid(const std::string& name, int n, double amplitude) {
    const fs::path path = dir_ / name;
    std::ofstream out(path);
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        out << "v " << i * 0.1 << " " << j * 0.1 << " " << amplitude * std::sin(i * 0.7 + j)
            << "\n";
    for (int j = 0; j + 1 < n; ++j)
      for (int i = 0; i + 1 < n; ++i) {
        const int a = j * n + i + 1;
        out << "f " << a << " " << a + 1 << " " << a + n + 1 << " " << a + n << "\n";
      }
    return path;
  }

  std::vector<fs::path> Entries() const {
    std::vector<fs::path> entries;
    for (const auto& e : fs::directory_iterator(dir_ / "cache")) entries.push_back(e.path());
    return entries;
  }

  static void ExpectSame(const Scene& a, const Scene& b) {
    ASSERT_EQ(a.positions.size(), b.positions.size());
    for (size_t i = 0; i < a.positions.size(); ++i) ASSERT_EQ(a.positions[i], b.positions[i]) << i;
    EXPECT_EQ(a.triangles, b.triangles);
    EXPECT_EQ(a.name, b.name);
  }

  fs::path dir_;
  SceneLoadOptions options_;
};

TEST_F(SceneCacheTest, CachedLoadEqualsParsingAndReusesTheEntry) {
  const fs::path mesh = WriteGrid("grid.obj", 40, 0.2);
  SceneLoadOptions uncached = options_;
  uncached.use_cache = false;
  const Expected<Scene> parsed = LoadScene(mesh.string(), uncached);
  ASSERT_TRUE(parsed) << parsed.error();
  EXPECT_TRUE(Entries().empty());

  const Expected<Scene> first = LoadScene(mesh.string(), options_);  // parses, writes the entry
  ASSERT_TRUE(first);
  ASSERT_EQ(Entries().size(), 1u);
  const fs::path entry = Entries()[0];
  const auto written = fs::last_write_time(entry);
  const Expected<Scene> second = LoadScene(mesh.string(), options_);  // reads the entry
  ASSERT_TRUE(second);
  ExpectSame(*parsed, *first);
  ExpectSame(*parsed, *second);
  EXPECT_EQ(fs::last_write_time(entry), written);  // not rewritten
  EXPECT_EQ(Entries().size(), 1u);

  // The same content under another name: the entry serves it, with its own name.
  fs::copy_file(mesh, dir_ / "copy.obj");
  const Expected<Scene> copy = LoadScene((dir_ / "copy.obj").string(), options_);
  ASSERT_TRUE(copy);
  EXPECT_EQ(copy->name, "copy");
  EXPECT_EQ(copy->positions, parsed->positions);
  EXPECT_EQ(Entries().size(), 1u);
}

TEST_F(SceneCacheTest, EditedSourceAndOtherTransformGetTheirOwnEntries) {
  const fs::path mesh = WriteGrid("grid.obj", 30, 0.2);
  ASSERT_TRUE(LoadScene(mesh.string(), options_));
  // Same size, other bytes: a stale entry must not be used.
  WriteGrid("grid.obj", 30, 0.3);
  SceneLoadOptions uncached = options_;
  uncached.use_cache = false;
  const Expected<Scene> edited = LoadScene(mesh.string(), options_);
  ASSERT_TRUE(edited);
  ExpectSame(*LoadScene(mesh.string(), uncached), *edited);
  EXPECT_EQ(Entries().size(), 2u);

  SceneLoadOptions scaled = options_;
  scaled.scale = 2.0;
  const Expected<Scene> big = LoadScene(mesh.string(), scaled);
  ASSERT_TRUE(big);
  EXPECT_EQ(big->positions[5], (edited->positions[5] * 2.0f));
  EXPECT_EQ(Entries().size(), 3u);
}

TEST_F(SceneCacheTest, DamagedEntriesAreIgnoredAndRewritten) {
  const fs::path mesh = WriteGrid("grid.obj", 30, 0.2);
  const Expected<Scene> parsed = LoadScene(mesh.string(), options_);
  ASSERT_TRUE(parsed);
  const fs::path entry = Entries().at(0);
  const uintmax_t full_size = fs::file_size(entry);

  // A flipped byte in the positions: the checksum refuses it.
  {
    std::fstream f(entry, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(full_size / 2));
    char c = 0;
    f.read(&c, 1);
    f.seekp(static_cast<std::streamoff>(full_size / 2));
    c = static_cast<char>(c ^ 0x40);
    f.write(&c, 1);
  }
  Expected<Scene> reloaded = LoadScene(mesh.string(), options_);
  ASSERT_TRUE(reloaded);
  ExpectSame(*parsed, *reloaded);

  // Truncated (a crash while writing it elsewhere), then garbage: same.
  fs::resize_file(entry, full_size / 3);
  reloaded = LoadScene(mesh.string(), options_);
  ASSERT_TRUE(reloaded);
  ExpectSame(*parsed, *reloaded);
  EXPECT_EQ(fs::file_size(entry), full_size);  // rewritten whole
  std::ofstream(entry, std::ios::trunc) << "not a cache entry";
  reloaded = LoadScene(mesh.string(), options_);
  ASSERT_TRUE(reloaded);
  ExpectSame(*parsed, *reloaded);
}

TEST_F(SceneCacheTest, SmallFilesAndUnwritableFoldersStillLoad) {
  const fs::path mesh = WriteGrid("grid.obj", 10, 0.2);
  SceneLoadOptions small = options_;
  small.cache_min_bytes = fs::file_size(mesh) + 1;
  ASSERT_TRUE(LoadScene(mesh.string(), small));
  EXPECT_TRUE(Entries().empty());

  SceneLoadOptions nowhere = options_;
  nowhere.cache_dir = "/proc/m2s_no_such_cache_dir";  // cannot be created
  const Expected<Scene> loaded = LoadScene(mesh.string(), nowhere);
  ASSERT_TRUE(loaded) << loaded.error();
  EXPECT_GT(loaded->num_vertices(), 0u);
}

}  // namespace
}  // namespace m2s
