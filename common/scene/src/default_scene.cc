// The embedded default scene: a furnished room built from axis-aligned grids, boxes,
// cylinders and spheres. World frame z up, floor at z = 0, room x in [-3, 3], y in [-2.5, 2.5],
// z in [0, 2.7]. Vertex density varies on purpose: dense wall panels, pictures and cushions,
// a sparse floor and ceiling. Every coordinate comes from the same float expressions, so shared
// edges of a box merge exactly and the result is identical on every machine.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>

#include "m2s/common/scene.h"
#include "scene_builder.h"

namespace m2s {
namespace {

constexpr float kRoomMinX = -3.0f, kRoomMaxX = 3.0f;
constexpr float kRoomMinY = -2.5f, kRoomMaxY = 2.5f;
constexpr float kRoomHeight = 2.7f;
constexpr float kTwoPi = 6.28318530717958647692f;

struct Rect {  // an opening in a wall, in the wall's (a, b) coordinates
  float a0, a1, b0, b1;
  bool Contains(float a, float b) const { return a > a0 && a < a1 && b > b0 && b < b1; }
};

float Lerp(float a, float b, int i, int n) {
  if (i == 0) return a;
  if (i == n) return b;
  return a + (b - a) * (static_cast<float>(i) / static_cast<float>(n));
}

int Segments(float length, float spacing) {
  return std::max(1, static_cast<int>(std::lround(std::abs(length) / spacing)));
}

// Deterministic on every platform (std distributions are implementation-defined).
class Lcg {
 public:
  explicit Lcg(uint64_t seed) : state_(seed) {}
  float Uniform(float lo, float hi) {
    state_ = state_ * 6364136223846793005ull + 1442695040888963407ull;
    const float unit = static_cast<float>(state_ >> 40) / static_cast<float>(1ull << 24);
    return lo + (hi - lo) * unit;
  }

 private:
  uint64_t state_;
};

class RoomBuilder {
 public:
  // A grid on the plane {x[axis] = fixed}; a runs along axis (axis+1)%3, b along (axis+2)%3.
  // Cells whose centre lies in one of `holes` are left out. `flip` reverses the winding.
  void AxisRect(int axis, float fixed, float a0, float a1, int na, float b0, float b1, int nb,
                bool flip, const std::vector<Rect>& holes = {}) {
    const int ia = (axis + 1) % 3, ib = (axis + 2) % 3;
    auto vertex = [&](int i, int j) {
      Eigen::Vector3f p;
      p[axis] = fixed;
      p[ia] = Lerp(a0, a1, i, na);
      p[ib] = Lerp(b0, b1, j, nb);
      return builder_.Add(p);
    };
    for (int j = 0; j < nb; ++j) {
      for (int i = 0; i < na; ++i) {
        const float ca = 0.5f * (Lerp(a0, a1, i, na) + Lerp(a0, a1, i + 1, na));
        const float cb = 0.5f * (Lerp(b0, b1, j, nb) + Lerp(b0, b1, j + 1, nb));
        if (std::any_of(holes.begin(), holes.end(),
                        [&](const Rect& r) { return r.Contains(ca, cb); })) {
          continue;
        }
        const VertexId v00 = vertex(i, j), v10 = vertex(i + 1, j);
        const VertexId v11 = vertex(i + 1, j + 1), v01 = vertex(i, j + 1);
        Quad(v00, v10, v11, v01, flip);
      }
    }
  }

  // An axis-aligned box with about `spacing` metres between vertices on every face.
  void Box(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, float spacing) {
    int n[3];
    for (int k = 0; k < 3; ++k) n[k] = Segments(hi[k] - lo[k], spacing);
    for (int axis = 0; axis < 3; ++axis) {
      const int ia = (axis + 1) % 3, ib = (axis + 2) % 3;
      AxisRect(axis, lo[axis], lo[ia], hi[ia], n[ia], lo[ib], hi[ib], n[ib], true);
      AxisRect(axis, hi[axis], lo[ia], hi[ia], n[ia], lo[ib], hi[ib], n[ib], false);
    }
  }

