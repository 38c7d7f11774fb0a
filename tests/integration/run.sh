#!/bin/sh
# Multi-process integration tests: a master and workers on this machine (ipc and tcp
# loopback), each step bounded by a timeout. Ends with "integration: N passed, N failed".
# Usage: BUILD=build sh tests/integration/run.sh
. "$(dirname "$0")/lib.sh"
lib_init it
port() { free_port; }

# --- help and command-line errors ---
if run $M --help && grep -q "usage: master" "$T/log"; then ok "master --help"; else bad "master --help"; fi
if run $W --help && grep -q "usage: worker" "$T/log"; then ok "worker --help"; else bad "worker --help"; fi
if ! run $M scenes/tiny/tiny.json && grep -q "error: .*-o" "$T/log"; then ok "missing -o is an error"; else bad "missing -o is an error"; fi
if ! run $M scenes/tiny/tiny.json -o "$T/x.exr" --spp abc && grep -q -- "--spp" "$T/log"; then ok "bad number named"; else bad "bad number named"; fi
if ! run $M "$T/none.json" -o "$T/x.exr" && grep -q "none.json" "$T/log" && [ ! -e "$T/x.exr" ]; then
  ok "missing scene file named, no output"; else bad "missing scene file named, no output"; fi

# --- a scene error names file:line:col ---
mkdir -p "$T/bad"
printf '{\n  "version": 1,\n  "camera": {"position": [0,0,5], "look_at": [0,0,0], "fov_yy": 40},\n  "render": {"width": 8, "height": 8}\n}\n' >"$T/bad/bad.json"
if ! run $M "$T/bad/bad.json" -o "$T/bad.exr" && grep -qE "bad.json:3:[0-9]+: .*fov_yy" "$T/log"; then
  ok "unknown key reported as file:line:col"; else bad "unknown key reported as file:line:col"; fi

# --- a failed run ends with its one error line: all of stderr, nothing after it, nothing on
# stdout; its stats file says it failed ---
printf '{\n  "version": 1,\n  "camera": {"position": [0,0,5],, "fov": 40}\n}\n' >"$T/bad/syntax.json"
for sc in syntax bad; do
  timeout 60 $M "$T/bad/$sc.json" -o "$T/$sc.exr" --workers 1 >"$T/out" 2>"$T/err" && r=0 || r=1
  cp "$T/err" "$T/log"
  if [ $r = 1 ] && [ "$(wc -l <"$T/err")" = 1 ] && grep -qE "^master: error: .*$sc\.json:3:[0-9]+: " "$T/err" &&
    [ ! -s "$T/out" ] && python3 -c 'import json, sys; sys.exit(json.load(open(sys.argv[1]))["ok"] is not False)' "$T/$sc.exr.stats.json"; then
    ok "$sc.json: one error line (file:line:col), last, nothing else"; else bad "$sc.json: one error line (file:line:col), last, nothing else"; fi
done

# --- tiny scene: 1 worker vs 3 workers, other threads and tile sizes: identical pixels ---
run $M scenes/tiny/tiny.json -o "$T/t1.exr" --workers 1 --threads 1 && r1=0 || r1=1
run $M scenes/tiny/tiny.json -o "$T/t3.exr" --workers 3 --threads 2 && r3=0 || r3=1
if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/t1.exr" "$T/t3.exr"; then ok "tiny: 1 vs 3 workers bit-identical"; else bad "tiny: 1 vs 3 workers bit-identical"; fi
run $M scenes/tiny/tiny.json -o "$T/t16.exr" --workers 2 --tile 8 && r=0 || r=1
if [ $r = 0 ] && $X cmp "$T/t1.exr" "$T/t16.exr"; then ok "tiny: tile size 8 vs default bit-identical"; else bad "tiny: tile size 8 vs default bit-identical"; fi
run $M scenes/tiny/tiny.json -o "$T/s2.exr" --workers 1 --seed 12345 && r=0 || r=1
if [ $r = 0 ] && ! $X cmp "$T/t1.exr" "$T/s2.exr" >/dev/null; then ok "tiny: another seed gives other pixels"; else bad "tiny: another seed gives other pixels"; fi

# --- Cornell box: 1 vs 3 workers bit-identical; output is a tiled EXR an independent reader accepts ---
run $M scenes/cornell/cornell.json -o "$T/c1.exr" --workers 1 --spp 4 --preview "$T/c1.png" && r1=0 || r1=1
cp "$T/log" "$T/c1.log"
run $M scenes/cornell/cornell.json -o "$T/c3.exr" --workers 3 --threads 1 --spp 4 --tile 48 && r3=0 || r3=1
if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/c1.exr" "$T/c3.exr"; then ok "cornell: 1 vs 3 workers bit-identical"; else bad "cornell: 1 vs 3 workers bit-identical"; fi
if exrheader "$T/c1.exr" >"$T/hdr" 2>&1 && grep -qi "tiledesc" "$T/hdr" && grep -q "brume_spp" "$T/hdr"; then
  ok "exrheader reads a tiled EXR with our attributes"; else cp "$T/hdr" "$T/log"; bad "exrheader reads a tiled EXR with our attributes"; fi
