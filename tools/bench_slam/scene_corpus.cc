#include "scene_corpus.h"

#include <cmath>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>

#include <nlohmann/json.hpp>

#include "m2s/common/motion.h"

namespace m2s::bench {
namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

// Appends `positions` (already in world coordinates) and their triangles to `scene`.
void Append(const std::vector<Eigen::Vector3f>& positions, const std::vector<uint32_t>& triangles,
            Scene* scene) {
  const auto offset = static_cast<uint32_t>(scene->positions.size());
  scene->positions.insert(scene->positions.end(), positions.begin(), positions.end());
  for (uint32_t index : triangles) scene->triangles.push_back(offset + index);
}

// A grid of n x n quads on a rectangle spanned by `corner`, `corner + a`, `corner + b`.
void AppendGrid(const Eigen::Vector3d& corner, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                int n, std::vector<Eigen::Vector3f>* positions, std::vector<uint32_t>* triangles) {
  const auto base = static_cast<uint32_t>(positions->size());
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      positions->push_back(
          (corner + a * (static_cast<double>(i) / n) + b * (static_cast<double>(j) / n))
              .cast<float>());
    }
  }
  const auto row = static_cast<uint32_t>(n + 1);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const uint32_t v = base + static_cast<uint32_t>(j) * row + static_cast<uint32_t>(i);
      triangles->insert(triangles->end(), {v, v + 1, v + row + 1, v, v + row + 1, v + row});
    }
  }
}

// Merges exactly equal positions (shared box corners) so every distinct point has one id.
Scene MergeEqual(const std::vector<Eigen::Vector3f>& positions,
                 const std::vector<uint32_t>& triangles) {
  Scene out;
  std::vector<uint32_t> remap(positions.size());
  for (size_t i = 0; i < positions.size(); ++i) {
    size_t found = out.positions.size();
    for (size_t k = 0; k < out.positions.size(); ++k) {
      if (out.positions[k] == positions[i]) {
        found = k;
        break;
      }
    }
    if (found == out.positions.size()) out.positions.push_back(positions[i]);
    remap[i] = static_cast<uint32_t>(found);
  }
  for (uint32_t index : triangles) out.triangles.push_back(remap[index]);
  return out;
}

// A closed box (6 quads) centred on the origin in x and y, standing on z = 0.
Scene MakeBox(const Eigen::Vector3d& size, int divisions) {
  std::vector<Eigen::Vector3f> positions;
  std::vector<uint32_t> triangles;
  const Eigen::Vector3d lo(-0.5 * size.x(), -0.5 * size.y(), 0.0);
  const Eigen::Vector3d ex(size.x(), 0, 0), ey(0, size.y(), 0), ez(0, 0, size.z());
  AppendGrid(lo, ey, ex, divisions, &positions, &triangles);       // bottom
  AppendGrid(lo + ez, ex, ey, divisions, &positions, &triangles);  // top
  AppendGrid(lo, ex, ez, divisions, &positions, &triangles);       // -y side
  AppendGrid(lo + ey, ez, ex, divisions, &positions, &triangles);  // +y side
  AppendGrid(lo, ez, ey, divisions, &positions, &triangles);       // -x side
  AppendGrid(lo + ex, ey, ez, divisions, &positions, &triangles);  // +x side
  return MergeEqual(positions, triangles);
}

Expected<Scene> LoadProp(const PropSpec& prop, const std::string& mesh_root) {
  if (prop.mesh.empty()) {
    if (!(prop.box_size.array() > 0.0).all() || !prop.box_size.allFinite()) {
      return Status::Error("prop '" + prop.name + "': box size must be positive");
    }
    return MakeBox(prop.box_size, 1);
  }
  std::filesystem::path path(prop.mesh);
  if (path.is_relative() && !mesh_root.empty()) path = std::filesystem::path(mesh_root) / path;
  Expected<Scene> scene = LoadScene(path.string());
  if (!scene) return Status::Error("prop '" + prop.name + "': " + scene.error());
  return scene;
}

}  // namespace

