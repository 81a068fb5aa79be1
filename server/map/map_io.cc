// Map file format (little-endian, version 2):
//   magic "M2SMAP01", u32 version, camera (i32 width, height; f64 fx fy cx cy),
//   u32 next keyframe id,
//   u64 #keyframes, each: u32 id, i64 seq, f64 timestamp, f64[7] pose (qx qy qz qw tx ty tz),
//                   u64 #features, each: u32 vertex id, f64 u, f64 v
//   u64 #points, each: u32 id, f64[3] position, u32 reference keyframe,
//                f64 relative uncertainty, u8 constrained (0 or 1),
//                u64 #observers, each: u32 keyframe id
//   Version 1 (read too) has no uncertainty and no flag: its points load as unknown and
//   constrained, the way they were shown when it was written, until mapping re-evaluates them.
//   u64 #links, each: u32 id, u32 parent, f64[7] parent_from_camera
//   magic "M2SEND01"
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "map/map.h"

namespace m2s::slam {
namespace {

constexpr char kMagic[8] = {'M', '2', 'S', 'M', 'A', 'P', '0', '1'};
constexpr char kEndMagic[8] = {'M', '2', 'S', 'E', 'N', 'D', '0', '1'};
constexpr uint32_t kVersion = 2;
constexpr uint32_t kOldestReadableVersion = 1;
// The fewest bytes each counted element takes in the file: a count is checked against them
// and the bytes that remain before anything is allocated for it.
constexpr size_t kPoseFileBytes = 7 * 8;
constexpr size_t kMinKeyframeBytes = 4 + 8 + 8 + kPoseFileBytes + 8;
constexpr size_t kFeatureBytes = 4 + 8 + 8;
constexpr size_t kMinPointBytes = 4 + 3 * 8 + 4 + 8;  // version 1; version 2 adds 8 + 1
constexpr size_t kObserverBytes = 4;
constexpr size_t kLinkBytes = 4 + 4 + kPoseFileBytes;

class Writer {
 public:
  explicit Writer(std::ofstream* out) : out_(out) {}
  template <typename T>
  void Put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    out_->write(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void PutPose(const Pose3& p) {
    const auto& q = p.rotation();
    for (double v : {q.x(), q.y(), q.z(), q.w()}) Put(v);
    for (int i = 0; i < 3; ++i) Put(p.translation()[i]);
  }

 private:
  std::ofstream* out_;
};

// Reads the file's fields from a byte range; every read is checked against what remains.
class Reader {
 public:
  Reader(const void* data, size_t size) : data_(static_cast<const uint8_t*>(data)), size_(size) {}
  template <typename T>
  bool Get(T* v) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (sizeof(T) > remaining()) return false;
    std::memcpy(v, data_ + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  // A count of elements taking at least `min_element_bytes` each; fails (saying why in `error`)
  // when it is missing or more than the bytes that remain can hold.
  bool GetCount(const char* what, size_t min_element_bytes, uint64_t* n, std::string* error) {
    if (!Get(n)) {
      *error = std::string("truncated ") + what + " count";
      return false;
    }
    if (*n > remaining() / min_element_bytes) {
      *error = std::string("truncated or corrupt ") + what + " count " + std::to_string(*n) +
               " (at least " + std::to_string(min_element_bytes) + " bytes each, " +
               std::to_string(remaining()) + " left)";
      return false;
    }
    return true;
  }
  bool GetPose(Pose3* p) {
    double v[7];
    for (double& x : v) {
      if (!Get(&x) || !std::isfinite(x)) return false;
    }
    const Eigen::Quaterniond q(v[3], v[0], v[1], v[2]);
    const double norm = q.norm();
    if (!(norm >= 1e-6) || !std::isfinite(norm)) return false;
    *p = Pose3(q, Eigen::Vector3d(v[4], v[5], v[6]));
    return true;
  }
  bool GetMagic(const char (&magic)[8]) {
    char read[8];
    return Get(&read) && std::memcmp(read, magic, sizeof(read)) == 0;
  }
  size_t remaining() const { return size_ - pos_; }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

// The content of a map file, checked; `error` says what is wrong when it is not empty.
struct ParsedMap {
  MapData data;
  KeyframeId next_id = 0;
  std::string error;
};

ParsedMap Fail(std::string why) {
  ParsedMap parsed;
  parsed.error = std::move(why);
  return parsed;
}

ParsedMap ParseMapFile(const void* bytes, size_t size, const Camera& camera) {
  Reader r(bytes, size);
  if (!r.GetMagic(kMagic)) return Fail("not a Mesh2SLAM map");
  uint32_t version = 0;
  if (!r.Get(&version)) return Fail("truncated header");
  if (version < kOldestReadableVersion || version > kVersion) {
    return Fail("unsupported version " + std::to_string(version) + " (expected " +
                std::to_string(kOldestReadableVersion) + " to " + std::to_string(kVersion) + ")");
  }
  int32_t width = 0, height = 0;
  double k[4];
  if (!r.Get(&width) || !r.Get(&height) || !r.Get(&k[0]) || !r.Get(&k[1]) || !r.Get(&k[2]) ||
      !r.Get(&k[3])) {
    return Fail("truncated camera");
  }
  const double tol = 1e-9;
  if (width != camera.width || height != camera.height || !(std::abs(k[0] - camera.fx) <= tol) ||
      !(std::abs(k[1] - camera.fy) <= tol) || !(std::abs(k[2] - camera.cx) <= tol) ||
      !(std::abs(k[3] - camera.cy) <= tol)) {
    return Fail("its camera differs from the system's camera");
  }
  ParsedMap parsed;
  MapData& data = parsed.data;
  uint32_t next_id = 0;
  if (!r.Get(&next_id)) return Fail("truncated header");
  parsed.next_id = next_id;

  uint64_t n = 0;
  std::string why;
  if (!r.GetCount("keyframe", kMinKeyframeBytes, &n, &why)) return Fail(why);
  for (uint64_t i = 0; i < n; ++i) {
    Keyframe kf;
    uint32_t id = 0;
    uint64_t nf = 0;
    if (!r.Get(&id) || !r.Get(&kf.seq) || !r.Get(&kf.timestamp) ||
        !r.GetPose(&kf.world_from_camera)) {
      return Fail("truncated keyframe or invalid keyframe pose");
    }
    if (!r.GetCount("feature", kFeatureBytes, &nf, &why)) return Fail(why);
    if (!std::isfinite(kf.timestamp)) {
      return Fail("keyframe " + std::to_string(id) + " has a non-finite time");
    }
    kf.id = id;
    if (id >= next_id || data.keyframe(id) != nullptr) return Fail("inconsistent keyframe ids");
    kf.ids.resize(nf);
    kf.uvs.resize(nf);
    for (uint64_t f = 0; f < nf; ++f) {
      uint32_t vid = 0;
      double u = 0, v = 0;
      if (!r.Get(&vid) || !r.Get(&u) || !r.Get(&v)) return Fail("truncated keyframe features");
      if (f > 0 && vid <= kf.ids[f - 1]) return Fail("keyframe features not sorted");
      if (!std::isfinite(u) || !std::isfinite(v)) return Fail("non-finite keyframe feature");
      kf.ids[f] = vid;
      kf.uvs[f] = Eigen::Vector2d(u, v);
    }
    data.AddKeyframe(std::move(kf));
  }
  if (!r.GetCount("point", kMinPointBytes, &n, &why)) return Fail(why);
  for (uint64_t i = 0; i < n; ++i) {
    uint32_t id = 0, ref = 0;
    Eigen::Vector3d pos;
    uint64_t no = 0;
    if (!r.Get(&id) || !r.Get(&pos[0]) || !r.Get(&pos[1]) || !r.Get(&pos[2]) || !r.Get(&ref)) {
      return Fail("truncated point");
    }
    double uncertainty = -1.0;
    uint8_t constrained = 1;
    if (version >= 2) {
      if (!r.Get(&uncertainty) || !r.Get(&constrained)) return Fail("truncated point");
      if (std::isnan(uncertainty) || constrained > 1) {
        return Fail("invalid uncertainty of point " + std::to_string(id));
      }
    }
    if (!r.GetCount("observer", kObserverBytes, &no, &why)) return Fail(why);
    if (!pos.allFinite() || data.point(id) != nullptr) {
      return Fail("invalid point " + std::to_string(id));
    }
    data.AddPoint(id, pos, ref);
    data.SetPointUncertainty(id, uncertainty, constrained == 1);
    for (uint64_t o = 0; o < no; ++o) {
      uint32_t kf = 0;
      if (!r.Get(&kf)) return Fail("truncated observers");
      if (!data.AddObservation(id, kf)) return Fail("observation of a missing keyframe feature");
    }
  }
  if (!r.GetCount("link", kLinkBytes, &n, &why)) return Fail(why);
  for (uint64_t i = 0; i < n; ++i) {
    uint32_t id = 0, parent = 0;
    KeyframeLink link;
    if (!r.Get(&id) || !r.Get(&parent) || !r.GetPose(&link.parent_from_camera)) {
      return Fail("truncated link or invalid link pose");
    }
    link.parent = parent;
    data.SetLink(id, link);
  }
  if (!r.GetMagic(kEndMagic)) return Fail("missing end marker");
  if (r.remaining() != 0) {
    return Fail(std::to_string(r.remaining()) + " bytes after the end marker");
  }
  data.ClearChanges();
  return parsed;
}

}  // namespace

Status Map::Save(const std::string& path, const Camera& camera) const {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return Status::Error("cannot open map file for writing: " + path);
  std::shared_lock<std::shared_mutex> lock(mutex_);
  Writer w(&out);
  out.write(kMagic, sizeof(kMagic));
  w.Put(kVersion);
  w.Put(static_cast<int32_t>(camera.width));
  w.Put(static_cast<int32_t>(camera.height));
  for (double v : {camera.fx, camera.fy, camera.cx, camera.cy}) w.Put(v);
  KeyframeId next_id = next_keyframe_id_;
  if (!data_.keyframes().empty())
    next_id = std::max(next_id, data_.keyframes().rbegin()->first + 1);
  w.Put(static_cast<uint32_t>(next_id));
  w.Put(static_cast<uint64_t>(data_.keyframes().size()));
  for (const auto& [id, kf] : data_.keyframes()) {
    w.Put(static_cast<uint32_t>(id));
    w.Put(static_cast<int64_t>(kf.seq));
    w.Put(kf.timestamp);
    w.PutPose(kf.world_from_camera);
    w.Put(static_cast<uint64_t>(kf.ids.size()));
    for (size_t i = 0; i < kf.ids.size(); ++i) {
      w.Put(static_cast<uint32_t>(kf.ids[i]));
      w.Put(kf.uvs[i].x());
      w.Put(kf.uvs[i].y());
    }
  }
  std::vector<VertexId> ids;
  for (const auto& [id, p] : data_.points()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  w.Put(static_cast<uint64_t>(ids.size()));
  for (const VertexId id : ids) {
    const MapPoint& p = *data_.point(id);
    w.Put(static_cast<uint32_t>(id));
    for (int i = 0; i < 3; ++i) w.Put(p.position[i]);
    w.Put(static_cast<uint32_t>(p.reference_keyframe));
    w.Put(p.uncertainty);
    w.Put(static_cast<uint8_t>(p.constrained ? 1 : 0));
    w.Put(static_cast<uint64_t>(p.observers.size()));
    for (const KeyframeId kf : p.observers) w.Put(static_cast<uint32_t>(kf));
  }
  w.Put(static_cast<uint64_t>(data_.links().size()));
  std::vector<KeyframeId> link_ids;
  for (const auto& [id, link] : data_.links()) link_ids.push_back(id);
  std::sort(link_ids.begin(), link_ids.end());
  for (const KeyframeId id : link_ids) {
    const KeyframeLink& link = data_.links().at(id);
    w.Put(static_cast<uint32_t>(id));
    w.Put(static_cast<uint32_t>(link.parent));
    w.PutPose(link.parent_from_camera);
  }
  out.write(kEndMagic, sizeof(kEndMagic));
  out.flush();
  if (!out) return Status::Error("failed writing map file: " + path);
  return Status::Ok();
}

Expected<Camera> ReadMapFileCamera(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error("cannot open map file: " + path);
  constexpr size_t kHeader = 8 + 4 + 2 * 4 + 4 * 8;  // magic, version, camera
  std::vector<uint8_t> bytes(kHeader);
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  Reader r(bytes.data(), static_cast<size_t>(in.gcount()));
  uint32_t version = 0;
  if (!r.GetMagic(kMagic)) return Status::Error("bad map file " + path + ": not a Mesh2SLAM map");
  if (!r.Get(&version) || version < kOldestReadableVersion || version > kVersion) {
    return Status::Error("bad map file " + path + ": unsupported version");
  }
  int32_t width = 0, height = 0;
  Camera camera;
  if (!r.Get(&width) || !r.Get(&height) || !r.Get(&camera.fx) || !r.Get(&camera.fy) ||
      !r.Get(&camera.cx) || !r.Get(&camera.cy)) {
    return Status::Error("bad map file " + path + ": truncated camera");
  }
  camera.width = width;
  camera.height = height;
  if (Status valid = camera.Check(); !valid) {
    return valid.Prefixed("bad map file " + path + ": camera: ");
  }
  return camera;
}

Status Map::Load(const std::string& path, const Camera& camera) {
  std::ifstream in(path, std::ios::binary);
  std::error_code ec;
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (!in || ec) return Status::Error("cannot open map file: " + path);
  std::vector<uint8_t> bytes(static_cast<size_t>(size));
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (static_cast<uintmax_t>(in.gcount()) != size) {
    return Status::Error("cannot read map file: " + path);
  }
  ParsedMap parsed = ParseMapFile(bytes.data(), bytes.size(), camera);
  if (!parsed.error.empty()) return Status::Error("bad map file " + path + ": " + parsed.error);
  Install(std::move(parsed.data), parsed.next_id);
  return Status::Ok();
}

Status Map::LoadFromBytes(const void* data, size_t size, const Camera& camera) {
  ParsedMap parsed = ParseMapFile(data, size, camera);
  if (!parsed.error.empty()) return Status::Error("bad map file: " + parsed.error);
  Install(std::move(parsed.data), parsed.next_id);
  return Status::Ok();
}

void Map::Install(MapData data, KeyframeId next_id) {
  std::unique_lock<std::shared_mutex> lock(mutex_);
  data_ = std::move(data);
  ++revision_;
  next_delta_full_ = true;
  next_keyframe_id_ = std::max(next_keyframe_id_, next_id);
}

}  // namespace m2s::slam
