// The SLAM map: MapData behind one reader-writer mutex owned by this object, with revisions,
// coalesced map deltas, drift-correction notices for the tracker, and Save/Load.
//
// Contract: one writer at a time (the mapping stage, or the system while it initialises or
// resets); any number of readers, concurrently (tracking reads the map on every frame while
// mapping reads it to build its problems). Read() runs a callable under a shared lock, Write()
// under the exclusive one: keep writes short (copy what you need, solve outside, write back).
// Every Write() that mutates bumps the revision by one.
//
//   Map map;
//   map.Write([&](MapData& m) { m.AddKeyframe(std::move(kf)); });
//   map.Read([&](const MapData& m) { n = m.points().size(); });
//   slam::MapDelta delta = map.TakeDelta();
#pragma once

#include <cstddef>
#include <cstdint>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <utility>

#include "m2s/common/camera.h"
#include "m2s/common/status.h"
#include "m2s/slam/system.h"
#include "map/map_data.h"

namespace m2s::slam {

// Published by drift correction: poses expressed in the world before `epoch` map to the
// corrected world through new_from_old (exact for the neighbourhood of the current keyframe).
struct WorldCorrection {
  uint64_t epoch = 0;
  Sim3 new_from_old;
};

class Map {
 public:
  Map() = default;
  Map(const Map&) = delete;
  Map& operator=(const Map&) = delete;

  template <typename F>
  decltype(auto) Read(F&& f) const {
    std::shared_lock<std::shared_mutex> lock(mutex_);
    return f(static_cast<const MapData&>(data_));
  }
  template <typename F>
  decltype(auto) Write(F&& f) {
    std::unique_lock<std::shared_mutex> lock(mutex_);
    struct Bump {
      Map* map;
      uint64_t before;
      ~Bump() {
        if (map->data_.mutation_count() != before) ++map->revision_;
      }
    } bump{this, data_.mutation_count()};
    return f(data_);
  }

  // A fresh keyframe id, never reused by this map (not even after Clear()).
  KeyframeId NextKeyframeId();
  // `count` consecutive fresh ids (a map merged in with renumbered keyframes); the first.
  KeyframeId ReserveKeyframeIds(size_t count);
  uint64_t revision() const;

  // Changes since the previous TakeDelta() (a full delta after Clear() or Load()). Deltas show
  // only well-constrained points (MapPoint::constrained): a point that stops being one is
  // listed as removed.
  MapDelta TakeDelta();
  // The whole map (base_revision 0, full; well-constrained points only); leaves TakeDelta()
  // undisturbed.
  MapDelta FullDelta() const;

  // Forgets everything; the next delta is full.
  void Clear();
  // Moves the contents out (set aside by multi-map tracking) and leaves the map empty as
  // Clear() does; keyframe ids stay unique across the two.
  MapData TakeData();
  // Multi-map merge (map/map_merge.h, MergeMapInto): the contents move by base_from_map into
  // `base`, which becomes the map; the move is published as a world correction (tracking
  // carries its pose over) and the next delta is full. Returns the correction's epoch.
  uint64_t MergeInto(MapData base, const Sim3& base_from_map);

  void PublishCorrection(const Sim3& new_from_old);
  WorldCorrection correction() const;

  // Versioned binary file: camera, keyframes (with all their features), points with observers.
  Status Save(const std::string& path, const Camera& camera) const;
  // Replaces the map with the file's content; fails (map untouched) on a bad or truncated file
  // or when the file's camera differs from `camera`. Every count in the file is checked against
  // the bytes that remain before anything is allocated for it.
  Status Load(const std::string& path, const Camera& camera);
  // The same for the bytes of a map file in memory.
  Status LoadFromBytes(const void* data, size_t size, const Camera& camera);

 private:
  MapDelta MakeDeltaLocked(bool full) const;
  // Replaces the map with loaded data (the next delta is full).
  void Install(MapData data, KeyframeId next_id);

  mutable std::shared_mutex mutex_;
  MapData data_;
  uint64_t revision_ = 0;
  uint64_t taken_revision_ = 0;
  bool next_delta_full_ = false;
  KeyframeId next_keyframe_id_ = 0;
  WorldCorrection correction_;
};

}  // namespace m2s::slam
