#!/usr/bin/env bash
# Collaborative SLAM in real time: m2s_server and two m2s_client processes over LCM UDP
# multicast on the loopback of a private network namespace (needs root: unshare -n), 30 fps
# real time (no --fast: frames the server cannot take in time are skipped), noise-free, the CPU
# projector. The two agents walk the default trajectory in opposite directions in one map
# group. Prints each agent's figures and the joint ATE (one Sim3 for both agents, m2s_eval
# --agent).
#
#   tools/bench_slam/run_map_group_bar.sh [BUILD_DIR] [SECONDS]   (default: build/, 20 s)
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
build="$(cd "${1:-$root/build}" && pwd)"
seconds="${2:-20}"
bin="$build/bin"
url='udpm://239.255.76.67:7667?ttl=0'
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# The walk: the default trajectory at 30 fps (the client writes the ground truth it played),
# and the same places backwards in time.
"$bin/m2s_client" --on-device --fast --fps 30 --duration "$seconds" --projector cpu \
  --no-map-png --out "$work/walk" >/dev/null 2>&1
cp "$work/walk/groundtruth.tum" "$work/a.tum"
python3 - "$work/a.tum" "$work/b.tum" <<'PY'
import sys
rows = [l.split() for l in open(sys.argv[1]) if l.strip() and not l.startswith('#')]
with open(sys.argv[2], 'w') as out:
    for row, place in zip(rows, reversed(rows)):
        out.write(' '.join([row[0]] + place[1:]) + '\n')
PY

cat >"$work/run.sh" <<EOF
ip link set lo up && ip route add 224.0.0.0/4 dev lo || exit 90
"$bin/m2s_server" --lcm-url '$url' --stats-period 0 --stats-out "$work/stats.json" \
  2> "$work/server.log" &
server=\$!
for i in \$(seq 100); do grep -q 'listening on' "$work/server.log" && break; sleep 0.1; done
for agent in a b; do
  "$bin/m2s_client" --lcm-url '$url' --fps 30 --trajectory "$work/\$agent.tum" \
    --map-group room --projector cpu --budget 1000 --no-map-png --out "$work/\$agent" \
    > "$work/\$agent.log" 2>&1 &
  eval "client_\$agent=\$!"
done
wait \$client_a; a=\$?
wait \$client_b; b=\$?
kill -TERM \$server; wait \$server
exit \$((a + b))
EOF
unshare -n sh "$work/run.sh" || { tail -n 5 "$work/server.log" "$work/a.log" "$work/b.log" >&2; exit 1; }

python3 - "$work" <<'PY'
import json, sys
work = sys.argv[1]
for agent in ('a', 'b'):
    m = json.load(open(f'{work}/{agent}/metrics.json'))
    print(f"agent {agent}: frames {m['frames_total']}, skipped {m['frames_skipped']}, "
          f"lost {m['frames_lost']}, tracked {m['frames_tracked']}, "
          f"before the merge {m['frames_in_unmerged_maps']}, merged_at_s {m['merged_at_s']}, "
          f"servers_seen {m['servers_seen']}, own ATE {m['ate_rmse'] * 1e3:.3f} mm, "
          f"latency p99 {m['latency_ms_p99']:.1f} ms")
s = json.load(open(f'{work}/stats.json'))
for g in s['groups']:
    print(f"group {g['name']}: agents {g['agents_joined']}, merges {g['merges']}, "
          f"merge_ms {g['merge_ms']}, keyframes {g['keyframes']}, points {g['map_points']}")
PY
"$bin/m2s_eval" --agent "$work/a/groundtruth.tum" "$work/a/trajectory.tum" \
  --agent "$work/b/groundtruth.tum" "$work/b/trajectory.tum"