  // A vertical (truncated) cone or cylinder around (cx, cy) from z0 to z1, with caps.
  void Cylinder(float cx, float cy, float z0, float z1, float r0, float r1, int segments, int rings,
                bool caps = true) {
    auto vertex = [&](int k, int j) {
      const float angle = kTwoPi * static_cast<float>(k % segments) / static_cast<float>(segments);
      const float r = Lerp(r0, r1, j, rings);
      return builder_.Add(
          {cx + r * std::cos(angle), cy + r * std::sin(angle), Lerp(z0, z1, j, rings)});
    };
    for (int j = 0; j < rings; ++j) {
      for (int k = 0; k < segments; ++k) {
        Quad(vertex(k, j), vertex(k + 1, j), vertex(k + 1, j + 1), vertex(k, j + 1), false);
      }
    }
    if (!caps) return;
    const VertexId bottom = builder_.Add({cx, cy, z0});
    const VertexId top = builder_.Add({cx, cy, z1});
    for (int k = 0; k < segments; ++k) {
      builder_.AddTriangle(bottom, vertex(k + 1, 0), vertex(k, 0));
      builder_.AddTriangle(top, vertex(k, rings), vertex(k + 1, rings));
    }
  }

  void Sphere(const Eigen::Vector3f& c, float radius, int segments, int rings) {
    const VertexId south = builder_.Add(c - Eigen::Vector3f(0, 0, radius));
    const VertexId north = builder_.Add(c + Eigen::Vector3f(0, 0, radius));
    auto vertex = [&](int k, int j) {  // j in [1, rings - 1]
      const float polar = 0.5f * kTwoPi * static_cast<float>(j) / static_cast<float>(rings);
      const float azimuth =
          kTwoPi * static_cast<float>(k % segments) / static_cast<float>(segments);
      const float s = std::sin(polar);
      return builder_.Add(c + radius * Eigen::Vector3f(s * std::cos(azimuth), s * std::sin(azimuth),
                                                       -std::cos(polar)));
    };
    for (int k = 0; k < segments; ++k) {
      builder_.AddTriangle(south, vertex(k + 1, 1), vertex(k, 1));
      builder_.AddTriangle(north, vertex(k, rings - 1), vertex(k + 1, rings - 1));
      for (int j = 1; j + 1 < rings; ++j) {
        Quad(vertex(k, j), vertex(k + 1, j), vertex(k + 1, j + 1), vertex(k, j + 1), false);
      }
    }
  }

  Scene Build() && {
    builder_.Canonicalize();
    Scene scene = std::move(builder_).Build("default_room");
    ScenePart room;
    room.name = "room";
    room.num_triangles = static_cast<uint32_t>(scene.num_triangles());
    room.end_vertex = static_cast<VertexId>(scene.num_vertices());
    scene.parts.push_back(std::move(room));
    return scene;
  }

 private:
  void Quad(VertexId a, VertexId b, VertexId c, VertexId d, bool flip) {
    if (flip) {
      std::swap(b, d);
    }
    builder_.AddTriangle(a, b, c);
    builder_.AddTriangle(a, c, d);
  }

