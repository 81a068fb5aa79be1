#!/usr/bin/env bash
# The paper's Table 2 on this workbench: vertex features and the ORB front end (plus the
# frame-to-frame PnP odometry plug-in as a baseline) on the same scenes and ground truth, at
# 30, 60 and 75 fps, noise-free, deterministic (m2s_client --fast), CPU projector.
#   tools/workbench/run_table2.sh BUILD_DIR [OUT_DIR] [extra m2s_bench args]
# Scenes: a room textured with photographs from Debian packages (make_textured_room.py) and
# the embedded default room (untextured: shaded surfaces only). 20 s of the default trajectory.
# Writes OUT_DIR/results.md (default out/table2) and the plots.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
BUILD="$(cd "${1:?usage: run_table2.sh BUILD_DIR [OUT_DIR]}" && pwd)"
OUT="${2:-$HERE/../../out/table2}"
shift $(( $# >= 2 ? 2 : 1 ))
mkdir -p "$OUT/scenes"
OUT="$(cd "$OUT" && pwd)"
python3 "$HERE/make_textured_room.py" "$OUT/scenes/textured_room" >/dev/null
cat >"$OUT/sweep.json" <<JSON
{
  "methods": [{"name": "vertex"}, {"name": "orb", "front_end": "orb"},
              {"name": "pnp_odometry", "plugin": "pnp_odometry"}],
  "scenes": [{"name": "textured_room", "mesh": "scenes/textured_room/room.obj", "duration_s": 20},
             {"name": "default_room", "duration_s": 20}],
  "fps": [30, 60, 75],
  "noise_px": [0]
}
JSON
exec "$BUILD/bin/m2s_bench" --config "$OUT/sweep.json" --out "$OUT" "$@"
