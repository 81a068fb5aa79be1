#include "scene_cache.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "m2s/common/logging.h"

namespace m2s::internal {
namespace {

namespace fs = std::filesystem;

constexpr char kMagic[8] = {'M', '2', 'S', 'S', 'C', 'E', 'N', 'E'};
// Bumped whenever LoadScene's id order or this format changes: old entries are then ignored.
constexpr uint32_t kVersion = 2;                // 2: parts
constexpr size_t kReadChunk = size_t{1} << 24;  // 16 MiB
// Entries above this are refused on read (a corrupt header must not trigger a huge allocation).
constexpr uint64_t kMaxElements = uint64_t{1} << 32;

uint64_t Mix(uint64_t h) {
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdULL;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ULL;
  h ^= h >> 33;
  return h;
}

std::vector<double> OptionValues(const SceneLoadOptions& o) {
  return {o.scale,        o.rotation.w(),    o.rotation.x(),    o.rotation.y(),
          o.rotation.z(), o.translation.x(), o.translation.y(), o.translation.z()};
}

std::string EntryPath(const std::string& dir, uint64_t key) {
  char name[32];
  std::snprintf(name, sizeof(name), "%016llx.m2sscene", static_cast<unsigned long long>(key));
  return (fs::path(dir) / name).string();
}

template <typename T>
void Put(std::ofstream& out, const T& value) {
  out.write(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <typename T>
bool Get(std::ifstream& in, T* value) {
  return static_cast<bool>(in.read(reinterpret_cast<char*>(value), sizeof(T)));
}

uint64_t PayloadChecksum(const Scene& scene) {
  const uint64_t h =
      HashBytes(scene.positions.data(), scene.positions.size() * sizeof(float) * 3, 0x5ce9e5ULL);
  return HashBytes(scene.triangles.data(), scene.triangles.size() * sizeof(uint32_t), h);
}

void PutIds(std::ofstream& out, const std::vector<VertexId>& ids) {
  Put(out, static_cast<uint64_t>(ids.size()));
  out.write(reinterpret_cast<const char*>(ids.data()),
            static_cast<std::streamsize>(ids.size() * sizeof(VertexId)));
}

bool GetIds(std::ifstream& in, uint64_t max_id, std::vector<VertexId>* ids) {
  uint64_t count = 0;
  if (!Get(in, &count) || count > max_id) return false;
  ids->resize(count);
  if (!in.read(reinterpret_cast<char*>(ids->data()),
               static_cast<std::streamsize>(count * sizeof(VertexId))))
    return false;
  for (VertexId id : *ids)
    if (id >= max_id) return false;
  return true;
}

// Parts: count, then per part its name, triangle range, id range, extra and given ids.
void PutParts(std::ofstream& out, const std::vector<ScenePart>& parts) {
  Put(out, static_cast<uint64_t>(parts.size()));
  for (const ScenePart& part : parts) {
    const auto name_bytes = static_cast<uint32_t>(std::min<size_t>(part.name.size(), 4096));
    Put(out, name_bytes);
    out.write(part.name.data(), name_bytes);
    for (uint32_t value :
         {part.first_triangle, part.num_triangles, part.first_vertex, part.end_vertex})
      Put(out, value);
    PutIds(out, part.extra_ids);
    PutIds(out, part.given_ids);
  }
}

bool GetParts(std::ifstream& in, const Scene& scene, std::vector<ScenePart>* parts) {
  uint64_t count = 0;
  if (!Get(in, &count) || count > scene.num_vertices() + scene.num_triangles() + 1) return false;
  parts->resize(count);
  for (ScenePart& part : *parts) {
    uint32_t name_bytes = 0;
    if (!Get(in, &name_bytes) || name_bytes > 4096) return false;
    part.name.resize(name_bytes);
    if (!in.read(part.name.data(), name_bytes) || !Get(in, &part.first_triangle) ||
        !Get(in, &part.num_triangles) || !Get(in, &part.first_vertex) || !Get(in, &part.end_vertex))
      return false;
    if (uint64_t{part.first_triangle} + part.num_triangles > scene.num_triangles() ||
        part.first_vertex > part.end_vertex || part.end_vertex > scene.num_vertices())
      return false;
    if (!GetIds(in, scene.num_vertices(), &part.extra_ids) ||
        !GetIds(in, scene.num_vertices(), &part.given_ids))
      return false;
  }
  return true;
}

}  // namespace

uint64_t HashBytes(const void* data, size_t size, uint64_t seed) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  uint64_t h = Mix(seed ^ (size * 0x9e3779b97f4a7c15ULL));
  size_t i = 0;
  for (; i + 8 <= size; i += 8) {
    uint64_t word;
    std::memcpy(&word, bytes + i, 8);
    h = (h ^ Mix(word)) * 0x9e3779b97f4a7c15ULL;
    h = (h << 27) | (h >> 37);
  }
  uint64_t tail = 0;
  std::memcpy(&tail, bytes + i, size - i);
  return Mix(h ^ Mix(tail ^ 0xa0761d6478bd642fULL));
}

std::optional<uint64_t> SceneCacheKey(const std::string& path, const SceneLoadOptions& options,
                                      uint64_t* source_size) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  std::vector<char> buffer(kReadChunk);
  uint64_t h = kVersion, size = 0;
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const size_t n = static_cast<size_t>(in.gcount());
    if (n == 0) break;
    h = HashBytes(buffer.data(), n, h);
    size += n;
  }
  if (in.bad()) return std::nullopt;
  const std::vector<double> values = OptionValues(options);
  h = HashBytes(values.data(), values.size() * sizeof(double), h);
  *source_size = size;
  return h;
}

