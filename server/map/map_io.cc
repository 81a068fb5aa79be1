// Map file format (little-endian, version 1):
//   magic "M2SMAP01", u32 version, camera (i32 width, height; f64 fx fy cx cy),
//   u32 next keyframe id,
//   u64 #keyframes, each: u32 id, i64 seq, f64 timestamp, f64[7] pose (qx qy qz qw tx ty tz),
//                   u64 #features, each: u32 vertex id, f64 u, f64 v
//   u64 #points, each: u32 id, f64[3] position, u32 reference keyframe,
//                u64 #observers, each: u32 keyframe id
//   u64 #links, each: u32 id, u32 parent, f64[7] parent_from_camera
//   magic "M2SEND01"
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <type_traits>

#include "map/map.h"

namespace m2s::slam {
namespace {

constexpr char kMagic[8] = {'M', '2', 'S', 'M', 'A', 'P', '0', '1'};
constexpr char kEndMagic[8] = {'M', '2', 'S', 'E', 'N', 'D', '0', '1'};
constexpr uint32_t kVersion = 1;
// Sanity bounds: a corrupt count must not make us allocate without limit.
constexpr uint64_t kMaxCount = uint64_t{1} << 28;

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

class Reader {
 public:
  explicit Reader(std::ifstream* in) : in_(in) {}
  template <typename T>
  bool Get(T* v) {
    static_assert(std::is_trivially_copyable_v<T>);
    in_->read(reinterpret_cast<char*>(v), sizeof(T));
    return static_cast<bool>(*in_);
  }
  bool GetCount(uint64_t* n) { return Get(n) && *n <= kMaxCount; }
  bool GetPose(Pose3* p) {
    double v[7];
    for (double& x : v) {
      if (!Get(&x) || !std::isfinite(x)) return false;
    }
    const Eigen::Quaterniond q(v[3], v[0], v[1], v[2]);
    if (q.norm() < 1e-6) return false;
    *p = Pose3(q, Eigen::Vector3d(v[4], v[5], v[6]));
    return true;
  }

 private:
  std::ifstream* in_;
};

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

Status Map::Load(const std::string& path, const Camera& camera) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error("cannot open map file: " + path);
  auto bad = [&path](const std::string& what) {
    return Status::Error("bad map file " + path + ": " + what);
  };
  char magic[8];
  in.read(magic, sizeof(magic));
  if (!in || std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) return bad("not a Mesh2SLAM map");
  Reader r(&in);
  uint32_t version = 0;
  if (!r.Get(&version)) return bad("truncated header");
  if (version != kVersion) {
    return bad("unsupported version " + std::to_string(version) + " (expected " +
               std::to_string(kVersion) + ")");
  }
  int32_t width = 0, height = 0;
  double k[4];
  if (!r.Get(&width) || !r.Get(&height) || !r.Get(&k[0]) || !r.Get(&k[1]) || !r.Get(&k[2]) ||
      !r.Get(&k[3])) {
    return bad("truncated camera");
  }
  const double tol = 1e-9;
  if (width != camera.width || height != camera.height || std::abs(k[0] - camera.fx) > tol ||
      std::abs(k[1] - camera.fy) > tol || std::abs(k[2] - camera.cx) > tol ||
      std::abs(k[3] - camera.cy) > tol) {
    return bad("its camera differs from the system's camera");
  }
  uint32_t next_id = 0;
  if (!r.Get(&next_id)) return bad("truncated header");

  MapData data;
  uint64_t n = 0;
  if (!r.GetCount(&n)) return bad("truncated or corrupt keyframe count");
  for (uint64_t i = 0; i < n; ++i) {
    Keyframe kf;
    uint32_t id = 0;
    uint64_t nf = 0;
    if (!r.Get(&id) || !r.Get(&kf.seq) || !r.Get(&kf.timestamp) ||
        !r.GetPose(&kf.world_from_camera) || !r.GetCount(&nf)) {
      return bad("truncated keyframe");
    }
    kf.id = id;
    if (id >= next_id || data.keyframe(id) != nullptr) return bad("inconsistent keyframe ids");
    kf.ids.resize(nf);
    kf.uvs.resize(nf);
    for (uint64_t f = 0; f < nf; ++f) {
      uint32_t vid = 0;
      double u = 0, v = 0;
      if (!r.Get(&vid) || !r.Get(&u) || !r.Get(&v)) return bad("truncated keyframe features");
      if (f > 0 && vid <= kf.ids[f - 1]) return bad("keyframe features not sorted");
      kf.ids[f] = vid;
      kf.uvs[f] = Eigen::Vector2d(u, v);
    }
    data.AddKeyframe(std::move(kf));
  }
  if (!r.GetCount(&n)) return bad("truncated or corrupt point count");
  for (uint64_t i = 0; i < n; ++i) {
    uint32_t id = 0, ref = 0;
    Eigen::Vector3d pos;
    uint64_t no = 0;
    if (!r.Get(&id) || !r.Get(&pos[0]) || !r.Get(&pos[1]) || !r.Get(&pos[2]) || !r.Get(&ref) ||
        !r.GetCount(&no)) {
      return bad("truncated point");
    }
    if (!pos.allFinite() || data.point(id) != nullptr)
      return bad("invalid point " + std::to_string(id));
    data.AddPoint(id, pos, ref);
    for (uint64_t o = 0; o < no; ++o) {
      uint32_t kf = 0;
      if (!r.Get(&kf)) return bad("truncated observers");
      if (!data.AddObservation(id, kf)) return bad("observation of a missing keyframe feature");
    }
  }
  if (!r.GetCount(&n)) return bad("truncated link count");
  for (uint64_t i = 0; i < n; ++i) {
    uint32_t id = 0, parent = 0;
    KeyframeLink link;
    if (!r.Get(&id) || !r.Get(&parent) || !r.GetPose(&link.parent_from_camera)) {
      return bad("truncated links");
    }
    link.parent = parent;
    data.SetLink(id, link);
  }
  in.read(magic, sizeof(magic));
  if (!in || std::memcmp(magic, kEndMagic, sizeof(kEndMagic)) != 0)
    return bad("missing end marker");

  std::unique_lock<std::shared_mutex> lock(mutex_);
  data.ClearChanges();
  data_ = std::move(data);
  ++revision_;
  next_delta_full_ = true;
  next_keyframe_id_ = std::max(next_keyframe_id_, static_cast<KeyframeId>(next_id));
  return Status::Ok();
}

}  // namespace m2s::slam