  internal::SceneBuilder builder_;
};

// A wall's inner face on {x[axis] = fixed}; openings in (a, b) = (along the wall, height).
void Wall(RoomBuilder& room, int axis, float fixed, float a0, float a1, float spacing,
          const std::vector<Rect>& openings, bool flip) {
  const int na = Segments(a1 - a0, spacing), nb = Segments(kRoomHeight, spacing);
  if (axis == 0) {  // x = fixed: a = y, b = z
    room.AxisRect(0, fixed, a0, a1, na, 0.f, kRoomHeight, nb, flip, openings);
  } else {  // y = fixed: axis 1's (a, b) are (z, x); swap so openings stay (x, z)
    std::vector<Rect> swapped;
    for (const Rect& r : openings) swapped.push_back({r.b0, r.b1, r.a0, r.a1});
    room.AxisRect(1, fixed, 0.f, kRoomHeight, nb, a0, a1, na, flip, swapped);
  }
}

// A frame of four bars around an opening in a wall at y = wall_y (x/z opening) or x = wall_x.
void FrameY(RoomBuilder& room, float wall_y, float inward, const Rect& o, float bar,
            float spacing) {
  const float y0 = std::min(wall_y, wall_y + inward), y1 = std::max(wall_y, wall_y + inward);
  room.Box({o.a0 - bar, y0, o.b0 > 0.f ? o.b0 - bar : 0.f}, {o.a0, y1, o.b1 + bar}, spacing);
  room.Box({o.a1, y0, o.b0 > 0.f ? o.b0 - bar : 0.f}, {o.a1 + bar, y1, o.b1 + bar}, spacing);
  room.Box({o.a0, y0, o.b1}, {o.a1, y1, o.b1 + bar}, spacing);
  if (o.b0 > 0.f) room.Box({o.a0, y0, o.b0 - bar}, {o.a1, y1, o.b0}, spacing);
}

void FrameX(RoomBuilder& room, float wall_x, float inward, const Rect& o, float bar,
            float spacing) {
  const float x0 = std::min(wall_x, wall_x + inward), x1 = std::max(wall_x, wall_x + inward);
  room.Box({x0, o.a0 - bar, o.b0 - bar}, {x1, o.a0, o.b1 + bar}, spacing);
  room.Box({x0, o.a1, o.b0 - bar}, {x1, o.a1 + bar, o.b1 + bar}, spacing);
  room.Box({x0, o.a0, o.b1}, {x1, o.a1, o.b1 + bar}, spacing);
  room.Box({x0, o.a0, o.b0 - bar}, {x1 + 0.12f, o.a1, o.b0}, spacing);  // sill
  room.Box({x0, 0.5f * (o.a0 + o.a1) - 0.02f, o.b0}, {x1, 0.5f * (o.a0 + o.a1) + 0.02f, o.b1},
           spacing);  // mullion
}

void Chair(RoomBuilder& room, float cx, float cy, bool back_north) {
  constexpr float kHalf = 0.21f, kSeat = 0.43f, kLeg = 0.03f, kSpacing = 0.03f;
  room.Box({cx - kHalf, cy - kHalf, kSeat}, {cx + kHalf, cy + kHalf, kSeat + 0.04f}, kSpacing);
  for (float sx : {-1.f, 1.f}) {
    for (float sy : {-1.f, 1.f}) {
      const float lx = cx + sx * (kHalf - kLeg), ly = cy + sy * (kHalf - kLeg);
      room.Box({lx - kLeg * 0.5f, ly - kLeg * 0.5f, 0.f},
               {lx + kLeg * 0.5f, ly + kLeg * 0.5f, kSeat}, 0.1f);
    }
  }
  const float by = back_north ? cy + kHalf - 0.04f : cy - kHalf;
  room.Box({cx - kHalf, by, kSeat + 0.04f}, {cx + kHalf, by + 0.04f, kSeat + 0.5f}, 0.03f);
}

}  // namespace

RoomLayout DefaultRoomLayout() {
  RoomLayout layout;
  layout.room = Eigen::AlignedBox3d(Eigen::Vector3d(kRoomMinX, kRoomMinY, 0.0),
                                    Eigen::Vector3d(kRoomMaxX, kRoomMaxY, kRoomHeight));
  auto box = [](double x0, double y0, double x1, double y1) {
    return Eigen::AlignedBox2d(Eigen::Vector2d(x0, y0), Eigen::Vector2d(x1, y1));
  };
  layout.obstacles = {
      box(-0.4, -1.16, 1.0, 0.56),      // table and chairs
      box(-2.4, 1.6, -0.4, 2.5),        // sofa
      box(2.62, -0.4, 3.0, 1.2),        // shelves
      box(-2.8, 1.05, -2.4, 1.45),      // floor lamp
      box(-2.2, -2.5, -0.8, -2.05),     // sideboard
      box(-2.85, -2.35, -2.45, -1.95),  // ball
      box(2.5, -1.45, 2.9, -1.05),      // plant
  };
  return layout;
}

Scene MakeDefaultScene() {
  RoomBuilder room;
  // Walls (inner faces), each with its own density. Openings: (along, height) rectangles.
  const Rect door{1.6f, 2.5f, 0.f, 2.1f};
  const Rect north_window{0.6f, 2.2f, 1.0f, 2.1f};
  const Rect west_window_a{-1.6f, -0.4f, 0.9f, 2.1f};
  const Rect west_window_b{0.4f, 1.6f, 0.9f, 2.1f};
  Wall(room, 1, kRoomMinY, kRoomMinX, kRoomMaxX, 0.05f, {door}, false);          // south
  Wall(room, 1, kRoomMaxY, kRoomMinX, kRoomMaxX, 0.045f, {north_window}, true);  // north
  Wall(room, 0, kRoomMinX, kRoomMinY, kRoomMaxY, 0.06f, {west_window_a, west_window_b}, false);
  Wall(room, 0, kRoomMaxX, kRoomMinY, kRoomMaxY, 0.1f, {}, true);  // east
  // Sparse floor and ceiling, a dense rug.
  room.AxisRect(2, 0.f, kRoomMinX, kRoomMaxX, 20, kRoomMinY, kRoomMaxY, 17, false);
  room.AxisRect(2, kRoomHeight, kRoomMinX, kRoomMaxX, 24, kRoomMinY, kRoomMaxY, 20, true);
  room.AxisRect(2, 0.01f, -0.9f, 1.5f, 48, -1.1f, 0.5f, 32, false);
  // Skirting boards.
  room.Box({kRoomMinX, kRoomMinY, 0.f}, {kRoomMaxX, kRoomMinY + 0.02f, 0.1f}, 0.05f);
  room.Box({kRoomMinX, kRoomMaxY - 0.02f, 0.f}, {kRoomMaxX, kRoomMaxY, 0.1f}, 0.05f);
  room.Box({kRoomMinX, kRoomMinY, 0.f}, {kRoomMinX + 0.02f, kRoomMaxY, 0.1f}, 0.05f);
  room.Box({kRoomMaxX - 0.02f, kRoomMinY, 0.f}, {kRoomMaxX, kRoomMaxY, 0.1f}, 0.05f);
  // Door and window frames.
  FrameY(room, kRoomMinY, 0.06f, door, 0.08f, 0.04f);
  FrameY(room, kRoomMaxY, -0.06f, north_window, 0.06f, 0.04f);
  FrameX(room, kRoomMinX, 0.06f, west_window_a, 0.06f, 0.04f);
  FrameX(room, kRoomMinX, 0.06f, west_window_b, 0.06f, 0.04f);
  // Pictures: thin boxes with densely tessellated fronts.
  room.Box({-1.6f, kRoomMinY + 0.02f, 1.2f}, {-0.6f, kRoomMinY + 0.05f, 1.9f}, 0.02f);
  room.Box({kRoomMaxX - 0.05f, -2.0f, 1.1f}, {kRoomMaxX - 0.02f, -1.0f, 1.8f}, 0.03f);
  room.Box({kRoomMinX + 0.02f, -0.3f, 1.2f}, {kRoomMinX + 0.05f, 0.3f, 1.8f}, 0.02f);
  room.Box({-2.2f, kRoomMaxY - 0.05f, 1.2f}, {-0.6f, kRoomMaxY - 0.02f, 1.9f}, 0.04f);
  // Table with four legs, four chairs, a vase and a bowl.
  room.Box({-0.4f, -0.7f, 0.71f}, {1.0f, 0.1f, 0.75f}, 0.04f);
  for (float lx : {-0.34f, 0.94f}) {
    for (float ly : {-0.64f, 0.04f}) room.Cylinder(lx, ly, 0.f, 0.71f, 0.03f, 0.03f, 12, 10);
  }
  Chair(room, 0.0f, 0.35f, true);
  Chair(room, 0.6f, 0.35f, true);
  Chair(room, 0.0f, -0.95f, false);
  Chair(room, 0.6f, -0.95f, false);
  room.Cylinder(0.55f, -0.3f, 0.75f, 1.0f, 0.05f, 0.07f, 32, 16);
  room.Sphere({0.05f, -0.35f, 0.82f}, 0.07f, 24, 12);
  // Sofa: base, back, arms, dense cushions.
  room.Box({-2.4f, 1.6f, 0.f}, {-0.4f, 2.45f, 0.42f}, 0.08f);
  room.Box({-2.4f, 2.2f, 0.42f}, {-0.4f, 2.45f, 0.85f}, 0.05f);
  room.Box({-2.4f, 1.6f, 0.42f}, {-2.2f, 2.2f, 0.62f}, 0.05f);
  room.Box({-0.6f, 1.6f, 0.42f}, {-0.4f, 2.2f, 0.62f}, 0.05f);
  for (int k = 0; k < 3; ++k) {
    const float x0 = -2.2f + 0.6f * static_cast<float>(k);
    room.Box({x0 + 0.01f, 1.62f, 0.42f}, {x0 + 0.59f, 2.18f, 0.55f}, 0.03f);
  }
  // Shelves against the east wall, with boxes of varied size and density.
  constexpr float kShelfX0 = 2.62f, kShelfX1 = 2.98f, kShelfY0 = -0.4f, kShelfY1 = 1.2f;
  room.Box({kShelfX0, kShelfY0, 0.f}, {kShelfX1, kShelfY0 + 0.03f, 2.0f}, 0.06f);
  room.Box({kShelfX0, kShelfY1 - 0.03f, 0.f}, {kShelfX1, kShelfY1, 2.0f}, 0.06f);
  room.Box({kShelfX1 - 0.02f, kShelfY0, 0.f}, {kShelfX1, kShelfY1, 2.0f}, 0.08f);
  Lcg rng(20240611);
  for (int level = 0; level < 5; ++level) {
    const float z = 0.05f + 0.45f * static_cast<float>(level);
    room.Box({kShelfX0, kShelfY0 + 0.03f, z - 0.025f}, {kShelfX1 - 0.02f, kShelfY1 - 0.03f, z},
             0.05f);
    if (level == 4) break;
    float y = kShelfY0 + 0.06f;
    while (true) {
      const float width = rng.Uniform(0.1f, 0.3f);
      if (y + width > kShelfY1 - 0.06f) break;
      const float height = rng.Uniform(0.12f, 0.38f), depth = rng.Uniform(0.15f, 0.3f);
      const float spacing = rng.Uniform(0.025f, 0.07f);
      room.Box({kShelfX1 - 0.03f - depth, y, z}, {kShelfX1 - 0.03f, y + width, z + height},
               spacing);
      y += width + rng.Uniform(0.02f, 0.08f);
    }
  }
  // Floor lamp: base, pole, dense shade.
  room.Cylinder(-2.6f, 1.25f, 0.f, 0.03f, 0.15f, 0.15f, 24, 1);
  room.Cylinder(-2.6f, 1.25f, 0.03f, 1.45f, 0.015f, 0.015f, 8, 20, false);
  room.Cylinder(-2.6f, 1.25f, 1.45f, 1.7f, 0.2f, 0.12f, 64, 24, false);
  // Sideboard with a vase, a ball in the corner, a potted plant, a ceiling light.
  room.Box({-2.2f, -2.48f, 0.f}, {-0.8f, -2.05f, 0.8f}, 0.04f);
  room.Cylinder(-1.9f, -2.27f, 0.8f, 1.1f, 0.06f, 0.04f, 32, 20);
  room.Sphere({-2.65f, -2.15f, 0.15f}, 0.15f, 32, 16);
  room.Cylinder(2.7f, -1.25f, 0.f, 0.35f, 0.13f, 0.17f, 32, 10);
  room.Sphere({2.7f, -1.25f, 0.65f}, 0.3f, 48, 24);
  room.Cylinder(0.3f, -0.3f, 2.55f, 2.7f, 0.3f, 0.25f, 48, 6);
  return std::move(room).Build();
}

}  // namespace m2s
