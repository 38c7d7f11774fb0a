#!/bin/sh
# smokesim (docs/smoke.md): a run cut short (by its frame count, then by kill -9 part way)
# and resumed from its checkpoint writes frames bit-identical to a run that never stopped;
# 2 FFTW threads write the same frames as 1; scenes/smoke_anim renders the frames;
# bad settings are refused with file:line:col.
# Usage: BUILD=build sh tests/integration/smoke.sh
. "$(dirname "$0")/lib.sh"
lib_init smoke
S=$BUILD/smokesim

# settings FILE FRAMES: a 24^3 plume
settings() {
  cat >"$1" <<JSON
{"version": 1, "resolution": [24, 32, 24], "size": 1.0, "frames": $2, "steps_per_frame": 2,
 "dt": 0.02, "buoyancy": {"alpha": 0.1, "beta": 2.0}, "confinement": 3.0,
 "source": {"center": [0.5, 0.25, 0.5], "radius": 0.12, "rate": 6.0, "temperature": 1.0, "jitter": 0.5},
 "sponge": {"width": 3, "strength": 30.0}, "seed": 5, "output": "smoke.####.grid"}
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

# scenes/smoke_anim around run a's frames, tiny: frames 1..2 with 1 and 3 workers are
# bit-identical, and the two frames differ (the plume moved)
sed 's/"width": 128, "height": 128, "spp": 8/"width": 32, "height": 32, "spp": 2/; s/"photons": 100000/"photons": 5000/' \
  scenes/smoke_anim/smoke_anim.json >"$T/a/anim.json" && cp scenes/smoke_anim/floor.obj "$T/a/"
run timeout 120 $M "$T/a/anim.json" -o "$T/one.exr" --frames 1:2 --workers 1 &&
  run timeout 120 $M "$T/a/anim.json" -o "$T/three.exr" --frames 1:2 --workers 3 &&
  $X cmp "$T/one.0001.exr" "$T/three.0001.exr" >/dev/null && $X cmp "$T/one.0002.exr" "$T/three.0002.exr" >/dev/null &&
  ! $X cmp "$T/one.0001.exr" "$T/one.0002.exr" >/dev/null 2>&1 \
  && ok "scenes/smoke_anim on simulated frames 1-2: 1 vs 3 workers bit-identical, frames differ" || bad "smoke_anim render"

printf '{\n  "resolution": [1, 1, 1]\n}\n' >"$T/bad.json"
run $S "$T/bad.json"; rc=$?
[ $rc = 1 ] && grep -q "bad.json:2:17: \"resolution\"\[0\] must be an integer in \[8, 512\]" "$T/log" \
  && ok "1-voxel domain refused: $(cat "$T/log")" || bad "1-voxel domain (rc $rc)"
printf '{"dt": NaN}\n' >"$T/nan.json"
run $S "$T/nan.json"; rc=$?
[ $rc = 1 ] && grep -q "nan.json:1:" "$T/log" && ok "NaN refused: $(cat "$T/log")" || bad "NaN (rc $rc)"
finish