if command -v exrcheck >/dev/null 2>&1; then
  if exrcheck "$T/c1.exr" >"$T/log" 2>&1; then ok "exrcheck accepts the file"; else bad "exrcheck accepts the file"; fi
fi
if head -c 8 "$T/c1.png" | od -An -c | grep -q "P   N   G"; then ok "PNG preview written"; else bad "PNG preview written"; fi
if grep -q "summary: wall" "$T/c1.log" && grep -q "Mrays/s" "$T/c1.log" && grep -q "NaN/Inf samples dropped: 0" "$T/c1.log" &&
  grep -q "relative standard error" "$T/c1.log"; then ok "summary reports speed, NaNs and noise"; else cp "$T/c1.log" "$T/log"; bad "summary reports speed, NaNs and noise"; fi

# --- --embree-isa: the job fixes Embree's kernels on every worker. Another instruction set
# gives other pixels (its kernels' hits differ in the last bits), one set the same pixels on
# any workers, and the set is part of the scene hash journals and --frames match ---
run $M scenes/cornell/cornell.json -o "$T/i1.exr" --workers 1 --spp 4 --embree-isa sse4.2 && r1=0 || r1=1
run $M scenes/cornell/cornell.json -o "$T/i3.exr" --workers 3 --threads 1 --spp 4 --tile 48 --embree-isa sse4.2 && r3=0 || r3=1
if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/i1.exr" "$T/i3.exr" && ! $X cmp "$T/c1.exr" "$T/i1.exr" >/dev/null &&
  python3 -c 'import json, sys; a, b = (json.load(open(f))["scene_hash"] for f in sys.argv[1:]); sys.exit(a == b)' \
    "$T/c1.exr.stats.json" "$T/i1.exr.stats.json"; then
  ok "--embree-isa sse4.2: other pixels and scene hash than avx2, 1 vs 3 workers bit-identical"
else bad "--embree-isa sse4.2: other pixels and scene hash than avx2, 1 vs 3 workers bit-identical"; fi
if ! run $M scenes/tiny/tiny.json -o "$T/x.exr" --embree-isa avx9 && grep -q -- "--embree-isa: .*avx9" "$T/log"; then
  ok "unknown --embree-isa named"; else bad "unknown --embree-isa named"; fi

# --- counters: not on screen by default; in OUT.stats.json, valid JSON that matches the
# "summary: counter" lines of --verbose and what the run did ---
run $M scenes/tiny/tiny.json -o "$T/v.exr" --workers 2 --threads 1 --verbose && r=0 || r=1
if [ $r = 0 ] && ! grep -q "summary: counter" "$T/c1.log" && python3 - "$T/v.exr.stats.json" "$T/log" <<'EOF'
import json, re, sys
st = json.load(open(sys.argv[1]))
shown = dict(re.findall(r"^summary: counter (\w+) (\d+)$", open(sys.argv[2]).read(), re.M))
c = st["counters"]
assert st["ok"] is True and st["error"] is None and st["output"].endswith("v.exr")
assert len(shown) >= 30 and {k: str(v) for k, v in c.items()} == shown, (c, shown)
units = st["tiles"] * st["passes"]  # the units are (tile, pass) pairs
assert st["tiles"] > 0 and st["passes"] >= 1 and c["tiles_done"] == units and c["tiles_assigned"] >= units
assert sum(w["tiles"] for w in st["workers"]) == units and c["workers_joined"] == len(st["workers"]) >= 1
assert st["samples"] > 0 and "wall_seconds" in st and "mean_rel_stderr" in st and st["nan_samples"] == 0
EOF
then ok "stats JSON written, counters match --verbose and the run; none on screen by default"
else bad "stats JSON written, counters match --verbose and the run; none on screen by default"; fi
ls "$T" | grep -q "\.tmp\." && bad "no temporary files left" || ok "no temporary files left"

# --- a remote worker over tcp loopback (master starts none) gives the same pixels ---
P=$(port)
timeout 60 $M scenes/tiny/tiny.json -o "$T/r.exr" --workers 0 --bind "tcp://127.0.0.1:$P" --insecure >"$T/log" 2>&1 &
mpid=$!
sleep 0.3
timeout 60 $W --connect "tcp://127.0.0.1:$P" --threads 2 >"$T/wlog" 2>&1
wait $mpid && r=0 || r=1
if [ $r = 0 ] && $X cmp "$T/t1.exr" "$T/r.exr"; then ok "remote tcp worker gives identical pixels"; else bad "remote tcp worker gives identical pixels"; fi

