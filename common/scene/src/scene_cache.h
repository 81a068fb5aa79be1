// Internal: the binary cache of loaded scenes (SceneLoadOptions::use_cache; see scene.h).
//
// A cache entry holds exactly what LoadScene built (name, positions, triangles) for one source
// file content and one set of load options. Its name is the 64-bit key in hex; its header
// repeats the key, the source size and the options, and a checksum covers the payload, so a
// stale, truncated or corrupt entry is detected and ignored (the file is then parsed again and
// the entry rewritten). Entries are written to a temporary name and renamed into place, so
// concurrent loads of one file never read a half-written entry.
//
// Format (little-endian): "M2SSCENE" | u32 version | u64 key | u64 source size |
// 8 x f64 options (scale, qw, qx, qy, qz, tx, ty, tz) | u64 vertices | u64 triangle indices |
// u32 name bytes | name | f32 x 3 per vertex | u32 per triangle index | u64 payload checksum.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "m2s/common/scene.h"

namespace m2s::internal {

// 64-bit hash of a byte range (8 bytes at a time, a multiply-xorshift mix; ~GB/s).
uint64_t HashBytes(const void* data, size_t size, uint64_t seed);

// The cache key of a file's content under these options; nullopt when the file cannot be read.
std::optional<uint64_t> SceneCacheKey(const std::string& path, const SceneLoadOptions& options,
                                      uint64_t* source_size);

// The folder of the cache: options.cache_dir, else $M2S_CACHE_DIR, else
// $XDG_CACHE_HOME/mesh2slam, else $HOME/.cache/mesh2slam; empty when none can be named.
std::string SceneCacheDir(const SceneLoadOptions& options);

// The entry for key in dir, when it exists and is intact and matches; nullopt otherwise (a
// damaged entry is logged).
std::optional<Scene> ReadSceneCache(const std::string& dir, uint64_t key, uint64_t source_size,
                                    const SceneLoadOptions& options);

// Writes the entry (creating dir); failures are logged and otherwise ignored: the cache only
// accelerates.
void WriteSceneCache(const std::string& dir, uint64_t key, uint64_t source_size,
                     const SceneLoadOptions& options, const Scene& scene);

}  // namespace m2s::internal
