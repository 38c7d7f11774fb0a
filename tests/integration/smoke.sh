#!/bin/sh
# smokesim (docs/smoke.md): a run cut short (by its frame count, then by kill -9 part way)
# and resumed from its checkpoint writes frames bit-identical to a run that never stopped;
# 2 FFTW threads write the same frames as 1, dense and NanoVDB; scenes/smoke_anim renders
# the .nvdb frames, and a frame from .nvdb and from .grid look the same;
# bad settings are refused with file:line:col.
# Usage: BUILD=build sh tests/integration/smoke.sh
. "$(dirname "$0")/lib.sh"
lib_init smoke
S=$BUILD/smokesim

# settings FILE FRAMES [RESOLUTION SIZE EXTENSION]: a 24x32x24 plume, dense frames
settings() {
  cat >"$1" <<JSON
{"version": 1, "resolution": ${3:-[24, 32, 24]}, "size": ${4:-1.0}, "frames": $2, "steps_per_frame": 2,
 "dt": 0.02, "buoyancy": {"alpha": 0.1, "beta": 2.0}, "confinement": 3.0,
 "source": {"center": [0.5, 0.25, 0.5], "radius": 0.12, "rate": 6.0, "temperature": 1.0, "jitter": 0.5},
 "sponge": {"width": 3, "strength": 30.0}, "seed": 5, "output": "smoke.####.${5:-grid}"}
JSON
}
same_frames() {  # DIR_A DIR_B N
  i=1
  while [ "$i" -le "$3" ]; do
    f=$(printf 'smoke.%04d.grid' "$i")
    cmp -s "$1/$f" "$2/$f" || return 1
    i=$((i + 1))
  done
}
mkdir -p "$T/a" "$T/b" "$T/c" "$T/d"
settings "$T/a/sim.json" 8
run $S "$T/a/sim.json" && [ -f "$T/a/smoke.0008.grid" ] && grep -q "done: 16 steps" "$T/log" \
  && ok "8 frames written: $(grep done "$T/log" | sed 's/.*done: //')" || bad "full run"

settings "$T/b/sim.json" 3
run $S "$T/b/sim.json" && [ -f "$T/b/smoke.0003.grid" ] && [ ! -f "$T/b/smoke.0004.grid" ] || bad "3-frame run"
settings "$T/b/sim.json" 8
run $S "$T/b/sim.json" && grep -q "resuming from .* after frame 3" "$T/log" && same_frames "$T/a" "$T/b" 8 \
  && ok "resumed after frame 3: frames 1-8 bit-identical" || bad "resume after frame 3"

