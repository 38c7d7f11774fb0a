#!/bin/sh
# Grids that change per frame: a density file "g.####.nvdb" names one NanoVDB grid per
# frame (three 8^3 blobs that move, written by NanoVDB's own writer via make_nvdb).
# --frames 1:3 gives the same pixels for 1 and 3 workers, frames that differ, each frame
# identical to the scene naming that frame's grid directly; a worker fetches only the
# grids of the frames it renders; a changed grid re-renders its frame only; a missing
# frame's grid is an error naming the scene's file:line:col, the frame and the file,
# before anything renders; a master killed mid-range resumes with the same frames.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/framegrid.sh
. "$(dirname "$0")/lib.sh"
lib_init framegrid
N=$BUILD/make_nvdb
S="$T/s"
mkdir -p "$S" "$T/o1" "$T/o3" "$T/od" "$T/of"
cp scenes/smoke/floor.obj "$S/"
sed 's/"smoke.grid"/"g.####.nvdb"/; s/"width": 128, "height": 128/"width": 32, "height": 32/; s/"photons": 300000/"photons": 3000/' \
  scenes/smoke/smoke.json >"$S/a.json"
python3 - "$S" <<'EOF'
import math, struct, sys
n = 8
for f in (1, 2, 3):
    cx = 0.3 + 0.2 * (f - 1)  # the blob moves along x
    v = [math.exp(-((i + .5) / n - cx) ** 2 / 0.04 - ((j + .5) / n - 0.4) ** 2 / 0.04 - ((k + .5) / n - 0.5) ** 2 / 0.04)
         for k in range(n) for j in range(n) for i in range(n)]
    with open("%s/g.%04d.grid" % (sys.argv[1], f), "wb") as out:
        out.write(b"BRGRID01" + struct.pack("<III", n, n, n) + struct.pack("<%df" % len(v), *v))
EOF
r=0
for f in 1 2 3; do $N --from-grid "$S/g.000$f.grid" "$S/g.000$f.nvdb" >"$T/log" 2>&1 || r=1; rm -f "$S/g.000$f.grid"; done
[ $r = 0 ] || bad "make_nvdb --from-grid"
ARGS="--spp 2 --tile 8"

run $M "$S/a.json" -o "$T/o1/f.exr" --frames 1:3 --workers 1 --threads 1 $ARGS && r1=0 || r1=1
cp "$T/log" "$T/log1"
run $M "$S/a.json" -o "$T/o3/f.exr" --frames 1:3 --workers 3 --threads 2 $ARGS && r3=0 || r3=1
same=0
for f in 1 2 3; do $X cmp "$T/o1/f.000$f.exr" "$T/o3/f.000$f.exr" >/dev/null && same=$((same + 1)); done
if [ $r1 = 0 ] && [ $r3 = 0 ] && [ $same = 3 ] && [ "$(counter frames_done "$T/o3/f.exr")" = 3 ]; then
  ok "--frames 1:3 over g.####.nvdb: 1 vs 3 workers bit-identical"; else bad "--frames 1:3 over g.####.nvdb: 1 vs 3 workers bit-identical"; fi
if ! $X cmp "$T/o1/f.0001.exr" "$T/o1/f.0002.exr" >/dev/null 2>&1 && ! $X cmp "$T/o1/f.0002.exr" "$T/o1/f.0003.exr" >/dev/null 2>&1; then
  ok "the frames differ"; else bad "the frames differ"; fi

# Frame 2 equals the scene naming g.0002.nvdb, rendered as frame 2.
sed 's/g.####.nvdb/g.0002.nvdb/' "$S/a.json" >"$S/d.json"
run $M "$S/d.json" -o "$T/od/f.exr" --frames 2:2 --workers 1 --threads 1 $ARGS && r=0 || r=1
if [ $r = 0 ] && $X cmp "$T/o1/f.0002.exr" "$T/od/f.0002.exr"; then
  ok "frame 2 identical to the scene naming frame 2's grid"; else bad "frame 2 identical to the scene naming frame 2's grid"; fi

