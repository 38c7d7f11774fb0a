#!/bin/sh
# Strangers on the machine and odd inputs: scene files that are FIFOs are refused at once
# (never opened blocking), a signal stops a long scene load, an output name that is one of
# the scene's own files (or a preview named like the output) is refused before rendering, a
# full disk is reported as such, and the tiny scene scaled by 1e-7, 1e7, 1e-12 and 1e12 or
# moved by 1e6 and 1e7 renders as the original does; a tile that drops NaN/Inf samples is
# logged with a command that renders it alone and drops the same samples.
# Usage: BUILD=build sh tests/integration/safety.sh
. "$(dirname "$0")/lib.sh"
lib_init safety

# --- a FIFO named as a texture or as an OBJ: refused by name, file:line:col, at once ---
mkdir -p "$T/fifo"
cp scenes/tiny/* "$T/fifo/"
mkfifo "$T/fifo/pipe.png"
printf 'newmtl floor\nKd 0.5 0.5 0.5\nmap_Kd pipe.png\n\nnewmtl box\nKd 0.7 0.3 0.2\n' >"$T/fifo/tiny.mtl"
TMO=20 run $M "$T/fifo/tiny.json" -o "$T/fifo.exr" && r=0 || r=$?
if [ $r = 1 ] && grep -qE "tiny\.mtl:3:[0-9]+: .*pipe\.png: not a regular file \(a FIFO\)" "$T/log" && [ ! -e "$T/fifo.exr" ]; then
  ok "FIFO as a texture refused at once, named with file:line:col"; else bad "FIFO as a texture refused at once, named with file:line:col (rc $r)"; fi
cp scenes/tiny/tiny.mtl "$T/fifo/"
rm "$T/fifo/tiny.obj"
mkfifo "$T/fifo/tiny.obj"
TMO=20 run $M "$T/fifo/tiny.json" -o "$T/fifo.exr" && r=0 || r=$?
if [ $r = 1 ] && grep -qE "tiny\.json:[0-9]+:[0-9]+: .*tiny\.obj: not a regular file \(a FIFO\)" "$T/log"; then
  ok "FIFO as an OBJ refused at once, named with file:line:col"; else bad "FIFO as an OBJ refused at once, named with file:line:col (rc $r)"; fi
# a FIFO where a frame's output would be (--frames reads an existing output to skip it): not
# opened blocking (which not even SIGTERM ended), rendered again and replaced by the EXR
mkfifo "$T/ff.0001.exr"
timeout -k 5 30 $M scenes/tiny/tiny.json -o "$T/ff.exr" --frames 1:1 >"$T/log" 2>&1 && r=0 || r=$?
if [ $r = 0 ] && [ -f "$T/ff.0001.exr" ] && grep -q "not a regular file" "$T/log"; then
  ok "a FIFO named like a frame's output: not waited on, rendered again"; else bad "a FIFO named like a frame's output: not waited on, rendered again (rc $r)"; fi

# --- SIGTERM during a long scene load (thousands of objects naming one long OBJ) stops it
# there, with the error line of an interrupted run ---
mkdir -p "$T/slow"
python3 - "$T/slow" <<'PY'
import json, sys
d = sys.argv[1]
open(d + '/long.obj', 'w').write('#\n' * 400000 + 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n')
objs = [{'type': 'obj', 'file': 'long.obj', 'material': 'm'} for i in range(20000)]
json.dump({'version': 1, 'camera': {'position': [0, 0, 5], 'look_at': [0, 0, 0], 'fov_y': 40},
           'render': {'width': 8, 'height': 8},
           'materials': {'m': {'type': 'diffuse', 'albedo': [0.5, 0.5, 0.5]}}, 'objects': objs}, open(d + '/slow.json', 'w'))
PY
timeout 300 $M "$T/slow/slow.json" -o "$T/slow.exr" >"$T/log" 2>&1 &
mp=$!
echo $mp >>"$T/pids"
sleep 1
kill -TERM $mp 2>/dev/null
wait $mp && r=0 || r=$?
if [ $r = 1 ] && tail -1 "$T/log" | grep -qE "^master: error: .*long\.obj:[0-9]+:[0-9]+: interrupted" && [ ! -e "$T/slow.exr" ]; then
  ok "SIGTERM during the scene load stops it, exit 1, interrupted"; else bad "SIGTERM during the scene load stops it, exit 1, interrupted (rc $r)"; fi
rm -rf "$T/slow"

# --- -o naming one of the scene's own files: refused before rendering, the file unchanged ---
mkdir -p "$T/own"
cp scenes/tiny/* "$T/own/"
for f in tiny.json tiny.obj; do
  sum=$(md5sum <"$T/own/$f")
  run $M "$T/own/tiny.json" -o "$T/own/$f" && r=0 || r=$?
  if [ $r = 1 ] && grep -q "refusing to overwrite" "$T/log" && [ "$(md5sum <"$T/own/$f")" = "$sum" ]; then
    ok "-o $f refused, the file unchanged"; else bad "-o $f refused, the file unchanged (rc $r)"; fi
done
# the same through another name (a hard link: same inode), as the preview, as a frame's name
# and as the stats file
ln "$T/own/tiny.mtl" "$T/own/link.png"
sum=$(md5sum <"$T/own/tiny.mtl")
run $M "$T/own/tiny.json" -o "$T/own/x.exr" --preview "$T/own/link.png" && r=0 || r=$?
if [ $r = 1 ] && grep -q "refusing to overwrite" "$T/log" && [ "$(md5sum <"$T/own/tiny.mtl")" = "$sum" ] && [ ! -e "$T/own/x.exr" ]; then
  ok "--preview onto an input (hard link) refused"; else bad "--preview onto an input (hard link) refused (rc $r)"; fi
cp "$T/own/lamp.obj" "$T/own/f.0007.exr"
sed 's/"lamp.obj"/"f.0007.exr"/' scenes/tiny/tiny.json >"$T/own/frames.json"
sum=$(md5sum <"$T/own/f.0007.exr")
run $M "$T/own/frames.json" -o "$T/own/f.exr" --frames 1:1000000 && r=0 || r=$?
if [ $r = 1 ] && grep -q "refusing to overwrite" "$T/log" && [ "$(md5sum <"$T/own/f.0007.exr")" = "$sum" ] && [ ! -e "$T/own/f.0001.exr" ]; then
  ok "a frame of a range named like an input refused before frame 1"; else bad "a frame of a range named like an input refused before frame 1 (rc $r)"; fi
# --preview naming the EXR itself (through another spelling, or per frame of a range): refused
# before rendering, so the PNG does not replace the image
for args in "-o $T/own/p.exr --preview $T/own/./p.exr" "-o $T/own/q.exr --preview $T/own/q.exr --frames 1:2"; do
  run $M "$T/own/tiny.json" $args && r=0 || r=$?
  if [ $r = 1 ] && grep -q "refusing to write over" "$T/log" && [ ! -e "$T/own/p.exr" ] && [ ! -e "$T/own/q.0001.exr" ]; then
    ok "--preview onto the output refused ($args)"; else bad "--preview onto the output refused ($args) (rc $r)"; fi
done
# -o naming a folder (the final rename cannot replace it): refused before rendering, no journal
mkdir -p "$T/own/dir.exr"
run $M "$T/own/tiny.json" -o "$T/own/dir.exr" && r=0 || r=$?
if [ $r = 1 ] && grep -q "is a folder" "$T/log" && [ ! -e "$T/own/dir.exr.journal" ]; then
  ok "-o naming a folder refused before rendering"; else bad "-o naming a folder refused before rendering (rc $r)"; fi
# an empty -o: refused at once, no ".stats.json" left where the master runs
mkdir -p "$T/empty"
mabs="$(cd "$(dirname "$M")" && pwd)/$(basename "$M")"
sabs="$(pwd)/scenes/tiny/tiny.json"
(cd "$T/empty" && timeout 60 "$mabs" "$sabs" -o "" >"$T/log" 2>&1) && r=0 || r=$?
if [ $r = 2 ] && grep -q "output name is empty" "$T/log" && [ -z "$(ls -A "$T/empty")" ]; then
  ok "an empty -o refused, nothing written"; else bad "an empty -o refused, nothing written (rc $r)"; fi
cp scenes/tiny/lamp.obj "$T/own/s.stats.json"
sed 's/"lamp.obj"/"s.stats.json"/' scenes/tiny/tiny.json >"$T/own/stats.json"
sum=$(md5sum <"$T/own/s.stats.json")
run $M "$T/own/stats.json" -o "$T/own/s" && r=0 || r=$?
if [ $r = 1 ] && grep -q "refusing to overwrite" "$T/log" && [ "$(md5sum <"$T/own/s.stats.json")" = "$sum" ]; then
  ok "a stats name that is an input: refused and left alone"; else bad "a stats name that is an input: refused and left alone (rc $r)"; fi

# --- a full disk: the first cause, "No space left on device", with the file name ---
mnt="$T/mnt"
mkdir -p "$mnt"
if mount -t tmpfs -o size=64k tmpfs "$mnt" 2>/dev/null; then
  seen=0
  for fill in 40 44 48 52 56 60; do
    rm -rf "$mnt"/*
    dd if=/dev/zero of="$mnt/fill" bs=1k count=$fill 2>/dev/null
    run $M scenes/tiny/tiny.json -o "$mnt/o.exr" && r=0 || r=$?
    [ $r = 0 ] && continue
    seen=$((seen + 1))
    if ! tail -1 "$T/log" | grep -qE "^master: error: $mnt/o\.exr[^ ]*: .*No space left on device$" || [ -e "$mnt/o.exr" ]; then
      seen=-100
      cp "$T/log" "$T/full.log"
    fi
  done
  umount "$mnt"
  if [ $seen -gt 0 ]; then ok "full disk reported as No space left on device, with the file ($seen fill levels)"
  else BAD_LOGS=full.log bad "full disk reported as No space left on device, with the file"; fi
else
  echo "skip: full disk (cannot mount a tmpfs here)"
fi

# --- a read-only output folder with --no-journal: refused before any tile is rendered ---
ro="$T/ro"
mkdir -p "$ro"
if mount -t tmpfs -o ro,size=64k tmpfs "$ro" 2>/dev/null; then
  run $M scenes/tiny/tiny.json -o "$ro/o.exr" --no-journal && r=0 || r=$?
  umount "$ro"
  if [ $r != 0 ] && tail -1 "$T/log" | grep -qE "^master: error: $ro/o\.exr\.tmp\.[0-9]+: .*Read-only file system$" &&
     ! grep -q "rendered [1-9]" "$T/log"; then
    ok "read-only output folder refused before rendering: $(tail -1 "$T/log")"
  else bad "read-only output folder refused before rendering (rc $r)"; fi
else
  echo "skip: read-only output folder (cannot mount a tmpfs here)"
fi

# --- a point light at 3.4e38 in the smoke scene (coordinates may lie anywhere a float
# reaches): rays from it pass Embree's bound on a ray (about 1.8e18), which Debian's Embree
# asserts; they are not traced, so the photon pass (beam) and the workers (vpt) go on ---
mkdir -p "$T/far"
cp scenes/smoke/* "$T/far/"
for method in beam vpt; do
  python3 - "$method" scenes/smoke/smoke.json >"$T/far/far.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[2]))
s["render"].update(width=16, height=12, spp=1, tile_size=8)
s["volume"].update(method=sys.argv[1], photons=2000)
s["lights"][0]["position"] = [3.4e38, 3.5, -1.5]
json.dump(s, sys.stdout)
PY
  run $M "$T/far/far.json" -o "$T/far-$method.exr" --no-journal && r=0 || r=$?
  if [ $r = 0 ] && [ -f "$T/far-$method.exr" ] && ! grep -q "Assertion" "$T/log"; then
    ok "a point light at 3.4e38 ($method): renders, no Embree assertion"
  else bad "a point light at 3.4e38 ($method): renders, no Embree assertion (rc $r)"; fi
done

# --- emission 1e30: the sample variance passes float's range; the render is the scene's,
# not a lying worker's: it completes, the variance channels saturate, the summary says so ---
mkdir -p "$T/hot"
cp scenes/tiny/* "$T/hot/"
sed 's/"emission": \[8, 8, 8\]/"emission": [1e30, 1e30, 1e30]/' scenes/tiny/tiny.json >"$T/hot/tiny.json"
run $M "$T/hot/tiny.json" -o "$T/hot.exr" --no-journal && r=0 || r=$?
hm=$($X mean "$T/hot.exr" 2>/dev/null | cut -d' ' -f1)
if [ $r = 0 ] && grep -q "lower bound" "$T/log" && ! grep -qE "tile [0-9]+ rejected|banned" "$T/log" &&
   python3 -c 'import math, sys; v = float(sys.argv[1]); sys.exit(not (math.isfinite(v) and v > 1e26))' "${hm:-nan}"; then
  ok "emission 1e30 renders (mean $hm), variance saturated and said to be a lower bound, no worker banned"
else bad "emission 1e30 renders, variance saturated, no worker banned (rc $r, mean ${hm:-?})"; fi

# --- "photons": 4294967296 (the documented maximum): refused before tracing, from a pilot ---
TMO=60 run $M scenes/fog_spot/fog_spot.json -o "$T/big.exr" --no-journal --spp 2 --photons 4294967296 && r=0 || r=$?
if [ $r != 0 ] && tail -1 "$T/log" | grep -q "^master: error: volume.photons 4294967296 .* more than the budget" &&
   ! grep -q "photon map 0 of" "$T/log" && [ ! -e "$T/big.exr" ]; then
  ok "4294967296 photons refused before tracing: $(tail -1 "$T/log" | cut -c1-120)..."
else bad "4294967296 photons refused before tracing (rc $r)"; fi
run $M scenes/fog_spot/fog_spot.json -o "$T/small.exr" --no-journal --spp 1 --photons 20000 --photon-memory 0.000001 && r=0 || r=$?
if [ $r != 0 ] && tail -1 "$T/log" | grep -q "more than the budget"; then
  ok "--photon-memory sets the budget"; else bad "--photon-memory sets the budget (rc $r)"; fi

# --- a lone local worker stopped (SIGSTOP) longer than --worker-timeout-ms: evicted, ended
# and started again by the master; the image is the one an undisturbed run gives ---
SA="--spp 16 --no-journal --workers 1 --threads 2"
run $M scenes/cornell/cornell.json -o "$T/nostop.exr" $SA && r0=0 || r0=1
timeout 120 $M scenes/cornell/cornell.json -o "$T/stop.exr" $SA --worker-timeout-ms 1500 >"$T/stop.log" 2>&1 &
mpid=$!
echo $mpid >"$T/pids"
wpid="" i=0
while [ -z "$wpid" ] && [ $i -lt 100 ]; do
  wpid=$(sed -n 's/.*worker [^ ]*:\([0-9][0-9]*\) joined.*/\1/p' "$T/stop.log" | head -1)
  i=$((i + 1)); sleep 0.1
