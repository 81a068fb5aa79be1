#!/usr/bin/env python3
"""Writes a scene with a movable part and a scene-events script for m2s_client --scene-events.

  python3 tools/bench/make_moving_crate.py OUT_DIR

OUT_DIR/crate_room.obj: the default room's box (6 x 5 x 2.7 m, walls, floor and ceiling
tessellated every 0.1 m; object "room") and a 0.8 m crate standing on the table's footprint
(tessellated every 0.05 m; object "crate"). OUT_DIR/events.txt moves the crate 0.3 m along x
at 10 s, so that it stays out of the default trajectory's way.
"""
import os
import sys


def grid(origin, du, dv, nu, nv, verts, faces):
    base = len(verts)
    for j in range(nv + 1):
        for i in range(nu + 1):
            verts.append(tuple(origin[k] + du[k] * i / nu + dv[k] * j / nv for k in range(3)))
    for j in range(nv):
        for i in range(nu):
            a = base + j * (nu + 1) + i
            faces.append((a, a + 1, a + nu + 2, a + nu + 1))


def box_faces(lo, hi, step, verts, faces):
    sx, sy, sz = (hi[k] - lo[k] for k in range(3))
    n = lambda s: max(1, round(s / step))
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    grid((x0, y0, z0), (sx, 0, 0), (0, sy, 0), n(sx), n(sy), verts, faces)  # floor / bottom
    grid((x0, y0, z1), (sx, 0, 0), (0, sy, 0), n(sx), n(sy), verts, faces)  # ceiling / top
    grid((x0, y0, z0), (sx, 0, 0), (0, 0, sz), n(sx), n(sz), verts, faces)
    grid((x0, y1, z0), (sx, 0, 0), (0, 0, sz), n(sx), n(sz), verts, faces)
    grid((x0, y0, z0), (0, sy, 0), (0, 0, sz), n(sy), n(sz), verts, faces)
    grid((x1, y0, z0), (0, sy, 0), (0, 0, sz), n(sy), n(sz), verts, faces)


def main():
    if len(sys.argv) != 2:
        sys.stderr.write(__doc__)
        sys.exit(2)
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "crate_room.obj"), "w") as f:
        offset = 0
        for name, lo, hi, step in (("room", (-3, -2.5, 0), (3, 2.5, 2.7), 0.1),
                                   ("crate", (-0.1, -0.7, 0), (0.7, 0.1, 0.8), 0.05)):
            verts, faces = [], []
            box_faces(lo, hi, step, verts, faces)
            f.write(f"o {name}\n")
            f.writelines(f"v {x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in verts)
            f.writelines("f " + " ".join(str(offset + i + 1) for i in q) + "\n" for q in faces)
            offset += len(verts)
    with open(os.path.join(out, "events.txt"), "w") as f:
        f.write("# time_s action part dx dy dz [qw qx qy qz]\n")
        f.write("10 move crate_room.obj/crate 0.3 0 0\n")


if __name__ == "__main__":
    main()