settings "$T/c/sim.json" 8
$S "$T/c/sim.json" >"$T/log.c" 2>&1 &
echo $! >>"$T/pids"
pid=$!
n=0
while [ ! -f "$T/c/smoke.0002.grid" ] && [ $n -lt 600 ]; do sleep 0.05; n=$((n + 1)); done
kill -9 "$pid" 2>/dev/null
wait "$pid" 2>/dev/null
ls "$T/c" | grep -q '\.tmp\.' && rm -f "$T/c"/*.tmp.*  # a write cut short leaves only its temporary
run $S "$T/c/sim.json" && same_frames "$T/a" "$T/c" 8 \
  && ok "killed -9 ($(grep -o 'after frame [0-9]*' "$T/log" || echo 'before a checkpoint')), resumed: bit-identical" \
  || bad "resume after kill -9"

settings "$T/d/sim.json" 8
run $S "$T/d/sim.json" --threads 2 && same_frames "$T/a" "$T/d" 8 \
  && ok "2 FFTW threads: frames bit-identical to 1" || bad "threads"

# NanoVDB frames (a cubic 24^3 domain of size 2, as scenes/smoke_anim's): 1 and 2 threads
# write bit-identical .nvdb files, which the renderer reads
mkdir -p "$T/e" "$T/f" "$T/g"
settings "$T/e/sim.json" 3 "[24, 24, 24]" 2.0 grid
settings "$T/f/sim.json" 3 "[24, 24, 24]" 2.0 nvdb
settings "$T/g/sim.json" 3 "[24, 24, 24]" 2.0 nvdb
run $S "$T/e/sim.json" && run $S "$T/f/sim.json" && run $S "$T/g/sim.json" --threads 2 &&
  cmp -s "$T/f/smoke.0001.nvdb" "$T/g/smoke.0001.nvdb" && cmp -s "$T/f/smoke.0003.nvdb" "$T/g/smoke.0003.nvdb" &&
  grep -q "grids written (dense: " "$T/log" \
  && ok "nvdb frames: 1 vs 2 threads bit-identical ($(grep -o 'done: .*written (dense: [0-9]*)' "$T/log"))" \
  || bad "nvdb frames"

# scenes/smoke_anim around run f's frames, tiny: frames 1..2 with 1 and 3 workers are
# bit-identical, and the two frames differ (the plume moved); frame 3 from the dense grids
# (placed by the dense transform, scale 2.4 over the unit cube, where the .nvdb's own map
# and scale 1.2 put it) has the same mean within 0.5 % (vpt, 16 spp: the two grids'
# majorant lattices differ, so their noise is independent; measured 0.04 %, 0.07 % at 64 spp)
sed 's/"width": 128, "height": 128, "spp": 8/"width": 32, "height": 32, "spp": 4/; s/"photons": 100000/"photons": 5000/' \
  scenes/smoke_anim/smoke_anim.json >"$T/f/anim.json" && cp scenes/smoke_anim/floor.obj "$T/f/"
sed 's/smoke.####.nvdb/smoke.####.grid/; s/"scale": 1.2,/"scale": 2.4,/' "$T/f/anim.json" >"$T/e/anim.json" &&
  cp scenes/smoke_anim/floor.obj "$T/e/"
run timeout 120 $M "$T/f/anim.json" -o "$T/one.exr" --frames 1:2 --workers 1 &&
  run timeout 120 $M "$T/f/anim.json" -o "$T/three.exr" --frames 1:2 --workers 3 &&
  $X cmp "$T/one.0001.exr" "$T/three.0001.exr" >/dev/null && $X cmp "$T/one.0002.exr" "$T/three.0002.exr" >/dev/null &&
  ! $X cmp "$T/one.0001.exr" "$T/one.0002.exr" >/dev/null 2>&1 \
  && ok "scenes/smoke_anim on simulated .nvdb frames 1-2: 1 vs 3 workers bit-identical, frames differ" \
  || bad "smoke_anim render"
run timeout 120 $M "$T/f/anim.json" -o "$T/nv.exr" --frames 3:3 --workers 2 --spp 16 --media-method vpt &&
  run timeout 120 $M "$T/e/anim.json" -o "$T/de.exr" --frames 3:3 --workers 2 --spp 16 --media-method vpt &&
  a=$($X mean "$T/nv.0003.exr" | cut -d' ' -f1) && b=$($X mean "$T/de.0003.exr" | cut -d' ' -f1) &&
  awk -v a="$a" -v b="$b" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(b > 0 && d < 0.005 * b) }' \
  && ok "frame 3 from .nvdb and from .grid: means $a and $b" || bad "nvdb against dense render (means ${a:-?} ${b:-?})"

printf '{\n  "resolution": [1, 1, 1]\n}\n' >"$T/bad.json"
run $S "$T/bad.json"; rc=$?
[ $rc = 1 ] && grep -q "bad.json:2:17: \"resolution\"\[0\] must be an integer in \[8, 512\]" "$T/log" \
  && ok "1-voxel domain refused: $(cat "$T/log")" || bad "1-voxel domain (rc $rc)"
printf '{"dt": NaN}\n' >"$T/nan.json"
run $S "$T/nan.json"; rc=$?
[ $rc = 1 ] && grep -q "nan.json:1:" "$T/log" && ok "NaN refused: $(cat "$T/log")" || bad "NaN (rc $rc)"
finish