done
[ -n "$wpid" ] && kill -STOP "$wpid" 2>/dev/null
wait $mpid && r=0 || r=1
if [ $r0 = 0 ] && [ $r = 0 ] && [ -n "$wpid" ] && grep -q "started again" "$T/stop.log" && $X cmp "$T/nostop.exr" "$T/stop.exr"; then
  ok "a lone local worker stopped: evicted, started again, identical image ($(grep -c 'started again' "$T/stop.log") restart(s))"
else cp "$T/stop.log" "$T/log"; bad "a lone local worker stopped: evicted, started again, identical image (rc $r, worker ${wpid:-?})"; fi
[ -n "$wpid" ] && kill -KILL "$wpid" 2>/dev/null

# --- the tiny scene scaled by 1e-7, 1e7, 1e-12 and 1e12 renders as the original (same
# samples, so the difference must stay far below the image's own noise estimate; at 1e12
# and 1e-12 a triangle's cross product squared leaves float's range: its normal and area) ---
run $M scenes/tiny/tiny.json -o "$T/base.exr" --spp 16 && r=0 || r=1
noise=$($X errest "$T/base.exr" 2>/dev/null)
for s in 1e-7 1e7 1e-12 1e12; do
  python3 scripts/scene_variant.py scenes/tiny "$T/s$s" $s 0 0 0
  run $M "$T/s$s/tiny.json" -o "$T/s$s.exr" --spp 16 && r2=0 || r2=1
  rel=$($X relrmse "$T/s$s.exr" "$T/base.exr" 2>/dev/null)
  if [ $r = 0 ] && [ $r2 = 0 ] && python3 -c 'import sys; sys.exit(not (float(sys.argv[1]) < 0.1 * float(sys.argv[2])))' "$rel" "$noise"; then
    ok "tiny scaled by $s: relRMSE $rel against the original, noise $noise"; else bad "tiny scaled by $s: relRMSE $rel against the original, noise $noise"; fi
