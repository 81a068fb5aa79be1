#include "m2s/common/scene_io.h"

#include <cstdint>
#include <cstdio>
#include <fstream>

namespace m2s {
namespace {

Status CheckScene(const std::string& path, const Scene& scene) {
  if (scene.triangles.size() % 3 != 0) {
    return Status::Error("'" + path + "': triangle index count is not a multiple of 3");
  }
  for (uint32_t index : scene.triangles) {
    if (index >= scene.positions.size()) {
      return Status::Error("'" + path + "': triangle index out of range");
    }
  }
  return Status::Ok();
}

}  // namespace

Status WriteSceneObj(const std::string& path, const Scene& scene) {
  if (Status s = CheckScene(path, scene); !s) return s;
  std::FILE* file = std::fopen(path.c_str(), "w");
  if (file == nullptr) return Status::Error("'" + path + "': cannot open file for writing");
  std::fprintf(file, "# %s: %zu vertices, %zu triangles (Mesh2SLAM)\no %s\n", scene.name.c_str(),
               scene.num_vertices(), scene.num_triangles(),
               scene.name.empty() ? "scene" : scene.name.c_str());
  for (const Eigen::Vector3f& p : scene.positions) {
    std::fprintf(file, "v %.9g %.9g %.9g\n", p.x(), p.y(), p.z());
  }
  for (size_t t = 0; t < scene.triangles.size(); t += 3) {
    std::fprintf(file, "f %u %u %u\n", scene.triangles[t] + 1, scene.triangles[t + 1] + 1,
                 scene.triangles[t + 2] + 1);
  }
  const bool ok = std::ferror(file) == 0;
  if (std::fclose(file) != 0 || !ok) return Status::Error("'" + path + "': write error");
  return Status::Ok();
}

Status WriteScenePly(const std::string& path, const Scene& scene) {
  if (Status s = CheckScene(path, scene); !s) return s;
  std::ofstream out(path, std::ios::binary);
  if (!out) return Status::Error("'" + path + "': cannot open file for writing");
  out << "ply\nformat binary_little_endian 1.0\ncomment " << scene.name << " (Mesh2SLAM)\n"
      << "element vertex " << scene.num_vertices() << "\nproperty float x\nproperty float y\n"
      << "property float z\nelement face " << scene.num_triangles()
      << "\nproperty list uchar int vertex_indices\nend_header\n";
  auto put = [&out](auto value) {  // little-endian on the platforms we build for
    out.write(reinterpret_cast<const char*>(&value), sizeof(value));
  };
  static_assert(sizeof(float) == 4);
  for (const Eigen::Vector3f& p : scene.positions) {
    put(p.x());
    put(p.y());
    put(p.z());
  }
  for (size_t t = 0; t < scene.triangles.size(); t += 3) {
    put(static_cast<uint8_t>(3));
    for (int k = 0; k < 3; ++k) put(static_cast<int32_t>(scene.triangles[t + k]));
  }
  out.flush();
  if (!out) return Status::Error("'" + path + "': write error");
  return Status::Ok();
}

}  // namespace m2s
