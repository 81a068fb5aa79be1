// Map files: save/load round trip, clear errors, and no allocation or read driven by a count
// the file does not hold.
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "map/map.h"
#include "map_test_util.h"

namespace m2s::slam {
namespace {

TEST(Map, SaveLoadRoundTrip) {
  Map map;
  Populate(&map);
  const Camera camera;
  const std::string path = ::testing::TempDir() + "/m2s_map_test.m2smap";
  ASSERT_TRUE(map.Save(path, camera).ok());
  Map loaded;
  const Status s = loaded.Load(path, camera);
  ASSERT_TRUE(s.ok()) << s.message();
  const MapDelta a = map.FullDelta(), b = loaded.FullDelta();
  EXPECT_EQ(a.point_ids, b.point_ids);
  EXPECT_EQ(a.point_positions, b.point_positions);
  ASSERT_EQ(a.keyframes.size(), b.keyframes.size());
  loaded.Read([](const MapData& m) {
    EXPECT_EQ(m.point(3)->observers, (std::vector<KeyframeId>{0, 1, 2}));
    EXPECT_EQ(m.keyframe(1)->uvs[7], Eigen::Vector2d(70.0, 5.0));
    EXPECT_EQ(m.keyframe(2)->seq, 20);
  });
  EXPECT_TRUE(loaded.TakeDelta().full);
  std::remove(path.c_str());
}

TEST(MapIo, TheCameraOfAMapFileIsReadBackWithoutLoadingIt) {
  Map map;
  Populate(&map);
  const Camera camera = Camera::FromHorizontalFov(1280, 720, 75.0);
  const std::string path = ::testing::TempDir() + "/m2s_map_camera_test.m2smap";
  ASSERT_TRUE(map.Save(path, camera).ok());
  const Expected<Camera> read = ReadMapFileCamera(path);
  ASSERT_TRUE(read.ok()) << read.error();
  EXPECT_EQ(read->width, 1280);
  EXPECT_EQ(read->height, 720);
  EXPECT_EQ(read->fx, camera.fx);
  EXPECT_EQ(read->fy, camera.fy);
  EXPECT_EQ(read->cx, camera.cx);
  EXPECT_EQ(read->cy, camera.cy);
  // The camera read back loads the file (Load compares it with the file's).
  Map loaded;
  EXPECT_TRUE(loaded.Load(path, *read).ok());
  // Not a map, truncated, missing: clear errors.
  std::ofstream(path, std::ios::binary | std::ios::trunc) << "M2SMAP01";
  EXPECT_NE(ReadMapFileCamera(path).error().find("bad map file"), std::string::npos);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << "not a map at all, no";
  EXPECT_NE(ReadMapFileCamera(path).error().find("not a Mesh2SLAM map"), std::string::npos);
  std::remove(path.c_str());
  EXPECT_NE(ReadMapFileCamera(path).error().find("cannot open"), std::string::npos);
}

TEST(Map, LoadRejectsBadFilesWithClearErrors) {
  const Camera camera;
  Map map;
  Populate(&map);
  const std::string path = ::testing::TempDir() + "/m2s_map_bad.m2smap";
  ASSERT_TRUE(map.Save(path, camera).ok());
  Map target;
  Camera other = camera;
  other.fx += 1.0;
  Status s = target.Load(path, other);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("camera"), std::string::npos) << s.message();

  // Truncated file.
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
  }
  s = target.Load(path, camera);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("truncated"), std::string::npos) << s.message();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << "not a map at all";
  }
  s = target.Load(path, camera);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not a Mesh2SLAM map"), std::string::npos) << s.message();
  EXPECT_FALSE(target.Load(path + ".missing", camera).ok());
  target.Read([](const MapData& m) { EXPECT_TRUE(m.empty()); });  // untouched on failure
  std::remove(path.c_str());
}

template <typename T>
void Append(std::string* bytes, const T& value) {
  bytes->append(reinterpret_cast<const char*>(&value), sizeof(T));
}

