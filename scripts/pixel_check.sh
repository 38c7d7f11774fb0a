#!/bin/sh
# Refactoring guard: renders every scene in scenes/ (media scenes by each method), the
# Embree Cornell box of the bench and the textured bench scene with each texture filter,
# and either saves the EXRs or compares decoded pixels bit for bit against a saved set.
# A change that must not move a pixel is checked by `save` before and `cmp` after.
# Usage: BUILD=build sh scripts/pixel_check.sh save|cmp DIR   (env: SPP, default 4;
# MASTER_OPTS, options added to every render, e.g. "--embree-isa avx512" to compare with a
# set saved under another default)
set -eu
BUILD=${BUILD:-build}
SPP=${SPP:-4}
MODE=${1:?usage: pixel_check.sh save|cmp DIR}
DIR=${2:?usage: pixel_check.sh save|cmp DIR}
mkdir -p "$DIR"
T=$(mktemp -d /tmp/brume-pixcheck.XXXXXX)
trap 'rm -rf "$T"' EXIT
pass=0 fail=0

# render NAME SCENE.json [master options]: to $DIR/NAME.exr (save) or compared with it (cmp)
render() {
  rn=$1; scene=$2; shift 2
  out="$T/$rn.exr"
  if ! "$BUILD/master" "$scene" -o "$out" --workers 2 --threads 1 --spp "$SPP" --no-journal "$@" ${MASTER_OPTS:-} \
      >"$T/log" 2>&1; then
    echo "pixel_check: $rn: render failed:"; tail -3 "$T/log"; fail=$((fail + 1)); return 0
  fi
  for f in "$T/$rn".*exr; do
    b=$(basename "$f")
    if [ "$MODE" = save ]; then
      cp "$f" "$DIR/$b"; pass=$((pass + 1))
    elif [ ! -f "$DIR/$b" ]; then
      echo "pixel_check: $b: not in $DIR"; fail=$((fail + 1))
    elif "$BUILD/exrtool" cmp "$f" "$DIR/$b" >"$T/cmp" 2>&1; then
      pass=$((pass + 1))
    else
      echo "pixel_check: $b differs: $(head -1 "$T/cmp")"; fail=$((fail + 1))
    fi
  done
}

for s in scenes/*/*.json; do
  name=$(basename "$s" .json)
  # Not a scene (a simulator's settings): no camera.
  grep -q '"camera"' "$s" || continue
  # One grid per frame ("####"): frame 1 only, and only once the simulator has written it.
  if grep -q '####' "$s"; then
    pat=$(sed -n 's/.*"file": *"\([^"]*####[^"]*\)".*/\1/p' "$s" | head -1)
    first=$(dirname "$s")/$(echo "$pat" | sed 's/####/0001/')
    if [ ! -f "$first" ]; then
      echo "pixel_check: $name skipped: $first missing (make smoke-sim)"; continue
    fi
    for m in vpt march beam; do render "$name-$m" "$s" --media-method "$m" --frames 1:1; done
    continue
  fi
  if grep -q '"volume"' "$s"; then
    for m in vpt march beam; do render "$name-$m" "$s" --media-method "$m"; done
  else
    render "$name" "$s"
  fi
done
render motion-frames scenes/motion/motion.json --frames 1:2

# The bench scenes: Embree's Cornell box (scripts/bench.sh) and the textured floor filters.
if [ -f /usr/share/doc/embree3/models/cornell_box.obj ]; then
  cp /usr/share/doc/embree3/models/cornell_box.obj /usr/share/doc/embree3/models/cornell_box.mtl "$T/"
  cat >"$T/embree_cornell.json" <<'JSON'
{"version": 1,
 "camera": {"position": [278, 273, -800], "look_at": [278, 273, 0], "up": [0, 1, 0], "fov_y": 37},
 "render": {"width": 96, "height": 96, "spp": 4, "max_depth": 8, "seed": 1, "tile_size": 32, "sampler": "independent"},
 "objects": [{"type": "obj", "file": "cornell_box.obj"}],
 "lights": [{"type": "point", "position": [213, 300, 227], "intensity": [100000, 100000, 100000]}]}
JSON
  render embree_cornell "$T/embree_cornell.json"
fi
cp -r scenes/textured "$T/tex"
python3 - "$T/tex" <<'PY'
import json, sys
d = json.load(open("scenes/textured/textured.json"))
d["render"].update(width=128, height=72)
for f in ["nearest", "bilinear", "trilinear", "ewa"]:
    for t in d["textures"].values():
        t["filter"] = f
    json.dump(d, open("%s/bench-%s.json" % (sys.argv[1], f), "w"))
PY
for f in nearest bilinear trilinear ewa; do render "textured-$f" "$T/tex/bench-$f.json"; done

echo "pixel_check ($MODE): $pass passed, $fail failed"
[ "$fail" -eq 0 ]
