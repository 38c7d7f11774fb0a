#!/bin/sh
# Adaptive rendering to a target error (docs/adaptive.md): the same --target-error run
# with 1 and 3 workers (and another tile order) is bit-identical, with tiles of 8 px (2x2
# blocks) and 32 px (8x8 blocks), units rendering some 4x4 blocks of a tile (each block then
# the uniform render of its passes); a master killed with
# kill -9 after round 0 and restarted resumes from its journal to identical pixels; the
# samples channel sums to the samples the run reports; a --time-limit run records its
# rounds and --max-rounds reproduces it; passes apply to a scene without photon maps; plain
# renders default to one pass per stream; a tile's m passes are the uniform render with m
# passes; a scene of uniform noise renders uniform passes (the fallback), the uniform
# render of as many passes; --pixel-error P (alone, and with a target in the kill test):
# 1 vs 3 workers bit-identical, every pixel not at the cap within P, more samples where
# round 0 saw a pixel above P; with a photon map, only the maps its passes use are traced.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/adaptive.sh
. "$(dirname "$0")/lib.sh"
lib_init adaptive
S=scenes/tiny/tiny.json
AD="--target-error 0.03 --tile 8 --spp 2048"
samples() { python3 -c 'import json, sys; print(json.load(open(sys.argv[1] + ".stats.json"))["samples"])' "$1" 2>/dev/null; }

run $M $S -o "$T/a1.exr" $AD --no-journal --workers 1 --threads 1 && r1=0 || r1=1
cp "$T/log" "$T/a1.log"
run $M $S -o "$T/a3.exr" $AD --no-journal --workers 3 --threads 2 && r3=0 || r3=1
est=$(sed -n 's/^summary: adaptive: target relRMSE [0-9.]*, estimated \([0-9.]*\).*/\1/p' "$T/a1.log")
if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/a1.exr" "$T/a3.exr" && [ -n "$est" ] &&
   awk -v e="$est" 'BEGIN { exit !(e <= 0.03 && e > 0) }' && grep -q "spp min [0-9]* mean [0-9.]* max" "$T/a1.log"; then
  ok "target 0.03: 1 vs 3 workers bit-identical, estimate $est met"
else bad "target 0.03: 1 vs 3 workers bit-identical (rc $r1 $r3, estimate $est)"; fi
ns=$(samples "$T/a1.exr")
cs=$($X chsum "$T/a1.exr" samples 2>/dev/null)
if [ -n "$ns" ] && [ -n "$cs" ] && awk -v a="$ns" -v b="$cs" 'BEGIN { exit !(a == b && a > 0) }' &&
   grep -aq brume_est_rel_rmse "$T/a1.exr" && grep -aq brume_target_error "$T/a1.exr"; then
  ok "samples channel sums to the samples reported ($ns); estimate and target in the header"
else bad "samples channel sums to the samples reported ($ns vs $cs)"; fi
if ! $X cmp "$T/a1.exr" "$T/a3.exr" >/dev/null 2>&1 || [ "$($X chsum "$T/a1.exr" samples)" != "$($X chsum "$T/a3.exr" samples)" ]; then
  bad "samples channel identical for 1 and 3 workers"; else ok "samples channel identical for 1 and 3 workers"; fi

