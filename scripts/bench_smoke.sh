#!/bin/sh
# The smoke simulator (docs/smoke.md, "Figures"): scenes/smoke_anim/sim.json at 64^3 and
# 128^3 (--res), 1 and 2 threads, STEPS steps each (--bench: no files written). Per run:
# wall and CPU ms per step (CPU: the solver's own per-phase clocks, all threads), the FFT
# share and the advection share of that CPU time, the peak resident memory and, from the
# two sizes, the memory per voxel (the RSS difference over the voxel difference); the grid
# bytes per frame written (dense BRGRID01 float32, 20-byte header) against the dense size.
# Environment: STEPS (default 10), RES (default "64 128"), THREADS (default "1 2").
# Output: bench-out/bench_smoke.txt. Usage: BUILD=build sh scripts/bench_smoke.sh
set -eu
. scripts/lib.sh
bench_init smoke
STEPS=${STEPS:-10}
RES=${RES:-64 128}
THREADS=${THREADS:-1 2}
R="$OUT/bench_smoke.txt"
: >"$T/runs"
for r in $RES; do
  for t in $THREADS; do
    logged $BUILD/smokesim scenes/smoke_anim/sim.json --bench "$STEPS" --res "$r" --threads "$t"
    grep '^res ' "$T/log" >>"$T/runs"
  done
done
{
  echo "smokesim --bench $STEPS on scenes/smoke_anim/sim.json, $CORES cores ($(date -u +%Y-%m-%d))"
  echo "res        threads  wall ms/step  CPU ms/step  FFT share  advect share  max RSS MiB  grid bytes/frame (dense: same)"
  awk '{ for (i = 1; i < NF; i += 2) v[$i] = $(i + 1);
         printf "%-10s %7s  %12.1f  %11.1f  %8.1f%%  %11.1f%%  %11.1f  %d\n", v["res"], v["threads"],
           v["wall_ms_per_step"], v["cpu_ms_per_step"], 100 * v["fft_share"], 100 * v["advect_share"],
           v["maxrss_kib"] / 1024, v["grid_bytes"] }' "$T/runs"
  awk '{ for (i = 1; i < NF; i += 2) v[$i] = $(i + 1); split(v["res"], d, "x"); n = d[1] * d[2] * d[3];
         if (!(n in rss)) { rss[n] = v["maxrss_kib"]; order[++k] = n } }
       END { if (k >= 2) printf "memory per voxel: %.1f bytes (RSS difference %d^3 -> %d^3; the state and scratch: %s bytes)\n",
               1024 * (rss[order[k]] - rss[order[1]]) / (order[k] - order[1]), order[1] ^ (1 / 3) + 0.5, order[k] ^ (1 / 3) + 0.5, "'"$(awk '{for(i=1;i<NF;i+=2) if($i=="bytes_per_voxel") print $(i+1)}' "$T/runs" | head -1)"'" }' "$T/runs"
} | tee "$R"
