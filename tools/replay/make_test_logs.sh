#!/usr/bin/env bash
# Makes the small session logs in tests/data/ with the project's own tools: m2s_server and
# m2s_client talk over UDP multicast on the loopback of a private network namespace while the
# standard lcm-logger records the frame and session channels.
#
#   tools/replay/make_test_logs.sh [BUILD_DIR]      (default: build)
#
# Logs (each under 1 MB: a feature budget keeps frames small):
#   default_fast_10hz.lcmlog        --fast, 10 fps, 6 s of the default trajectory, 1500 features
#   default_realtime_30hz.lcmlog    real time, 30 fps, 5 s, 600 features, 0.5 px noise, 1% wrong ids
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
build="${1:-$root/build}"
bin="$build/bin"
out="$root/tests/data"
url='udpm://239.255.76.67:7667?ttl=0'

if [[ "${M2S_IN_NETNS:-}" != 1 ]]; then
  exec unshare -n env M2S_IN_NETNS=1 "$0" "$build"
fi
ip link set lo up
ip route add 224.0.0.0/4 dev lo

record() {  # name, client flags...
  local name="$1"; shift
  local tmp; tmp="$(mktemp -d)"
  "$bin/m2s_server" --lcm-url "$url" --stats-period 0 2> "$tmp/server.log" &
  local server=$!
  # Frames and session messages are what a replay needs (poses and maps are recomputed).
  lcm-logger --lcm-url="$url" --quiet --channel="M2S_FRAME|M2S_SESSION" "$tmp/$name.lcmlog" &
  local logger=$!
  sleep 1
  "$bin/m2s_client" --lcm-url "$url" --projector cpu --no-map-png --out "$tmp/run" "$@"
  sleep 0.5
  kill -INT "$logger" "$server"
  wait "$logger" "$server" || true
  cp "$tmp/$name.lcmlog" "$out/$name.lcmlog"
  ls -l "$out/$name.lcmlog"
  rm -rf "$tmp"
}

record default_fast_10hz --fast --fps 10 --duration 6 --budget 1500
record default_realtime_30hz --fps 30 --duration 5 --budget 600 --noise-px 0.5 --outlier-ids 0.01 --seed 7
