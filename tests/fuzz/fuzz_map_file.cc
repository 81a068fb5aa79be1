// Fuzz target of map files (server/map/map_io.cc): Map::LoadFromBytes.
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>

#include "fuzz_targets.h"
#include "m2s/common/camera.h"
#include "m2s/common/check.h"
#include "map/map.h"

namespace m2s::fuzz {
namespace {

// Saves `map` and returns the file's bytes (a file per process: libFuzzer may run several).
std::string SavedBytes(const slam::Map& map, const Camera& camera) {
  const std::string path = "/tmp/m2s_fuzz_map_" + std::to_string(getpid()) + ".m2smap";
  const Status saved = map.Save(path, camera);
  M2S_CHECK(saved.ok()) << saved.message();
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::remove(path.c_str());
  return bytes;
}

// Poses are renormalised on load, so they agree to rounding; everything else exactly.
bool SamePose(const Pose3& a, const Pose3& b) {
  return a.rotation().angularDistance(b.rotation()) < 1e-9 &&
         (a.translation() - b.translation()).norm() <= 1e-12 * (1 + a.translation().norm());
}

void CheckSameMaps(const slam::MapData& a, const slam::MapData& b) {
  M2S_CHECK(a.keyframes().size() == b.keyframes().size());
  for (const auto& [id, kf] : a.keyframes()) {
    const slam::Keyframe* other = b.keyframe(id);
    M2S_CHECK(other != nullptr && other->seq == kf.seq && other->timestamp == kf.timestamp &&
              other->ids == kf.ids && other->uvs == kf.uvs && other->num_points == kf.num_points)
        << "keyframe " << id;
    M2S_CHECK(SamePose(kf.world_from_camera, other->world_from_camera)) << "keyframe " << id;
  }
  M2S_CHECK(a.points().size() == b.points().size());
  for (const auto& [id, p] : a.points()) {
    const slam::MapPoint* other = b.point(id);
    M2S_CHECK(other != nullptr && other->position == p.position &&
              other->reference_keyframe == p.reference_keyframe && other->observers == p.observers)
        << "point " << id;
  }
  M2S_CHECK(a.links().size() == b.links().size());
  for (const auto& [id, link] : a.links()) {
    const auto other = b.links().find(id);
    M2S_CHECK(other != b.links().end() && other->second.parent == link.parent &&
              SamePose(link.parent_from_camera, other->second.parent_from_camera))
        << "link " << id;
  }
}

}  // namespace

int FuzzMapFile(const uint8_t* data, size_t size) {
  const Camera camera;  // the camera of the committed seed maps
  slam::Map map;
  const Status loaded = map.LoadFromBytes(data, size, camera);
  if (!loaded.ok()) {
    // A failed load leaves the map as it was.
    M2S_CHECK(!loaded.message().empty());
    M2S_CHECK(map.revision() == 0);
    map.Read([](const slam::MapData& m) { M2S_CHECK(m.empty() && m.points().empty()); });
    return 0;
  }
  const slam::MapDelta full = map.FullDelta();
  M2S_CHECK(full.full && full.point_ids.size() == full.point_positions.size());
  map.Read([](const slam::MapData& m) {
    for (const auto& [id, kf] : m.keyframes()) {
      M2S_CHECK(kf.ids.size() == kf.uvs.size());
      M2S_CHECK(m.ResolveKeyframePose(id).has_value());
    }
  });
  // What a loaded map saves loads again into the same map.
  const std::string saved = SavedBytes(map, camera);
  slam::Map reloaded;
  const Status again = reloaded.LoadFromBytes(saved.data(), saved.size(), camera);
  M2S_CHECK(again.ok()) << again.message();
  map.Read([&reloaded](const slam::MapData& a) {
    reloaded.Read([&a](const slam::MapData& b) { CheckSameMaps(a, b); });
  });
  return 0;
}

}  // namespace m2s::fuzz