# --- a worker killed mid-render: its tiles are re-queued, the image is unchanged ---
run $M scenes/cornell/cornell.json -o "$T/k.exr" --workers 3 --threads 1 --spp 4 --tile 16 &
bg=$!
sleep 0.5
# Only this render's workers (descendants of $bg), never another run's on this machine.
descends() { q=$1; while [ "$q" -gt 1 ] 2>/dev/null; do [ "$q" = "$2" ] && return 0; q=$(awk '{print $4}' /proc/$q/stat 2>/dev/null || echo 0); done; return 1; }
victim=
for w in $(pgrep -f "$W --connect ipc://"); do if descends "$w" $bg; then victim=$w; break; fi; done
[ -n "$victim" ] && kill -9 "$victim"
wait $bg && r=0 || r=1
if [ -n "$victim" ] && [ $r = 0 ] && $X cmp "$T/c1.exr" "$T/k.exr"; then ok "killed worker: tiles re-queued, identical pixels"; else bad "killed worker: tiles re-queued, identical pixels"; fi

# --- a hostile peer: garbage, wrong versions, results for tiles it never got: dropped, image unchanged ---
P=$(port)
run $M scenes/cornell/cornell.json -o "$T/j0.exr" --workers 2 --threads 1 --spp 12 && r0=0 || r0=1
timeout 60 $M scenes/cornell/cornell.json -o "$T/j.exr" --workers 1 --spp 12 --bind "tcp://127.0.0.1:$P" --insecure >"$T/log" 2>&1 &
mpid=$!
sleep 0.3
timeout 20 $BUILD/junkpeer "tcp://127.0.0.1:$P" >/dev/null 2>&1
wait $mpid && r=0 || r=1
if [ $r0 = 0 ] && [ $r = 0 ] && $X cmp "$T/j0.exr" "$T/j.exr" && grep -q "version 99" "$T/log" && grep -q "malformed envelope" "$T/log" &&
  grep -q "junk?peer:1: RESULT for job" "$T/log" && grep -q "further dropped messages are counted" "$T/log" &&
  ! grep -q "stale or rejected results: 0" "$T/log"; then ok "hostile peer: messages dropped, identical pixels"; else bad "hostile peer: messages dropped, identical pixels"; fi

# --- depth of field (thin lens, hexagonal aperture): 1 vs 3 workers bit-identical, per sampler ---
for smp in sobol stratified independent; do
  run $M scenes/dof/dof.json -o "$T/dof1-$smp.exr" --workers 1 --threads 1 --sampler $smp && r1=0 || r1=1
  run $M scenes/dof/dof.json -o "$T/dof3-$smp.exr" --workers 3 --threads 2 --tile 8 --sampler $smp && r3=0 || r3=1
  if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/dof1-$smp.exr" "$T/dof3-$smp.exr"; then
    ok "dof ($smp): 1 vs 3 workers bit-identical"; else bad "dof ($smp): 1 vs 3 workers bit-identical"; fi
done
if ! $X cmp "$T/dof1-sobol.exr" "$T/dof1-stratified.exr" >/dev/null 2>&1; then ok "dof: --sampler changes the pattern"; else bad "dof: --sampler changes the pattern"; fi
if ! run $M scenes/dof/dof.json -o "$T/x.exr" --sampler halton && grep -q "unknown sampler" "$T/log"; then
  ok "unknown --sampler is an error"; else bad "unknown --sampler is an error"; fi

# --- object motion (rigid keys, deformation frames, a moving sphere) and a mirror: 1 vs 3 workers bit-identical ---
run $M scenes/motion/motion.json -o "$T/mo1.exr" --workers 1 --threads 1 && r1=0 || r1=1
run $M scenes/motion/motion.json -o "$T/mo3.exr" --workers 3 --threads 2 --tile 8 && r3=0 || r3=1
if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/mo1.exr" "$T/mo3.exr" && grep -q "NaN/Inf samples dropped: 0" "$T/log"; then
  ok "motion: 1 vs 3 workers bit-identical"; else bad "motion: 1 vs 3 workers bit-identical"; fi

# --- defocus and motion blur together (thin lens, trapezoid shutter, moving objects, glass) ---
run $M scenes/dof_motion/dof_motion.json -o "$T/dm1.exr" --workers 1 --threads 1 && r1=0 || r1=1
run $M scenes/dof_motion/dof_motion.json -o "$T/dm3.exr" --workers 3 --threads 2 --tile 8 && r3=0 || r3=1
if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/dm1.exr" "$T/dm3.exr"; then
  ok "dof + motion: 1 vs 3 workers bit-identical"; else bad "dof + motion: 1 vs 3 workers bit-identical"; fi

finish