done
# --- and moved by 1e6 and 1e7 along every axis (rendered relative to the camera) ---
for t in 1e6 1e7; do
  python3 scripts/scene_variant.py scenes/tiny "$T/t$t" 1 $t $t -$t
  run $M "$T/t$t/tiny.json" -o "$T/t$t.exr" --spp 16 && r2=0 || r2=1
  rel=$($X relrmse "$T/t$t.exr" "$T/base.exr" 2>/dev/null)
  if [ $r = 0 ] && [ $r2 = 0 ] && python3 -c 'import sys; sys.exit(not (float(sys.argv[1]) < 0.1 * float(sys.argv[2])))' "$rel" "$noise"; then
    ok "tiny moved by $t: relRMSE $rel against the original, noise $noise"; else bad "tiny moved by $t: relRMSE $rel against the original, noise $noise"; fi
done

# --- NaN/Inf samples: each tile that dropped some is logged with the command that renders
# it alone, and that command drops exactly the same samples (design principle 4) ---
mkdir -p "$T/nan"
cat >"$T/nan/nan.json" <<'EOF'
{
  "version": 1,
  "camera": {"position": [0, 1, 0], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov_y": 60},
  "render": {"width": 32, "height": 32, "spp": 8, "max_depth": 2, "seed": 3, "tile_size": 16},
  "materials": {"floor": {"type": "diffuse", "albedo": [0.5, 0.5, 0.5]}},
  "objects": [{"type": "sphere", "center": [0, -100, 0], "radius": 100, "material": "floor"}],
  "lights": [{"type": "point", "position": [0.3, 0.01, 0.3], "intensity": [3e38, 3e38, 3e38]}]
}
EOF
run $M "$T/nan/nan.json" -o "$T/nan.exr" --workers 1 --spp 4 --passes 2 --seed 5 && r=0 || r=1
# the last tile logged: its count and its command
line=$(grep "NaN/Inf sample(s) dropped; to render" "$T/log" | tail -1)
want=$(printf '%s\n' "$line" | sed -n 's/.*): \([0-9]*\) NaN\/Inf sample(s) dropped.*/\1/p')
cmd=$(printf '%s\n' "$line" | sed -n 's/.*the scene): //p')
got=""
if [ -n "$cmd" ]; then
  TMO=60 run sh -c "$cmd" && got=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["nan_samples"])' \
    "$(printf '%s\n' "$cmd" | sed -n 's/.* -o \([^ ]*\) .*/\1/p').stats.json" 2>/dev/null)
fi
echo "safety: NaN tile: logged $want NaN/Inf sample(s), its command drops ${got:-?}: $cmd"
if [ $r = 0 ] && [ -n "$want" ] && [ "$want" -gt 0 ] && [ "$got" = "$want" ] &&
  printf '%s\n' "$cmd" | grep -q -- "--spp 4 --passes 2 --seed 5 .*--tiles [0-9]"; then
  ok "NaN/Inf samples logged per tile with a command that drops the same $want samples again"
else bad "NaN/Inf samples logged per tile with a command that drops the same samples again (logged ${want:-none}, again ${got:-?})"; fi

finish
