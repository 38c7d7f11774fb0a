#!/bin/sh
# The showcase scene (scenes/showcase) keeps rendering as the code changes: the Scherk-Collins
# generator writes a closed, outward-wound mesh (its own check passes) and refuses a twist
# that cannot close the ring; the committed sky is the script's output; then the scene, with
# a coarse sculpture and a tiny simulated plume in place of the make-target assets, renders
# at 64x48, 1 spp, bit-identical for 1 worker and for 3 workers with 16-pixel tiles, with no
# NaN/Inf samples; and scripts/make_movie.sh joins 2 tiny frames into an animated WebP.
# Ends with "integration: N passed, N failed".
# Usage: BUILD=build sh tests/integration/showcase.sh
. "$(dirname "$0")/lib.sh"
lib_init showcase
ROOT=$(pwd)
M=$ROOT/$BUILD/master
X=$ROOT/$BUILD/exrtool
S=$T/sc

mkdir -p "$S"
for f in $(git ls-files scenes/showcase 2>/dev/null || ls scenes/showcase); do cp "$f" "$S/"; done
python3 scripts/gen_scherk.py "$S/scherk.obj" --cell 0.07 --thickness 0.16 >"$T/log" 2>&1 && r=0 || r=1
if [ $r = 0 ] && grep -q "watertight, consistently wound" "$T/log"; then ok "showcase: gen_scherk writes a closed, consistently wound mesh"; else bad "showcase: gen_scherk writes a closed, consistently wound mesh"; fi
if ! python3 scripts/gen_scherk.py "$T/x.obj" --saddles 7 --twist 0.5 >"$T/log" 2>&1 && grep -q "does not close" "$T/log"; then
  ok "showcase: gen_scherk refuses a ring that does not close"; else bad "showcase: gen_scherk refuses a ring that does not close"; fi

python3 scripts/gen_sky_hdr.py "$T/sky.hdr" 256 128 7 250 3 1
if cmp -s "$T/sky.hdr" scenes/showcase/sky.hdr; then ok "showcase: sky.hdr is the script's output"; else bad "showcase: sky.hdr is the script's output"; fi

# A 16x24x16 plume, 2 frames, in place of sim.json's (make showcase-sim).
python3 - "$S/sim.json" <<'PY'
import json, sys
p = sys.argv[1]
s = json.load(open(p))
s.update({"resolution": [16, 24, 16], "frames": 2})
s["sponge"]["width"] = 2
json.dump(s, open(p, "w"), indent=1)
PY
run "$ROOT/$BUILD/smokesim" "$S/sim.json" && r=0 || r=1
if [ $r = 0 ] && [ -s "$S/smoke.0002.grid" ]; then ok "showcase: tiny plume simulated"; else bad "showcase: tiny plume simulated"; fi

python3 - "$S/showcase.json" <<'PY'
import json, sys
p = sys.argv[1]
s = json.load(open(p))
s["render"].update({"width": 64, "height": 48, "spp": 1})
json.dump(s, open(p, "w"), indent=1)
PY
run $M "$S/showcase.json" -o "$T/a1.exr" --frames 2:2 --workers 1 && r1=0 || r1=1
nan=$(grep -c "NaN/Inf samples dropped: 0" "$T/log")
run $M "$S/showcase.json" -o "$T/a3.exr" --frames 2:2 --workers 3 --tile 16 && r3=0 || r3=1
if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/a1.0002.exr" "$T/a3.0002.exr"; then ok "showcase: 64x48, 1 spp: 1 vs 3 workers bit-identical"; else bad "showcase: 64x48, 1 spp: 1 vs 3 workers bit-identical"; fi
if [ "$nan" = 1 ] && grep -q "NaN/Inf samples dropped: 0" "$T/log"; then ok "showcase: no NaN/Inf samples"; else bad "showcase: no NaN/Inf samples"; fi

# The movie script at a tiny size: 2 frames of the tiny plume, each its own numbered PNG
# preview, joined into an animated WebP (img2webp: Debian webp; skipped where missing).
if command -v img2webp >/dev/null 2>&1; then
  run env SCENE="$S/showcase.json" WIDTH=32 HEIGHT=24 SPP=1 FIRST=1 LAST=2 WORKERS=1 BUILD="$BUILD" \
    sh scripts/make_movie.sh "$T/m.webp" "$T/movie" && r=0 || r=1
  if [ $r = 0 ] && [ -s "$T/movie/frame.0001.png" ] && [ -s "$T/movie/frame.0002.png" ] &&
    [ "$(head -c 4 "$T/m.webp")" = RIFF ] && grep -q "2 frames" "$T/log"; then
    ok "showcase: make_movie.sh renders 2 frames into an animated WebP"
  else bad "showcase: make_movie.sh renders 2 frames into an animated WebP"; fi
else
  echo "skip: showcase: make_movie.sh (no img2webp; Debian package webp)"
fi
finish