// Populate()'s map written in version 1 of the format (no point uncertainty), by hand.
std::string VersionOneFile(const Camera& camera) {
  Map map;
  Populate(&map);
  std::string bytes = "M2SMAP01";
  Append(&bytes, uint32_t{1});
  Append(&bytes, int32_t{camera.width});
  Append(&bytes, int32_t{camera.height});
  for (double v : {camera.fx, camera.fy, camera.cx, camera.cy}) Append(&bytes, v);
  map.Read([&](const MapData& m) {
    Append(&bytes, uint32_t{3});  // next keyframe id
    Append(&bytes, uint64_t{m.keyframes().size()});
    for (const auto& [id, kf] : m.keyframes()) {
      Append(&bytes, uint32_t{id});
      Append(&bytes, int64_t{kf.seq});
      Append(&bytes, kf.timestamp);
      const Eigen::Quaterniond& q = kf.world_from_camera.rotation();
      const Eigen::Vector3d& t = kf.world_from_camera.translation();
      for (double v : {q.x(), q.y(), q.z(), q.w(), t.x(), t.y(), t.z()}) Append(&bytes, v);
      Append(&bytes, uint64_t{kf.ids.size()});
      for (size_t i = 0; i < kf.ids.size(); ++i) {
        Append(&bytes, uint32_t{kf.ids[i]});
        Append(&bytes, kf.uvs[i].x());
        Append(&bytes, kf.uvs[i].y());
      }
    }
    Append(&bytes, uint64_t{m.points().size()});
    for (VertexId id = 0; id < m.points().size(); ++id) {
      const MapPoint& p = *m.point(id);
      Append(&bytes, uint32_t{id});
      for (int i = 0; i < 3; ++i) Append(&bytes, p.position[i]);
      Append(&bytes, uint32_t{p.reference_keyframe});
      Append(&bytes, uint64_t{p.observers.size()});
      for (const KeyframeId o : p.observers) Append(&bytes, uint32_t{o});
    }
  });
  Append(&bytes, uint64_t{0});  // links
  bytes += "M2SEND01";
  return bytes;
}

TEST(MapIo, PointUncertaintyIsSavedAndVersionOneFilesLoadEveryPointAsShown) {
  const Camera camera;
  Map map;
  Populate(&map);
  map.Write([](MapData& m) {
    for (VertexId v = 0; v < 15; ++v) {
      const bool hidden = v == 3 || v == 11;
      m.SetPointUncertainty(v, hidden ? 0.25 : 0.001 * v, !hidden);
    }
  });
  const std::string path = ::testing::TempDir() + "/m2s_map_uncertainty.m2smap";
  ASSERT_TRUE(map.Save(path, camera).ok());
  Map loaded;
  ASSERT_TRUE(loaded.Load(path, camera).ok());
  std::remove(path.c_str());
  loaded.Read([](const MapData& m) {
    for (VertexId v = 0; v < 15; ++v) {
      const bool hidden = v == 3 || v == 11;
      EXPECT_EQ(m.point(v)->uncertainty, hidden ? 0.25 : 0.001 * v) << v;
      EXPECT_EQ(m.point(v)->constrained, !hidden) << v;
    }
  });
  EXPECT_EQ(loaded.FullDelta().point_ids, map.FullDelta().point_ids);
  EXPECT_EQ(loaded.FullDelta().point_ids.size(), 13u);

  const std::string old = VersionOneFile(camera);
  Map from_old;
  const Status s = from_old.LoadFromBytes(old.data(), old.size(), camera);
  ASSERT_TRUE(s.ok()) << s.message();
  from_old.Read([](const MapData& m) {
    ASSERT_EQ(m.points().size(), 15u);
    EXPECT_EQ(m.point(3)->observers, (std::vector<KeyframeId>{0, 1, 2}));
    for (const auto& [id, p] : m.points()) {
      EXPECT_LT(p.uncertainty, 0.0) << id;  // unknown
      EXPECT_TRUE(p.constrained) << id;
    }
  });
  EXPECT_EQ(from_old.FullDelta().point_ids.size(), 15u);

  // A later version is refused by name.
  std::string future = old;
  const uint32_t version = 3;
  std::memcpy(future.data() + 8, &version, sizeof(version));
  const Status refused = from_old.LoadFromBytes(future.data(), future.size(), camera);
  EXPECT_EQ(refused.message(), "bad map file: unsupported version 3 (expected 1 to 2)");
}

// The 148-byte file of the security review: a header for `camera`, a keyframe count, then one
// keyframe (id 0, an identity pose) whose feature count is `feature_count`, and nothing else.
std::string HugeCountFile(const Camera& camera, uint64_t keyframe_count, uint64_t feature_count) {
  std::string bytes = "M2SMAP01";
  Append(&bytes, uint32_t{1});
  Append(&bytes, int32_t{camera.width});
  Append(&bytes, int32_t{camera.height});
  for (double v : {camera.fx, camera.fy, camera.cx, camera.cy}) Append(&bytes, v);
  Append(&bytes, uint32_t{1});  // next keyframe id
  Append(&bytes, keyframe_count);
  Append(&bytes, uint32_t{0});                                             // keyframe id
  Append(&bytes, int64_t{0});                                              // seq
  Append(&bytes, 0.0);                                                     // timestamp
  for (double v : {0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0}) Append(&bytes, v);  // qx qy qz qw t
  Append(&bytes, feature_count);
  return bytes;
}