# A per-pixel bound alone: 1 vs 3 workers bit-identical; every pixel's estimate (from the
# EXR's channels) within P unless its block is at the cap (256 spp), as the stats say; the
# blocks whose pixels round 0 (= --spp 32 --passes 4) saw above P got more samples.
PD="--pixel-error 0.2 --tile 16 --spp 256"
run $M $S -o "$T/x1.exr" $PD --no-journal --workers 1 --threads 1 && x1=0 || x1=1
cp "$T/log" "$T/x1.log"
run $M $S -o "$T/x3.exr" $PD --no-journal --workers 3 --threads 2 && x3=0 || x3=1
run $M $S -o "$T/x0.exr" --spp 32 --passes 4 --tile 16 --no-journal --workers 1 --threads 2 && x0=0 || x0=1
px=$($X pixerr "$T/x1.exr" 0.2 --cap 256 | sed -n 's/^estimate: over \([0-9]*\) of [0-9]* (\([0-9]*\) at the cap).*/\1 \2/p')
pstat=$(python3 -c 'import json, sys; s = json.load(open(sys.argv[1] + ".stats.json")); print(s["pixels_over_bound"], s["pixels_over_bound_at_cap"])' "$T/x1.exr" 2>/dev/null)
# Pixels above P only where their block is at the cap, or the rounds stopped because no
# growing tile had units left (docs/adaptive.md, Limits).
pstop=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1] + ".stats.json"))["adaptive_stop"])' "$T/x1.exr" 2>/dev/null)
al=$($X pixerr "$T/x0.exr" 0.2 --alloc "$T/x1.exr" | sed -n 's/^alloc: mean samples \([0-9.]*\) where the estimate is above P, \([0-9.]*\) elsewhere/\1 \2/p')
if [ $x1$x3$x0 = 000 ] && $X cmp "$T/x1.exr" "$T/x3.exr" && [ -n "$px" ] && { [ "${px% *}" = "${px#* }" ] || [ "$pstop" = "every growing tile out of units" ]; } && [ "$px" = "$pstat" ] &&
   grep -aq brume_pixel_error "$T/x1.exr" && grep -q "summary: adaptive: per-pixel bound 0.2 .*pixels above 0.2: ${px% *} " "$T/x1.log" &&
   [ -n "$al" ] && awk -v a="${al% *}" -v b="${al#* }" 'BEGIN { exit !(a >= 2 * b && b >= 32) }'; then
  ok "pixel bound 0.2: 1 vs 3 workers bit-identical, pixels above it all at the cap ($px; stop: $pstop), mean spp $al where round 0 saw them above / not"
else bad "pixel bound 0.2: 1 vs 3 workers identical, above it only at the cap (over, at cap: $px; stats $pstat), spp $al (rc $x1$x3$x0)"; fi

# Per pixel block: a unit renders some 4x4-pixel blocks of its tile (8x8 of them in a tile of 32 px).
# 1 vs 3 workers bit-identical, the samples channel sums to the samples reported, and
# blocks got different counts.
BD="--target-error 0.03 --tile 32 --spp 2048"
run $M $S -o "$T/b1.exr" $BD --no-journal --workers 1 --threads 1 && b1=0 || b1=1
cp "$T/log" "$T/b1.log"
run $M $S -o "$T/b3.exr" $BD --no-journal --workers 3 --threads 2 && b3=0 || b3=1
ns=$(samples "$T/b1.exr")
cs=$($X chsum "$T/b1.exr" samples 2>/dev/null)
lohi=$(sed -n 's/^summary: adaptive: .* spp min \([0-9]*\) mean [0-9.]* max \([0-9]*\).*/\1 \2/p' "$T/b1.log")
if [ $b1 = 0 ] && [ $b3 = 0 ] && $X cmp "$T/b1.exr" "$T/b3.exr" && [ -n "$ns" ] && [ "$ns" = "$cs" ] &&
   [ "$cs" = "$($X chsum "$T/b3.exr" samples)" ] && [ -n "$lohi" ] && awk -v a="${lohi% *}" -v b="${lohi#* }" 'BEGIN { exit !(a < b) }'; then
  ok "blocks of 32-px tiles: 1 vs 3 workers bit-identical, samples channel sums to $ns, spp min/max $lohi"
else bad "blocks of 32-px tiles: 1 vs 3 workers identical, samples $ns vs $cs, spp min/max $lohi (rc $b1 $b3)"; fi
# Each 4x4 block (tiles of 16 px: 4x4 blocks) that got n passes is the uniform render with
# --spp 8n --passes n, bit for bit: two rounds leave the blocks at 4, 6 or 8 passes.
run $M $S -o "$T/c2.exr" --target-error 0.15 --max-rounds 2 --tile 16 --spp 2048 --no-journal --workers 2 --threads 1 && c2=0 || c2=1
for n in 4 6 8; do
  run $M $S -o "$T/u$n.exr" --spp $((8 * n)) --passes $n --no-journal --workers 1 --threads 2 || c2=1