Expected<ComposedScene> ComposeScene(const SceneSpec& spec, const std::string& mesh_root) {
  if (!(spec.room_size.array() > 0.0).all() || !spec.room_size.allFinite()) {
    return Status::Error("scene '" + spec.name + "': room size must be positive");
  }
  if (spec.wall_divisions < 1) {
    return Status::Error("scene '" + spec.name + "': wall divisions must be at least 1");
  }
  ComposedScene out;
  out.scene.name = spec.name;
  const Eigen::Vector3d half(0.5 * spec.room_size.x(), 0.5 * spec.room_size.y(), 0.0);
  out.layout.room = Eigen::AlignedBox3d(-half, half + Eigen::Vector3d(0, 0, spec.room_size.z()));
  Scene room = MakeBox(spec.room_size, spec.wall_divisions);
  out.parts.push_back({"room", 0, static_cast<uint32_t>(room.num_vertices())});
  Append(room.positions, room.triangles, &out.scene);

  for (const PropSpec& prop : spec.props) {
    Expected<Scene> loaded = LoadProp(prop, mesh_root);
    if (!loaded) return Status::Error("scene '" + spec.name + "': " + loaded.error());
    // Up axis and turn first, then the fit: the size is measured on the turned mesh.
    Eigen::Matrix3d rotation =
        Eigen::AngleAxisd(prop.yaw_deg * kDegToRad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    if (prop.y_up) {
      rotation =
          rotation * Eigen::AngleAxisd(0.5 * 3.14159265358979323846, Eigen::Vector3d::UnitX())
                         .toRotationMatrix();
    }
    Eigen::AlignedBox3d box;
    for (const Eigen::Vector3f& p : loaded->positions) box.extend(rotation * p.cast<double>());
    const double extent = box.sizes().maxCoeff();
    double scale = 1.0;
    if (prop.size_m > 0.0) {
      if (!(extent > 0.0)) return Status::Error("prop '" + prop.name + "': mesh has no extent");
      scale = prop.size_m / extent;
    }
    const Eigen::Vector3d bottom_centre(box.center().x(), box.center().y(), box.min().z());
    const Eigen::Vector3d translation = prop.position - scale * bottom_centre;
    std::vector<Eigen::Vector3f> positions;
    positions.reserve(loaded->positions.size());
    Eigen::AlignedBox3d placed;
    for (const Eigen::Vector3f& p : loaded->positions) {
      const Eigen::Vector3d world = scale * (rotation * p.cast<double>()) + translation;
      placed.extend(world);
      positions.push_back(world.cast<float>());
    }
    out.parts.push_back({prop.name, static_cast<uint32_t>(out.scene.num_vertices()),
                         static_cast<uint32_t>(positions.size())});
    Append(positions, loaded->triangles, &out.scene);
    if (prop.obstacle) {
      out.layout.obstacles.emplace_back(placed.min().head<2>(), placed.max().head<2>());
      out.obstacles.push_back(placed);
    }
    if (prop.target) out.targets.push_back(placed.center());
  }
  return out;
}

Expected<std::vector<SceneSpec>> ReadSceneManifest(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::Error("cannot read scene manifest " + path);
  auto vec3 = [](const nlohmann::json& j) {
    if (!j.is_array() || j.size() != 3) throw std::runtime_error("expected [x, y, z]");
    return Eigen::Vector3d(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
  };
  std::vector<SceneSpec> specs;
  try {
    const nlohmann::json root = nlohmann::json::parse(in);
    for (const nlohmann::json& s : root.at("scenes")) {
      SceneSpec spec;
      spec.name = s.at("name").get<std::string>();
      if (s.contains("room")) {
        const nlohmann::json& room = s.at("room");
        if (room.contains("size")) spec.room_size = vec3(room.at("size"));
        spec.wall_divisions = room.value("divisions", 1);
      }
      for (const nlohmann::json& p : s.value("props", nlohmann::json::array())) {
        PropSpec prop;
        prop.name = p.value("name", std::string());
        if (p.contains("mesh")) {
          prop.mesh = p.at("mesh").get<std::string>();
        } else {
          prop.box_size = vec3(p.at("box"));
        }
        if (prop.name.empty()) prop.name = prop.mesh.empty() ? "box" : prop.mesh;
        prop.size_m = p.value("size", 0.0);
        prop.y_up = p.value("up", std::string("z")) == "y";
        if (p.contains("position")) prop.position = vec3(p.at("position"));
        prop.yaw_deg = p.value("yaw_deg", 0.0);
        prop.obstacle = p.value("obstacle", true);
        prop.target = p.value("target", false);
        spec.props.push_back(std::move(prop));
      }
      specs.push_back(std::move(spec));
    }
  } catch (const std::exception& e) {
    return Status::Error("scene manifest " + path + ": " + e.what());
  }
  return specs;
}

const std::vector<std::string>& MotionKinds() {
  static const std::vector<std::string> kinds = {"head", "handheld", "drone"};
  return kinds;
}

Expected<Trajectory> MakeMotion(const std::string& kind, const ComposedScene& scene, uint64_t seed,
                                double duration_s) {
  const RoomLayout& layout = scene.layout;
  if (kind == "head") {
    HeadMotionOptions o;
    o.room = Eigen::AlignedBox2d(layout.room.min().head<2>(), layout.room.max().head<2>());
    o.obstacles = layout.obstacles;
    o.seed = seed;
    o.duration_s = duration_s;
    return GenerateHeadMotion(o);
  }
  if (kind == "handheld") {
    HandheldMotionOptions o;
    o.room = layout.room;
    o.obstacles = layout.obstacles;
    o.targets = scene.targets;
    o.seed = seed;
    o.duration_s = duration_s;
    return GenerateHandheldMotion(o);
  }
  if (kind == "drone") {
    DroneMotionOptions o;
    o.room = layout.room;
    for (const Eigen::AlignedBox3d& box : scene.obstacles) {
      if (box.max().z() > layout.room.min().z() + o.min_altitude_m - o.obstacle_clearance_m) {
        o.obstacles.emplace_back(box.min().head<2>(), box.max().head<2>());
      }
    }
    o.seed = seed;
    o.duration_s = duration_s;
    return GenerateDroneMotion(o);
  }
  return Status::Error("unknown motion '" + kind + "' (head, handheld, drone)");
}

}  // namespace m2s::bench
