#include "textured_scene.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <vector>

#include <Eigen/Core>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "m2s/common/scene.h"

namespace m2s::testing {
namespace {

namespace fs = std::filesystem;

// Heights of the boxes put on the first four footprints of DefaultRoomLayout().obstacles
// (table and chairs, sofa, shelves, sideboard).
constexpr double kBoxHeights[] = {0.75, 0.8, 1.8, 0.9};
constexpr double kBlobCoverage = 2.0;  // blob area drawn / texture area
constexpr double kBlurSigmaPx = 1.0;

// One material: a texture of its own, and the OBJ faces that use it.
struct Material {
  std::string name;
  int width_px = 0, height_px = 0;
  std::vector<std::string> faces;  // "f a/b c/d e/f" lines
};

// OBJ text under construction: positions and texture coordinates (1-based indices).
class ObjWriter {
 public:
  // A rectangle origin + s u + t v (s, t in [0, 1]) tessellated into cells of about cell_m,
  // facing u x v (counter-clockwise seen from that side), mapped to the texture rectangle
  // [uv0, uv1].
  void AddFace(Material* material, const Eigen::Vector3d& origin, const Eigen::Vector3d& u,
               const Eigen::Vector3d& v, Eigen::Vector2d uv0, Eigen::Vector2d uv1, double cell_m) {
    const int nu = std::max(1, static_cast<int>(std::ceil(u.norm() / cell_m)));
    const int nv = std::max(1, static_cast<int>(std::ceil(v.norm() / cell_m)));
    const int first = num_vertices_ + 1;
    for (int j = 0; j <= nv; ++j) {
      for (int i = 0; i <= nu; ++i) {
        const double s = static_cast<double>(i) / nu, t = static_cast<double>(j) / nv;
        const Eigen::Vector3d p = origin + s * u + t * v;
        const Eigen::Vector2d uv = uv0 + Eigen::Vector2d(s, t).cwiseProduct(uv1 - uv0);
        positions_ << "v " << p.x() << " " << p.y() << " " << p.z() << "\n";
        uvs_ << "vt " << uv.x() << " " << uv.y() << "\n";
        ++num_vertices_;
      }
    }
    const auto index = [&](int i, int j) { return first + j * (nu + 1) + i; };
    const auto corner = [](int k) { return std::to_string(k) + "/" + std::to_string(k); };
    for (int j = 0; j < nv; ++j) {
      for (int i = 0; i < nu; ++i) {
        const int a = index(i, j), b = index(i + 1, j), c = index(i + 1, j + 1),
                  d = index(i, j + 1);
        material->faces.push_back("f " + corner(a) + " " + corner(b) + " " + corner(c));
        material->faces.push_back("f " + corner(a) + " " + corner(c) + " " + corner(d));
      }
    }
  }
  std::string Text(const std::vector<Material>& materials, const std::string& mtl_name) const {
    std::ostringstream out;
    out << "# Textured test room\nmtllib " << mtl_name << "\n" << positions_.str() << uvs_.str();
    for (const Material& m : materials) {
      out << "o " << m.name << "\nusemtl " << m.name << "\n";
      for (const std::string& f : m.faces) out << f << "\n";
    }
    return out.str();
  }

 private:
  std::ostringstream positions_, uvs_;
  int num_vertices_ = 0;
};

int TexturePx(double extent_m, const TexturedRoomOptions& options) {
  return std::clamp(static_cast<int>(std::ceil(extent_m * options.texels_per_m)), 64,
                    options.max_texture_px);
}

Status WriteTextFile(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  out.close();
  if (!out) return Status::Error("cannot write " + path.string());
  return Status::Ok();
}

}  // namespace

cv::Mat MakeBlobTexture(int width, int height, uint64_t seed) {
  cv::RNG rng(seed);
  const auto colour = [&rng] {
    return cv::Scalar(rng.uniform(0, 256), rng.uniform(0, 256), rng.uniform(0, 256));
  };
  cv::Mat texture(height, width, CV_8UC3, colour());
  constexpr int kMinRadius = 3, kMaxRadius = 24;
  const double mean_area = 3.14159 * 0.25 * (kMinRadius + kMaxRadius) * (kMinRadius + kMaxRadius);
  const int blobs = static_cast<int>(kBlobCoverage * width * height / mean_area);
  for (int k = 0; k < blobs; ++k) {
    const cv::Point centre(rng.uniform(0, width), rng.uniform(0, height));
    const int rx = rng.uniform(kMinRadius, kMaxRadius + 1);
    const int ry = rng.uniform(kMinRadius, kMaxRadius + 1);
    switch (rng.uniform(0, 3)) {
      case 0:
        cv::circle(texture, centre, rx, colour(), cv::FILLED, cv::LINE_AA);
        break;
      case 1:
        cv::ellipse(texture, centre, cv::Size(rx, ry), rng.uniform(0.0, 180.0), 0, 360, colour(),
                    cv::FILLED, cv::LINE_AA);
        break;
      default:
        cv::rectangle(texture, cv::Rect(centre.x - rx, centre.y - ry, 2 * rx, 2 * ry), colour(),
                      cv::FILLED);
        break;
    }
  }
  cv::GaussianBlur(texture, texture, cv::Size(), kBlurSigmaPx);
  return texture;
}

Expected<std::string> WriteTexturedRoom(const fs::path& dir, const TexturedRoomOptions& options) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::Error("cannot create " + dir.string() + ": " + ec.message());
  const RoomLayout layout = DefaultRoomLayout();
  const Eigen::Vector3d lo = layout.room.min(), hi = layout.room.max();
  const Eigen::Vector3d size = hi - lo;
  const Eigen::Vector3d x(size.x(), 0, 0), y(0, size.y(), 0), z(0, 0, size.z());
  const Eigen::Vector2d uv0(0, 0), uv1(1, 1);

