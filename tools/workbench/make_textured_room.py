#!/usr/bin/env python3
"""Writes a textured room (OBJ + MTL) for image-based methods, textured with photographs from
Debian packages (assimp-testmodels, glmark2-data).

The room has the footprint of the default scene (6 m x 5 m x 2.7 m, centred on the origin in x
and y, floor at z = 0, z up), so the client's default trajectory walks through it. Walls, floor
and ceiling are grids of 0.25 m quads: the vertex front end gets vertices to project, the image
front ends get textures to describe: three walls carry murals (one photograph each, floor to
ceiling), the fourth is plastered with a poster on it; floor and ceiling repeat every metre.

    tools/workbench/make_textured_room.py OUT_DIR   # writes OUT_DIR/room.obj, room.mtl
"""
import os
import sys

TEXTURES = {
    "wall": "/usr/share/assimp/models/3DS/CWALL02.jpg",
    "mural1": "/usr/share/glmark2/textures/nasa1.png",
    "mural2": "/usr/share/glmark2/textures/nasa2.png",
    "mural3": "/usr/share/glmark2/textures/nasa3.png",
    "floor": "/usr/share/glmark2/textures/terrain-backgrounddetailed6.jpg",
    "ceiling": "/usr/share/glmark2/textures/crate-base.png",
}
SIZE_X, SIZE_Y, SIZE_Z = 6.0, 5.0, 2.7
CELL = 0.25  # quad size, metres
MURAL_M = 2.7  # metres per texture repeat of a mural (one photograph floor to ceiling)


class Obj:
    def __init__(self):
        self.lines = ["# textured room: tools/workbench/make_textured_room.py", "mtllib room.mtl"]
        self.vertices = 0
        self.uvs = 0

    def grid(self, material, origin, axis_u, axis_v, length_u, length_v, texture_m):
        """A grid of quads on the plane origin + s * axis_u + t * axis_v, s in [0, length_u],
        t in [0, length_v]; faces wound so that axis_u x axis_v is the visible side."""
        nu = max(1, round(length_u / CELL))
        nv = max(1, round(length_v / CELL))
        self.lines.append("usemtl " + material)
        first_v, first_t = self.vertices, self.uvs
        for j in range(nv + 1):
            for i in range(nu + 1):
                s, t = length_u * i / nu, length_v * j / nv
                p = [origin[k] + s * axis_u[k] + t * axis_v[k] for k in range(3)]
                self.lines.append("v %.6f %.6f %.6f" % tuple(p))
                self.lines.append("vt %.6f %.6f" % (s / texture_m, t / texture_m))
        self.vertices += (nu + 1) * (nv + 1)
        self.uvs += (nu + 1) * (nv + 1)
        for j in range(nv):
            for i in range(nu):
                a = first_v + j * (nu + 1) + i + 1
                b, c, d = a + 1, a + nu + 2, a + nu + 1
                ta = first_t + j * (nu + 1) + i + 1
                tb, tc, td = ta + 1, ta + nu + 2, ta + nu + 1
                self.lines.append("f %d/%d %d/%d %d/%d %d/%d" % (a, ta, b, tb, c, tc, d, td))


def main():
    if len(sys.argv) != 2:
        sys.stderr.write("usage: make_textured_room.py OUT_DIR\n")
        return 2
    missing = [p for p in TEXTURES.values() if not os.path.exists(p)]
    if missing:
        sys.stderr.write("make_textured_room.py: missing %s (tools/m2s setup installs it)\n"
                         % missing[0])
        return 1
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    x0, y0 = -SIZE_X / 2, -SIZE_Y / 2
    obj = Obj()
    # Inward-facing walls (u along the wall, v up), floor (facing up), ceiling (facing down).
    # Three walls with murals (photographs), one plain plastered wall.
    obj.grid("mural1", (-x0, y0, 0), (-1, 0, 0), (0, 0, 1), SIZE_X, SIZE_Z, MURAL_M)  # y = y0
    obj.grid("mural2", (x0, -y0, 0), (1, 0, 0), (0, 0, 1), SIZE_X, SIZE_Z, MURAL_M)  # y = -y0
    obj.grid("mural3", (-x0, -y0, 0), (0, -1, 0), (0, 0, 1), SIZE_Y, SIZE_Z, MURAL_M)  # x = -x0
    obj.grid("wall", (x0, y0, 0), (0, 1, 0), (0, 0, 1), SIZE_Y, SIZE_Z, 1.0)  # x = x0
    obj.grid("floor", (x0, y0, 0), (1, 0, 0), (0, 1, 0), SIZE_X, SIZE_Y, 1.0)
    obj.grid("ceiling", (x0, -y0, SIZE_Z), (1, 0, 0), (0, -1, 0), SIZE_X, SIZE_Y, 1.0)
    # A poster 2 cm off the plain wall.
    obj.grid("mural1", (x0 + 0.02, -1.0, 0.9), (0, 1, 0), (0, 0, 1), 1.5, 1.0, 1.5)
    with open(os.path.join(out, "room.obj"), "w") as f:
        f.write("\n".join(obj.lines) + "\n")
    with open(os.path.join(out, "room.mtl"), "w") as f:
        for name, path in TEXTURES.items():
            f.write("newmtl %s\nKd 1 1 1\nmap_Kd %s\n\n" % (name, path))
    print("%s: %d vertices" % (os.path.join(out, "room.obj"), obj.vertices))
    return 0


if __name__ == "__main__":
    sys.exit(main())