done
matched=0 kinds=""
for by in 0 4 8 12 16 20; do for bx in 0 4 8 12 16 20 24 28; do
  for n in 4 6 8; do
    if $X cmprect "$T/c2.exr" "$T/u$n.exr" $bx $by 4 4 >/dev/null 2>&1; then
      matched=$((matched + 1)); case " $kinds " in *" $n "*) ;; *) kinds="$kinds $n";; esac; break
    fi
  done
done; done
if [ $c2 = 0 ] && [ $matched = 48 ] && [ $(echo $kinds | wc -w) -ge 2 ]; then
  ok "every 4x4 block with n passes = --spp 8n --passes n, bit for bit (48 blocks; n in$kinds)"
else bad "every 4x4 block with n passes = the uniform render with n passes ($matched of 48 matched; n in$kinds; rc $c2)"; fi

# Killed after round 0 (the journal holds a unit of slot 4 or later), restarted: identical,
# with units of pixel blocks (tiles of 16 px).
# jtop JOURNAL TILES: the highest slot (pass) among the journal's records (header 76 bytes;
# record: "TREC", u32 unit, u32 chunk size, 44 bytes of stats, chunk, 32-byte hash).
jtop() {
  python3 -c 'import struct, sys
try: d = open(sys.argv[1], "rb").read()
except OSError: d = b""
tiles, at, top = int(sys.argv[2]), 76, -1
while at + 12 <= len(d) and d[at:at + 4] == b"TREC":
    unit, size = struct.unpack_from("<II", d, at + 4)
    if at + 12 + 44 + size + 32 > len(d): break
    top = max(top, unit // tiles); at += 12 + 44 + size + 32
print(top)' "$1" "$2"
}
jtop_reached() { [ "$(jtop "$1" "$2")" -ge "$3" ]; } # jtop_reached JOURNAL TILES SLOT
KD="--target-error 0.02 --pixel-error 0.05 --tile 16 --spp 4096" # 4 tiles of 4x4 blocks; both rules decide
run $M $S -o "$T/k0.exr" $KD --no-journal --workers 2 --threads 1 && r0=0 || r0=1
# Under a heavy load the poll can see slot 5 only as the render ends, and the kill then
# finds a finished frame (no journal): that try says nothing, so it is made again.
for try in 1 2 3; do
  rm -f "$T/k.exr" "$T/k.exr.journal"
  $M $S -o "$T/k.exr" $KD --workers 2 --threads 1 >"$T/klog" 2>&1 &
  kill_when $! 600 0.05 jtop_reached "$T/k.exr.journal" 4 5
  jt=$(jtop "$T/k.exr.journal" 4)
  [ "$jt" -ge 5 ] && break
  echo "note: try $try: the master had ended before the kill (journal up to slot $jt); again"
done
run $M $S -o "$T/k.exr" $KD --workers 2 --threads 1 && rk=0 || rk=1
fj=$(counter tiles_from_journal "$T/k.exr")
if [ $r0 = 0 ] && [ $rk = 0 ] && [ "${fj:-0}" -gt 0 ] && $X cmp "$T/k0.exr" "$T/k.exr" &&
   [ "$($X chsum "$T/k0.exr" samples)" = "$($X chsum "$T/k.exr" samples)" ]; then
  ok "master kill -9 mid-round (journal up to slot $jt; target and pixel bound) + restart: identical ($fj units from the journal)"
else bad "master kill -9 mid-round + restart: identical (rc $r0 $rk, journal pass $jt, from journal ${fj:-0})"; fi

# A time limit stops at a round boundary and records the rounds; --max-rounds reproduces it.
run $M $S -o "$T/t.exr" --time-limit 0.001 --tile 8 --spp 1024 --no-journal --workers 1 --threads 1 && rt=0 || rt=1
rounds=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1] + ".stats.json"))["rounds"])' "$T/t.exr" 2>/dev/null)
run $M $S -o "$T/t2.exr" --time-limit 1000 --max-rounds "${rounds:-1}" --tile 8 --spp 1024 --no-journal --workers 2 --threads 1 && rt2=0 || rt2=1
if [ $rt = 0 ] && [ $rt2 = 0 ] && [ -n "$rounds" ] && grep -aq brume_time_limited "$T/t.exr" && $X cmp "$T/t.exr" "$T/t2.exr"; then
  ok "time limit: stopped after $rounds round(s), recorded; --max-rounds $rounds reproduces it"
