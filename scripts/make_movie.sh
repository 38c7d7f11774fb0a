#!/bin/sh
# Renders the showcase movie and assembles it into an animated WebP (img2webp, Debian
# package `webp`, installed through scripts/install-deps.sh when missing).
# Each frame is one master run with --frames F:F and its own --preview PNG, from a copy of
# the scene at the movie's size written beside it (scenes/showcase/movie.json, not
# committed; SCENE names another scene file). Frames whose PNG exists are skipped, so a killed run resumes. The smoke grids must exist (make showcase-assets).
# Usage: [BUILD=build] [WIDTH=320 HEIGHT=180 SPP=2 FIRST=25 LAST=72 STEP=1 WORKERS=2 FPS=12 SCENE=...]
#        sh scripts/make_movie.sh OUT.webp [FRAMES_DIR]
set -eu
[ $# -ge 1 ] || { sed -n 2,9p "$0"; exit 2; }
OUT=$1
DIR=${2:-out/movie}
BUILD=${BUILD:-build}
W=${WIDTH:-320}; H=${HEIGHT:-180}; SPP=${SPP:-2}
FIRST=${FIRST:-25}; LAST=${LAST:-72}; STEP=${STEP:-1}; WORKERS=${WORKERS:-2}; FPS=${FPS:-12}
command -v img2webp >/dev/null 2>&1 || sh "$(dirname "$0")/install-deps.sh" webp
mkdir -p "$DIR"
SRC=${SCENE:-scenes/showcase/showcase.json}
SCENE=$(dirname "$SRC")/movie.json
python3 - "$SRC" "$SCENE" "$W" "$H" "$SPP" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["render"].update({"width": int(sys.argv[3]), "height": int(sys.argv[4]), "spp": int(sys.argv[5])})
json.dump(s, open(sys.argv[2], "w"), indent=1)
PY
f=$FIRST
frames=""
while [ "$f" -le "$LAST" ]; do
  png=$(printf '%s/frame.%04d.png' "$DIR" "$f")
  if [ ! -s "$png" ]; then
    # With --frames, -o and --preview are numbered: frame.NNNN.exr, preview.NNNN.png.
    "$BUILD/master" "$SCENE" -o "$DIR/frame.exr" --frames "$f:$f" --workers "$WORKERS" \
      --no-journal --preview "$DIR/preview.png" >"$DIR/render.log" 2>&1 ||
      { tail -5 "$DIR/render.log" >&2; echo "make_movie: frame $f failed (log: $DIR/render.log)" >&2; exit 1; }
    grep -q "NaN/Inf samples dropped: 0" "$DIR/render.log" ||
      echo "make_movie: frame $f: $(grep 'NaN/Inf' "$DIR/render.log")" >&2
    mv "$(printf '%s/preview.%04d.png' "$DIR" "$f")" "$png"
    echo "make_movie: frame $f -> $png"
  fi
  frames="$frames $png"
  f=$((f + STEP))
done
# shellcheck disable=SC2086
img2webp -loop 0 -lossy -q 80 -m 6 -d $((1000 * STEP / FPS)) $frames -o "$OUT"
echo "make_movie: $OUT ($(wc -c <"$OUT") bytes, $(echo $frames | wc -w) frames)"
