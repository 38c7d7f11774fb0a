#!/bin/sh
# Inputs and outputs (docs/benchmarks.md, "AOVs and PLY"):
# 1. The cost of AOVs: CPU time (user + system of the master and its workers) to render
#    scenes/cornell with every AOV (--aovs all) against the beauty alone, REPS runs of
#    each, interleaved, at each sample count of SPP; throughput ratio = beauty CPU / AOV
#    CPU (medians).
# 2. PLY load time: a grid of about 1M triangles (scripts/gen_mesh.py 708) as binary
#    PLY (little- and big-endian), ascii PLY and OBJ, each loaded REPS times by
#    build/meshload (CPU time of reading and parsing, best of REPS).
# Environment: SPP (sample counts, default "4 16 64"), REPS (default 3), N (grid size, default 708).
# Output: bench-out/bench_io.txt. Usage: BUILD=build sh scripts/bench_io.sh
set -eu
. scripts/lib.sh
bench_init io
SPP=${SPP:-"4 16 64"}
REPS=${REPS:-3}
N=${N:-708}
R="$OUT/bench_io.txt"

median() { sort -g | awk '{ a[NR] = $1 } END { print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2 }'; }

aov_cost() {
  : >"$T/beauty"
  : >"$T/aovs"
  for i in $(seq "$REPS"); do
    cpu_secs $BUILD/master scenes/cornell/cornell.json -o "$T/b.exr" --workers 1 --threads 1 --spp "$1" >>"$T/beauty"
    cpu_secs $BUILD/master scenes/cornell/cornell.json -o "$T/a.exr" --workers 1 --threads 1 --spp "$1" --aovs all >>"$T/aovs"
  done
  b=$(median <"$T/beauty")
  a=$(median <"$T/aovs")
  echo "AOV cost: scenes/cornell, 512x512, $1 spp, 1 worker x 1 thread, CPU s (median of $REPS)"
  echo "beauty alone: $b s  [$(tr '\n' ' ' <"$T/beauty")]  $(wc -c <"$T/b.exr") bytes"
  echo "all AOVs:     $a s  [$(tr '\n' ' ' <"$T/aovs")]  $(wc -c <"$T/a.exr") bytes"
  awk -v b="$b" -v a="$a" 'BEGIN { printf "throughput with all AOVs / beauty alone: %.3f\n", b / a }'
}
{
  for s in $SPP; do aov_cost "$s"; done
  echo
  python3 scripts/gen_mesh.py "$N" "$T/m"
  echo "PLY load: grid $N ($(head -c 0 /dev/null)$($BUILD/meshload "$T/m.ply" 1 | awk '{print $1}') triangles), CPU s, best of $REPS"
  echo "file | bytes | best s | mean s | ratio to OBJ (best)"
  obj=$($BUILD/meshload "$T/m.obj" "$REPS")
  objbest=$(echo "$obj" | awk '{print $3}')
  for f in m.ply m.be.ply m.ascii.ply m.obj; do
    l=$($BUILD/meshload "$T/$f" "$REPS")
    [ "$f" = m.obj ] && l=$obj
    echo "$l" | awk -v f="$f" -v s="$(wc -c <"$T/$f")" -v o="$objbest" '{ printf "%s | %d | %.3f | %.3f | %.2f\n", f, s, $3, $4, $3 / o }'
  done
} | tee "$R"