// A map loaded from Populate()'s file, and what to compare it against after a failed load.
struct LoadedMap {
  Map map;
  uint64_t revision = 0;
  MapDelta full;
};

void LoadPopulated(const Camera& camera, LoadedMap* loaded) {
  const std::string bytes = PopulatedMapFile(camera);
  ASSERT_TRUE(loaded->map.LoadFromBytes(bytes.data(), bytes.size(), camera).ok());
  loaded->revision = loaded->map.revision();
  loaded->full = loaded->map.FullDelta();
}

void ExpectUntouched(const LoadedMap& loaded) {
  EXPECT_EQ(loaded.map.revision(), loaded.revision);
  const MapDelta full = loaded.map.FullDelta();
  EXPECT_EQ(full.point_ids, loaded.full.point_ids);
  EXPECT_EQ(full.point_positions, loaded.full.point_positions);
  EXPECT_EQ(full.keyframes.size(), loaded.full.keyframes.size());
}

TEST(MapIo, CountOf2To28FailsFastWithAClearErrorAndLeavesTheMapUntouched) {
  const Camera camera;
  LoadedMap loaded;
  LoadPopulated(camera, &loaded);
  const uint64_t huge = uint64_t{1} << 28;
  const std::string both_huge = HugeCountFile(camera, huge, huge);
  ASSERT_EQ(both_huge.size(), 148u);
  const std::string path = ::testing::TempDir() + "/m2s_map_huge_count.m2smap";
  WriteFileBytes(path, both_huge);
  Status s = loaded.map.Load(path, camera);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), "bad map file " + path +
                             ": truncated or corrupt keyframe count 268435456 (at least 84 "
                             "bytes each, 84 left)");
  ExpectUntouched(loaded);

  // One keyframe whose feature count is 2^28: 5 GiB of features announced, none there.
  const std::string features_huge = HugeCountFile(camera, 1, huge);
  s = loaded.map.LoadFromBytes(features_huge.data(), features_huge.size(), camera);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(),
            "bad map file: truncated or corrupt feature count 268435456 (at least 20 bytes each, "
            "0 left)");
  ExpectUntouched(loaded);
  for (uint64_t count : {~uint64_t{0}, uint64_t{1} << 63, uint64_t{1} << 60}) {
    const std::string bytes = HugeCountFile(camera, count, 0);
    s = loaded.map.LoadFromBytes(bytes.data(), bytes.size(), camera);
    EXPECT_NE(s.message().find("truncated or corrupt keyframe count"), std::string::npos)
        << s.message();
  }
  ExpectUntouched(loaded);
  std::remove(path.c_str());
}

TEST(MapIo, TruncationAtEveryByteFailsCleanlyAndTheWholeFileLoads) {
  const Camera camera;
  LoadedMap loaded;
  LoadPopulated(camera, &loaded);
  const std::string bytes = PopulatedMapFile(camera);
  for (size_t n = 0; n < bytes.size(); ++n) {
    const Status s = loaded.map.LoadFromBytes(bytes.data(), n, camera);
    ASSERT_FALSE(s.ok()) << n;
    EXPECT_EQ(s.message().rfind("bad map file: ", 0), 0u) << s.message();
  }
  ExpectUntouched(loaded);
  std::string longer = bytes + "x";
  EXPECT_NE(loaded.map.LoadFromBytes(longer.data(), longer.size(), camera)
                .message()
                .find("1 bytes after the end marker"),
            std::string::npos);
  ExpectUntouched(loaded);
  Map fresh;
  ASSERT_TRUE(fresh.LoadFromBytes(bytes.data(), bytes.size(), camera).ok());
  const MapDelta full = fresh.FullDelta();
  EXPECT_EQ(full.point_ids, loaded.full.point_ids);
  EXPECT_EQ(full.keyframes.size(), 3u);
}

TEST(MapIo, NonFiniteValuesAreRejected) {
  const Camera camera;
  std::string bytes = PopulatedMapFile(camera);
  // The first feature's u of the first keyframe: header, keyframe fields, feature id.
  const size_t u_at = 64 + 4 + 8 + 8 + 56 + 8 + 4;
  const double nan = std::nan("");
  std::memcpy(&bytes[u_at], &nan, sizeof(nan));
  Map map;
  const Status s = map.LoadFromBytes(bytes.data(), bytes.size(), camera);
  EXPECT_EQ(s.message(), "bad map file: non-finite keyframe feature");
  Camera nan_camera = camera;
  nan_camera.fx = nan;
  const std::string nan_file = PopulatedMapFile(nan_camera);
  EXPECT_NE(map.LoadFromBytes(nan_file.data(), nan_file.size(), nan_camera)
                .message()
                .find("camera differs"),
            std::string::npos);
}

}  // namespace
}  // namespace m2s::slam
