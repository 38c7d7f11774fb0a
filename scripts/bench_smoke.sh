#!/bin/sh
# The smoke simulator (docs/smoke.md, "Figures"). Part 1: scenes/smoke_anim/sim.json at
# 64^3 and 128^3 (--res), 1 and 2 threads, WARMUP untimed steps (the plume grows) then STEPS
# timed ones (--bench: no files written). Per run: wall and CPU ms per step (CPU: the
# solver's own per-phase clocks, all threads), the FFT and advection CPU ms per step and
# their shares, the peak resident memory and, from the two sizes, the memory per voxel (the
# RSS difference over the voxel difference); the last state's frame as dense BRGRID01 bytes
# and as .nvdb bytes (NanoVDB's writer, densities above nvdb_threshold) with the voxels it
# stores. Part 2: render cost per frame of scenes/smoke_anim (a grid and a photon map per
# frame) against the same scene with one still grid (frame LAST for every frame), frames
# LAST-2..LAST with 2 local workers, CPU seconds of the whole process tree.
# The runs go round REPEAT times through every size and thread count (alternating, so
# that a burst of load on the shared machine spreads over all of them); the table gives
# the median of each figure over the rounds, and advect/FFT the median of the runs' ratios
# of advection to FFT CPU time. With threads, per-phase wall times are printed beside the
# CPU times (all threads).
# Environment: STEPS (10), WARMUP (48), RES ("64 128"), THREADS ("1 2"), REPEAT (3), LAST (48).
# Output: bench-out/bench_smoke.txt. Usage: BUILD=build sh scripts/bench_smoke.sh
set -eu
. scripts/lib.sh
bench_init smoke
STEPS=${STEPS:-10}
WARMUP=${WARMUP:-48}
RES=${RES:-64 128}
THREADS=${THREADS:-1 2}
LAST=${LAST:-48}
REPEAT=${REPEAT:-3}
R="$OUT/bench_smoke.txt"
: >"$T/runs"
round=0
while [ "$round" -lt "$REPEAT" ]; do
  round=$((round + 1))
  for r in $RES; do
    for t in $THREADS; do
      logged $BUILD/smokesim scenes/smoke_anim/sim.json --bench "$STEPS" --warmup "$WARMUP" --res "$r" --threads "$t"
      grep '^res ' "$T/log" >>"$T/runs"
    done
  done
done
# Part 2: the scene's own frames (64^3, written into $T), animated against still.
A="$T/anim"
mkdir -p "$A"
cp scenes/smoke_anim/smoke_anim.json scenes/smoke_anim/floor.obj "$A/"
sed "s/\"frames\": [0-9]*/\"frames\": $LAST/" scenes/smoke_anim/sim.json >"$A/sim.json"
logged $BUILD/smokesim "$A/sim.json"
sed "s/smoke.####.nvdb/smoke.$(printf %04d "$LAST").nvdb/" "$A/smoke_anim.json" >"$A/still.json"
F="$((LAST - 2)):$LAST"
anim=$(cpu_secs $BUILD/master "$A/smoke_anim.json" -o "$T/anim.exr" --frames "$F" --workers 2 --no-journal)
still=$(cpu_secs $BUILD/master "$A/still.json" -o "$T/still.exr" --frames "$F" --workers 2 --no-journal)
{
  echo "smokesim --bench $STEPS --warmup $WARMUP on scenes/smoke_anim/sim.json, $CORES cores ($(date -u +%Y-%m-%d))"
  echo "medians of $REPEAT runs; FFT and advect: CPU ms per step (all threads), then wall ms per step"
  echo "res        threads  wall ms/step  CPU ms/step  FFT ms  advect ms  advect/FFT  FFT wall  advect wall  FFT share  advect share  max RSS MiB  dense bytes  nvdb bytes  nvdb voxels"
  awk 'function med(key,   n, i, j, x, a) { n = split(vals[key], a, " ");
         for (i = 2; i <= n; i++) { x = a[i] + 0; for (j = i - 1; j >= 1 && a[j] + 0 > x; j--) a[j + 1] = a[j]; a[j + 1] = x }
         return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2 }
       { for (i = 1; i < NF; i += 2) v[$i] = $(i + 1);
         k = v["res"] " " v["threads"]; if (!(k in seen)) { seen[k] = 1; order[++nk] = k }
         v["ratio"] = v["fft_ms"] > 0 ? v["advect_ms"] / v["fft_ms"] : 0;
         split("wall_ms_per_step cpu_ms_per_step fft_ms advect_ms ratio fft_wall_ms advect_wall_ms fft_share advect_share maxrss_kib grid_bytes nvdb_bytes nvdb_voxels", f, " ");
         for (i in f) vals[k SUBSEP f[i]] = vals[k SUBSEP f[i]] " " v[f[i]] }
       END { for (o = 1; o <= nk; o++) { k = order[o]; split(k, rt, " ");
         printf "%-10s %7s  %12.1f  %11.1f  %6.1f  %9.1f  %10.2f  %8.1f  %11.1f  %8.1f%%  %11.1f%%  %11.1f  %11d  %10d  %11d\n", rt[1], rt[2],
           med(k SUBSEP "wall_ms_per_step"), med(k SUBSEP "cpu_ms_per_step"), med(k SUBSEP "fft_ms"), med(k SUBSEP "advect_ms"),
           med(k SUBSEP "ratio"), med(k SUBSEP "fft_wall_ms"), med(k SUBSEP "advect_wall_ms"), 100 * med(k SUBSEP "fft_share"),
           100 * med(k SUBSEP "advect_share"), med(k SUBSEP "maxrss_kib") / 1024, med(k SUBSEP "grid_bytes"),
           med(k SUBSEP "nvdb_bytes"), med(k SUBSEP "nvdb_voxels") } }' "$T/runs"
  awk '{ for (i = 1; i < NF; i += 2) v[$i] = $(i + 1); split(v["res"], d, "x"); n = d[1] * d[2] * d[3];
         if (!(n in rss)) { rss[n] = v["maxrss_kib"]; order[++k] = n } }
       END { if (k >= 2) printf "memory per voxel: %.1f bytes (RSS difference %d^3 -> %d^3; the state and scratch: %s bytes)\n",
               1024 * (rss[order[k]] - rss[order[1]]) / (order[k] - order[1]), order[1] ^ (1 / 3) + 0.5, order[k] ^ (1 / 3) + 0.5, "'"$(awk '{for(i=1;i<NF;i+=2) if($i=="bytes_per_voxel") print $(i+1)}' "$T/runs" | head -1)"'" }' "$T/runs"
  awk -v a="$anim" -v s="$still" -v f="$F" 'BEGIN { printf "render, frames %s of scenes/smoke_anim (2 local workers), CPU s per frame: animated %.2f, still grid %.2f (ratio %.2f)\n", f, a / 3, s / 3, a / s }' 
} | tee "$R"