else bad "time limit: recorded rounds ($rounds) and --max-rounds reproduce it (rc $rt $rt2)"; fi

# Passes on a scene without photon maps: batch-means estimate, 1 vs 2 workers identical.
run $M $S -o "$T/p1.exr" --spp 16 --passes 4 --no-journal --workers 1 --threads 1 && p1=0 || p1=1
run $M $S -o "$T/p2.exr" --spp 16 --passes 4 --no-journal --workers 2 --threads 1 --tile 8 && p2=0 || p2=1
if [ $p1 = 0 ] && [ $p2 = 0 ] && grep -q "batch means over the streams of passes" "$T/log" && $X cmp "$T/p1.exr" "$T/p2.exr"; then
  ok "4 passes without photon maps: batch means, 1 vs 2 workers identical"
else bad "4 passes without photon maps: batch means, 1 vs 2 workers identical"; fi

# Default passes: a plain render with an even spp is 2 passes (one per sampler stream, a
# batch-means estimate); --passes 1 and an odd spp are one pass. 2 passes = --passes 2.
passes() { python3 -c 'import json, sys; print(json.load(open(sys.argv[1] + ".stats.json"))["passes"])' "$1" 2>/dev/null; }
run $M $S -o "$T/d2.exr" --spp 16 --no-journal --workers 1 --threads 1 && d1=0 || d1=1
grep -q "batch means over the streams of passes" "$T/log" && dm=1 || dm=0
run $M $S -o "$T/e2.exr" --spp 16 --passes 2 --no-journal --workers 2 --threads 1 --tile 8 && d2=0 || d2=1
run $M $S -o "$T/d1.exr" --spp 16 --passes 1 --no-journal --workers 1 --threads 1 && d3=0 || d3=1
run $M $S -o "$T/d3.exr" --spp 3 --no-journal --workers 1 --threads 1 && d4=0 || d4=1
if [ $d1$d2$d3$d4 = 0000 ] && [ $dm = 1 ] && [ "$(passes "$T/d2.exr")" = 2 ] && [ "$(passes "$T/d1.exr")" = 1 ] &&
   [ "$(passes "$T/d3.exr")" = 1 ] && $X cmp "$T/d2.exr" "$T/e2.exr" && ! $X cmp "$T/d2.exr" "$T/d1.exr" >/dev/null 2>&1; then
  ok "default passes: 2 streams for an even spp (= --passes 2), 1 with --passes 1 or an odd spp"
else bad "default passes: 2 streams for an even spp, 1 with --passes 1 or an odd spp (rc $d1$d2$d3$d4)"; fi

# A tile that got m passes is the uniform render with --spp 8m --passes m: round 0 (4
# passes of 8 spp per tile) against --spp 32 --passes 4, bit for bit, samples included.
run $M $S -o "$T/r0.exr" --target-error 0.0001 --max-rounds 1 --spp 4096 --tile 8 --no-journal --workers 2 --threads 1 && q1=0 || q1=1
run $M $S -o "$T/u32.exr" --spp 32 --passes 4 --tile 16 --no-journal --workers 1 --threads 2 && q2=0 || q2=1
if [ $q1 = 0 ] && [ $q2 = 0 ] && $X cmp "$T/r0.exr" "$T/u32.exr" &&
   [ "$($X chsum "$T/r0.exr" samples)" = "$($X chsum "$T/u32.exr" samples)" ]; then
  ok "adaptive round 0 (4 passes of 8) = --spp 32 --passes 4, bit for bit"
else bad "adaptive round 0 (4 passes of 8) = --spp 32 --passes 4 (rc $q1 $q2)"; fi

