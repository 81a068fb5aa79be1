// Test helpers for the map: a small populated map and the bytes of its saved file.
#pragma once

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "map/map.h"

namespace m2s::slam {

// Three keyframes seeing overlapping ids; points 0..9 are seen by all, 10..14 by the first two.
inline void Populate(Map* map) {
  map->Write([](MapData& m) {
    for (KeyframeId k = 0; k < 3; ++k) {
      Keyframe kf;
      kf.id = k;
      kf.seq = 10 * k;
      kf.timestamp = 0.5 * k;
      kf.world_from_camera = Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * k, 0, 0));
      for (VertexId v = 0; v < 20; ++v) {
        kf.ids.push_back(v);
        kf.uvs.emplace_back(10.0 * v, 5.0 * k);
      }
      m.AddKeyframe(std::move(kf));
    }
    for (VertexId v = 0; v < 15; ++v) {
      m.AddPoint(v, Eigen::Vector3d(v, 1, 2), 0);
      m.AddObservation(v, 0);
      m.AddObservation(v, 1);
      if (v < 10) m.AddObservation(v, 2);
    }
  });
}

inline std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline void WriteFileBytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// The saved file of Populate()'s map for `camera`.
inline std::string PopulatedMapFile(const Camera& camera) {
  Map map;
  Populate(&map);
  const std::string path = ::testing::TempDir() + "/m2s_populated.m2smap";
  EXPECT_TRUE(map.Save(path, camera).ok());
  std::string bytes = ReadFileBytes(path);
  std::remove(path.c_str());
  return bytes;
}

}  // namespace m2s::slam