std::string SceneCacheDir(const SceneLoadOptions& options) {
  if (!options.cache_dir.empty()) return options.cache_dir;
  if (const char* dir = std::getenv("M2S_CACHE_DIR"); dir != nullptr && *dir != '\0') return dir;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg != nullptr && *xdg != '\0')
    return (fs::path(xdg) / "mesh2slam").string();
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0')
    return (fs::path(home) / ".cache" / "mesh2slam").string();
  return "";
}

std::optional<Scene> ReadSceneCache(const std::string& dir, uint64_t key, uint64_t source_size,
                                    const SceneLoadOptions& options) {
  const std::string path = EntryPath(dir, key);
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  auto damaged = [&path](const char* why) -> std::optional<Scene> {
    M2S_LOG(kWarning) << "scene cache entry " << path << " ignored: " << why;
    return std::nullopt;
  };
  char magic[8];
  uint32_t version = 0;
  uint64_t stored_key = 0, stored_size = 0, vertices = 0, indices = 0;
  uint32_t name_bytes = 0;
  if (!in.read(magic, 8) || std::memcmp(magic, kMagic, 8) != 0) return damaged("not a cache file");
  if (!Get(in, &version) || version != kVersion) return damaged("another format version");
  if (!Get(in, &stored_key) || !Get(in, &stored_size)) return damaged("truncated header");
  if (stored_key != key || stored_size != source_size) return damaged("another source file");
  for (double expected : OptionValues(options)) {
    double value = 0;
    if (!Get(in, &value)) return damaged("truncated header");
    if (std::memcmp(&value, &expected, sizeof(double)) != 0) return damaged("other load options");
  }
  if (!Get(in, &vertices) || !Get(in, &indices) || !Get(in, &name_bytes))
    return damaged("truncated header");
  if (vertices == 0 || vertices >= kMaxElements || indices >= kMaxElements || indices % 3 != 0 ||
      name_bytes > 4096)
    return damaged("implausible sizes");
  Scene scene;
  scene.name.resize(name_bytes);
  scene.positions.resize(vertices);
  scene.triangles.resize(indices);
  if (!in.read(scene.name.data(), name_bytes) ||
      !in.read(reinterpret_cast<char*>(scene.positions.data()),
               static_cast<std::streamsize>(vertices * 3 * sizeof(float))) ||
      !in.read(reinterpret_cast<char*>(scene.triangles.data()),
               static_cast<std::streamsize>(indices * sizeof(uint32_t))))
    return damaged("truncated payload");
  if (!GetParts(in, scene, &scene.parts)) return damaged("bad parts");
  uint64_t checksum = 0;
  if (!Get(in, &checksum) || checksum != PayloadChecksum(scene)) return damaged("bad checksum");
  for (uint32_t index : scene.triangles)
    if (index >= vertices) return damaged("triangle index out of range");
  return scene;
}

void WriteSceneCache(const std::string& dir, uint64_t key, uint64_t source_size,
                     const SceneLoadOptions& options, const Scene& scene) {
  std::error_code error;
  fs::create_directories(dir, error);
  const std::string path = EntryPath(dir, key);
  const std::string temporary = path + ".tmp" + std::to_string(::getpid());
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out.write(kMagic, 8);
    Put(out, kVersion);
    Put(out, key);
    Put(out, source_size);
    for (double value : OptionValues(options)) Put(out, value);
    Put(out, static_cast<uint64_t>(scene.positions.size()));
    Put(out, static_cast<uint64_t>(scene.triangles.size()));
    Put(out, static_cast<uint32_t>(std::min<size_t>(scene.name.size(), 4096)));
    out.write(scene.name.data(),
              static_cast<std::streamsize>(std::min<size_t>(scene.name.size(), 4096)));
    out.write(reinterpret_cast<const char*>(scene.positions.data()),
              static_cast<std::streamsize>(scene.positions.size() * 3 * sizeof(float)));
    out.write(reinterpret_cast<const char*>(scene.triangles.data()),
              static_cast<std::streamsize>(scene.triangles.size() * sizeof(uint32_t)));
    PutParts(out, scene.parts);
    Put(out, PayloadChecksum(scene));
    out.close();
    if (!out) {
      M2S_LOG(kWarning) << "scene cache: cannot write " << temporary << " (cache left alone)";
      fs::remove(temporary, error);
      return;
    }
  }
  fs::rename(temporary, path, error);
  if (error) {
    M2S_LOG(kWarning) << "scene cache: cannot rename into " << path << ": " << error.message();
    fs::remove(temporary, error);
  }
}

}  // namespace m2s::internal