  std::vector<Material> materials;
  ObjWriter obj;
  const auto add_material = [&](const std::string& name, double width_m, double height_m) {
    materials.push_back({name, TexturePx(width_m, options), TexturePx(height_m, options), {}});
    return materials.size() - 1;
  };
  // The room: surfaces facing inwards.
  size_t m = add_material("floor", size.x(), size.y());
  obj.AddFace(&materials[m], lo, x, y, uv0, uv1, options.cell_m);
  m = add_material("ceiling", size.y(), size.x());
  obj.AddFace(&materials[m], lo + z, y, x, uv0, uv1, options.cell_m);
  m = add_material("wall_south", size.x(), size.z());
  obj.AddFace(&materials[m], {hi.x(), lo.y(), lo.z()}, -x, z, uv0, uv1, options.cell_m);
  m = add_material("wall_north", size.x(), size.z());
  obj.AddFace(&materials[m], {lo.x(), hi.y(), lo.z()}, x, z, uv0, uv1, options.cell_m);
  m = add_material("wall_west", size.y(), size.z());
  obj.AddFace(&materials[m], lo, y, z, uv0, uv1, options.cell_m);
  m = add_material("wall_east", size.y(), size.z());
  obj.AddFace(&materials[m], {hi.x(), hi.y(), lo.z()}, -y, z, uv0, uv1, options.cell_m);
  // Boxes: four sides and a top facing outwards, each in one cell of a 3 x 2 texture atlas.
  for (size_t b = 0; b < std::size(kBoxHeights) && b < layout.obstacles.size(); ++b) {
    const Eigen::Vector2d f0 = layout.obstacles[b].min(), f1 = layout.obstacles[b].max();
    const double h = kBoxHeights[b];
    const Eigen::Vector3d dx(f1.x() - f0.x(), 0, 0), dy(0, f1.y() - f0.y(), 0), dz(0, 0, h);
    const double longest = std::max({dx.norm(), dy.norm(), h});
    m = add_material("box" + std::to_string(b), 3 * longest, 2 * longest);
    const auto cell = [](int k) {
      return std::pair<Eigen::Vector2d, Eigen::Vector2d>{{(k % 3) / 3.0, (k / 3) / 2.0},
                                                         {(k % 3 + 1) / 3.0, (k / 3 + 1) / 2.0}};
    };
    const Eigen::Vector3d p0(f0.x(), f0.y(), 0), p1(f1.x(), f1.y(), 0);
    const std::pair<Eigen::Vector3d, std::pair<Eigen::Vector3d, Eigen::Vector3d>> faces[] = {
        {p0 + dz, {dx, dy}},               // top
        {p0, {dx, dz}},                    // facing -y
        {p1, {-dx, dz}},                   // facing +y
        {{f0.x(), f1.y(), 0}, {-dy, dz}},  // facing -x
        {{f1.x(), f0.y(), 0}, {dy, dz}},   // facing +x
    };
    for (int k = 0; k < 5; ++k) {
      const auto [a, c] = cell(k);
      obj.AddFace(&materials[m], faces[k].first, faces[k].second.first, faces[k].second.second, a,
                  c, options.cell_m);
    }
  }

  std::ostringstream mtl;
  for (size_t i = 0; i < materials.size(); ++i) {
    const Material& material = materials[i];
    const std::string png = material.name + ".png";
    const cv::Mat texture =
        MakeBlobTexture(material.width_px, material.height_px, options.seed * 1000 + i);
    if (!cv::imwrite((dir / png).string(), texture)) {
      return Status::Error("cannot write " + (dir / png).string());
    }
    mtl << "newmtl " << material.name << "\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nmap_Kd " << png << "\n\n";
  }
  if (Status s = WriteTextFile(dir / "textured_room.mtl", mtl.str()); !s) return s;
  const fs::path obj_path = dir / "textured_room.obj";
  if (Status s = WriteTextFile(obj_path, obj.Text(materials, "textured_room.mtl")); !s) return s;
  return obj_path.string();
}

}  // namespace m2s::testing