# One worker, frames 2:3: its first job fetches the scene's files and frame 2's grid (not
# frame 1's nor 3's); its second job fetches frame 3's grid alone (the rest is cached).
grid=$(stat -c %s "$S/g.0002.nvdb")
others=$(($(stat -c %s "$S/a.json") + $(stat -c %s "$S/floor.obj") + 4096))
run $M "$S/a.json" -o "$T/of/f.exr" --frames 2:3 --workers 1 --threads 1 $ARGS && r=0 || r=1
fetched=$(sed -n 's/.* loaded: .*; \([0-9]*\) bytes of assets fetched.*/\1/p' "$T/log" | tr '\n' ' ')
set -- $fetched
echo "framegrid: grid $grid bytes; bytes fetched per job of one worker over frames 2:3: $fetched"
if [ $r = 0 ] && [ $# = 2 ] && [ "$1" -ge "$grid" ] && [ "$1" -lt $((grid + others)) ] && [ "$2" = "$(stat -c %s "$S/g.0003.nvdb")" ]; then
  ok "a worker fetches only the grids of the frames it renders"; else bad "a worker fetches only the grids of the frames it renders"; fi

# A changed grid re-renders its frame; the others are skipped.
cp "$T/o1/f.0002.exr" "$T/f2_before.exr"
cp "$S/g.0001.nvdb" "$S/g.0002.nvdb"
run $M "$S/a.json" -o "$T/o1/f.exr" --frames 1:3 --workers 1 --threads 1 $ARGS && r=0 || r=1
if [ $r = 0 ] && [ "$(counter frames_skipped "$T/o1/f.exr")" = 2 ] && [ "$(counter frames_done "$T/o1/f.exr")" = 1 ] &&
  grep -q "frame 1: .* skipped" "$T/log" && grep -q "frame 3: .* skipped" "$T/log" &&
  ! $X cmp "$T/f2_before.exr" "$T/o1/f.0002.exr" >/dev/null 2>&1; then
  ok "a changed grid re-renders its frame only"; else bad "a changed grid re-renders its frame only"; fi

# A master killed along the way and restarted ends with the same frames: the finished
# ones skipped, the half-done one resumed from its journal (its job key covers its grid).
mkdir -p "$T/ref" "$T/kill"
KARGS="--spp 32 --tile 8"
run $M "$S/a.json" -o "$T/ref/f.exr" --frames 1:3 --workers 2 --threads 1 $KARGS && r=0 || r=1
$M "$S/a.json" -o "$T/kill/f.exr" --frames 1:3 --workers 2 --threads 1 $KARGS >"$T/klog" 2>&1 &
mpid=$!
echo $mpid >"$T/pids"
# Killed as soon as frame 1 is written, so the restart has a finished frame to skip (and,
# most times, frame 2's journal to resume from).
i=0
while [ ! -f "$T/kill/f.0001.exr" ] && [ $i -lt 3000 ] && kill -0 $mpid 2>/dev/null; do sleep 0.02; i=$((i + 1)); done
# Then until frame 2's journal holds a tile more than it was created with.
j="$T/kill/f.0002.exr.journal"
i=0
while [ ! -f "$j" ] && [ $i -lt 500 ] && kill -0 $mpid 2>/dev/null; do sleep 0.01; i=$((i + 1)); done
s0=$(stat -c %s "$j" 2>/dev/null || echo 0)
i=0
while [ "$(stat -c %s "$j" 2>/dev/null || echo 0)" = "$s0" ] && [ $i -lt 500 ] && kill -0 $mpid 2>/dev/null; do sleep 0.01; i=$((i + 1)); done
kill -9 $mpid 2>/dev/null
wait $mpid 2>/dev/null
before=$(ls "$T/kill" | grep -c '^f\.[0-9]*\.exr$')
run $M "$S/a.json" -o "$T/kill/f.exr" --frames 1:3 --workers 2 --threads 1 $KARGS || r=1
same=0
for f in 1 2 3; do $X cmp "$T/ref/f.000$f.exr" "$T/kill/f.000$f.exr" >/dev/null 2>&1 && same=$((same + 1)); done
echo "framegrid: killed master: $before frame(s) done before the restart, $(counter tiles_from_journal "$T/kill/f.exr") tile(s) from the journal"
if [ $r = 0 ] && [ $same = 3 ] && [ "$before" -ge 1 ] && [ "$before" -le 2 ] && [ "$(counter frames_skipped "$T/kill/f.exr")" = "$before" ]; then
  ok "a killed master resumes the range with the same frames"; else bad "a killed master resumes the range with the same frames"; fi

# A missing frame's grid: the scene's file:line:col, the frame and the file.
# Checked before the first frame renders: nothing is written.
mkdir -p "$T/om"
run $M "$S/a.json" -o "$T/om/f.exr" --frames 1:4 --workers 1 --threads 1 $ARGS && r=0 || r=1
if [ $r = 1 ] && grep -q "a.json:10:35: cannot read frame 4's grid \"g.0004.nvdb\"" "$T/log" && [ -z "$(ls "$T/om" | grep '\.exr$')" ]; then
  ok "a missing frame's grid: a clear error"; else bad "a missing frame's grid: a clear error"; fi
# Without --frames the scene is frame 0: g.0000.nvdb.
run $M "$S/a.json" -o "$T/o1/plain.exr" --workers 1 --threads 1 $ARGS && r=0 || r=1
if [ $r = 1 ] && grep -q "cannot read frame 0's grid \"g.0000.nvdb\"" "$T/log"; then
  ok "a render without --frames is frame 0"; else bad "a render without --frames is frame 0"; fi
finish