# Uniform noise: the tiny scene's floor seen from above under a large lamp. The pilot
# predicts that per-block passes save little, so every block goes on at one level: the
# image is the uniform render of that many passes, bit for bit, for 1 and 3 workers.
mkdir -p "$T/flat"
cp scenes/tiny/* "$T/flat/"
sed -n '1,16p' scenes/tiny/tiny.obj >"$T/flat/floor.obj"
cat >"$T/flat/flat.json" <<'JSON'
{
  "version": 1,
  "camera": {"position": [0, 1.2, 0.01], "look_at": [0, 0, 0], "fov_y": 30},
  "render": {"width": 32, "height": 24, "spp": 4, "max_depth": 2, "seed": 7, "tile_size": 16},
  "materials": {"lamp": {"type": "diffuse", "albedo": [0, 0, 0], "emission": [8, 8, 8]}},
  "objects": [
    {"type": "obj", "file": "floor.obj"},
    {"type": "obj", "file": "lamp.obj", "material": "lamp", "transform": {"translate": [0, 3, 0], "scale": [8, 1, 8]}}
  ],
  "lights": []
}
JSON
FD="--target-error 0.01 --tile 16 --spp 2048"
run $M "$T/flat/flat.json" -o "$T/f1.exr" $FD --no-journal --workers 1 --threads 1 && f1=0 || f1=1
cp "$T/log" "$T/f1.log"
run $M "$T/flat/flat.json" -o "$T/f3.exr" $FD --no-journal --workers 3 --threads 2 && f3=0 || f3=1
lohi=$(sed -n 's/^summary: adaptive: .* spp min \([0-9]*\) mean [0-9.]* max \([0-9]*\).*/\1 \2/p' "$T/f1.log")
fs=${lohi% *}
run $M "$T/flat/flat.json" -o "$T/fu.exr" --spp "${fs:-8}" --passes $((${fs:-8} / 8)) --no-journal --workers 2 --threads 1 && f2=0 || f2=1
if [ $f1$f3$f2 = 000 ] && grep -q "uniform passes$" "$T/f1.log" && [ "${lohi% *}" = "${lohi#* }" ] && [ "${fs:-0}" -gt 32 ] &&
   $X cmp "$T/f1.exr" "$T/f3.exr" && $X cmp "$T/f1.exr" "$T/fu.exr" &&
   [ "$($X chsum "$T/f1.exr" samples)" = "$($X chsum "$T/fu.exr" samples)" ]; then
  ok "uniform noise: uniform passes ($fs spp everywhere) = --spp $fs --passes $((fs / 8)), 1 vs 3 workers bit-identical"
else bad "uniform noise: uniform passes = the uniform render, 1 vs 3 workers (rc $f1$f3$f2, spp min/max $lohi)"; fi

# With a photon map an adaptive render traces only the maps of the passes its rounds give
# out (and one ahead), not every pass up to the cap: fog_spot at 80x60 to a loose target
# stops after round 0 (4 passes of 8), and is the uniform render of those 4 passes.
mkdir -p "$T/fs"
cp scenes/fog_spot/* "$T/fs/"
sed -i 's/"width": 160, "height": 120/"width": 80, "height": 60/' "$T/fs/fog_spot.json"
run $M "$T/fs/fog_spot.json" -o "$T/m1.exr" --target-error 0.5 --spp 4096 --no-journal --workers 1 --threads 2 && m1=0 || m1=1
cp "$T/log" "$T/m1.log"
run $M "$T/fs/fog_spot.json" -o "$T/mu.exr" --spp 32 --passes 4 --no-journal --workers 2 --threads 1 && mu=0 || mu=1
maps=$(grep -c "media: photon map [0-9]* of" "$T/m1.log")
mx=$(sed -n 's/^summary: adaptive: .* spp min [0-9]* mean [0-9.]* max \([0-9]*\).*/\1/p' "$T/m1.log")
if [ $m1$mu = 00 ] && [ "${mx:-0}" = 32 ] && [ "$maps" -le 5 ] && $X cmp "$T/m1.exr" "$T/mu.exr"; then
  ok "photon maps: an adaptive render traces the maps its passes use and one more ($maps of 512), = --spp 32 --passes 4"
else bad "photon maps: an adaptive render traces the maps its passes use and one more ($maps of 512, max spp ${mx:-?}; rc $m1$mu)"; fi

finish
