#!/usr/bin/env bash
# Builds the libFuzzer targets of tests/fuzz in BUILD_DIR (clang, -DM2S_FUZZ=ON) and runs each
# one, as many at once as there are cores (JOBS to change): first over its committed inputs
# (tests/fuzz/regressions/<target>_* and tests/fuzz/corpus/<target>/), then SECONDS of fuzzing
# (default 10) from its seed corpus. An allocation larger than 512 MB counts as a finding
# (-malloc_limit_mb), so does a run past 2 GB of memory or 10 s on one input. Prints one line
# per target, in a fixed order; exits non-zero when any target found something (its log and
# crash input are under BUILD_DIR/fuzz/).
#
#   tools/fuzz/run_fuzzers.sh build-fuzz 60
#   build-fuzz/bin/fuzz_session_control build-fuzz/fuzz/session_control-crash-...   # reproduce
set -euo pipefail

if [[ $# -lt 1 || $# -gt 2 || ! ${2:-10} =~ ^[0-9]+$ ]]; then
  echo "usage: $0 BUILD_DIR [SECONDS]" >&2
  exit 2
fi
root=$(cd "$(dirname "$0")/../.." && pwd)
build_dir=$(mkdir -p "$1" && cd "$1" && pwd)
seconds=${2:-10}
targets=(feature_frame session_control pose_estimate map_delta server_stats map_file lcm_log
         bus_envelope)
limits=(-rss_limit_mb=2048 -malloc_limit_mb=512 -timeout=10)

if ! cmake -S "$root" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DM2S_BUILD_TESTS=OFF -DM2S_BUILD_BENCHMARKS=OFF -DM2S_BUILD_XR=OFF -DM2S_FUZZ=ON \
    -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_C_COMPILER=clang >"$build_dir/configure.log" 2>&1; then
  echo "configure failed: see $build_dir/configure.log" >&2
  exit 1
fi
if ! cmake --build "$build_dir" -j "${JOBS:-$(nproc)}" >"$build_dir/build.log" 2>&1; then
  echo "build failed: see $build_dir/build.log" >&2
  exit 1
fi

out="$build_dir/fuzz"
mkdir -p "$out"

run_target() {  # TARGET: writes its one-line summary to $out/TARGET.status
  local target=$1
  local bin="$build_dir/bin/fuzz_$target"
  local seeds="$root/tests/fuzz/corpus/$target"
  local corpus="$out/corpus-$target"  # seeds plus what fuzzing adds; the source tree stays clean
  local log="$out/$target.log"
  mkdir -p "$corpus"
  shopt -s nullglob
  local inputs=("$root"/tests/fuzz/regressions/"$target"_* "$seeds"/*)
  shopt -u nullglob
  local status=ok
  if ! "$bin" "${limits[@]}" "${inputs[@]}" >"$log" 2>&1; then
    status="FAILED on a committed input"
  elif ! "$bin" "${limits[@]}" -max_total_time="$seconds" -print_final_stats=1 \
      -artifact_prefix="$out/$target-" "$corpus" "$seeds" >>"$log" 2>&1; then
    status="FOUND A CRASH: $(ls -t "$out/$target"-* 2>/dev/null | head -1)"
  fi
  local runs cov
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2 || true)
  printf '%-24s %s: %d committed inputs, %s runs in %s s, coverage %s (log %s)\n' \
    "fuzz_$target" "$status" "${#inputs[@]}" "${runs:-0}" "$seconds" "${cov:-?}" "$log" \
    >"$out/$target.status"
}

# One target per core at a time (each fuzzer is single-threaded); lines print in target order.
jobs=${JOBS:-$(nproc)}
running=0
for target in "${targets[@]}"; do
  rm -f "$out/$target.status"
  run_target "$target" &
  running=$((running + 1))
  if ((running >= jobs)); then
    wait -n || true
    running=$((running - 1))
  fi
done
wait
failed=0
for target in "${targets[@]}"; do
  if [[ -s $out/$target.status ]]; then
    cat "$out/$target.status"
    grep -q "^fuzz_$target *ok:" "$out/$target.status" || failed=1
  else
    echo "fuzz_$target: no result (see $out/$target.log)"
    failed=1
  fi
done
exit "$failed"
