#!/bin/sh
# Benchmark: error against samples and against time for each sampler on a scene with
# defocus and motion blur (scenes/dof_motion; SCENE=path.json for another). RMSE is measured against a converged reference of the same renderer
# (independent sampler, another seed, REF_SPP spp, cached in bench-out/). Prints a table,
# the fitted log-log slopes, the equal-time ratio at 64 spp, and writes
# bench-out/sampling.txt and bench-out/sampling.png. Called by `make bench`.
# Usage: BUILD=build sh scripts/bench_sampling.sh   (env: REF_SPP, SEEDS)
set -eu
. scripts/lib.sh
REF_SPP=${REF_SPP:-32768}
SEEDS=${SEEDS:-"11 12 13"}
W=${W:-160}
H=${H:-120}
bench_init bsamp gnuplot-nox bc time
# The scene (default: defocus and motion blur together, glass in front of a lit checker
# wall) at a bench resolution, so render time dominates process start-up.
SRC=${SCENE:-scenes/dof_motion/dof_motion.json}
NAME=$(basename "$SRC" .json)
cp "$(dirname "$SRC")"/* "$T/"
SCENE="$T/bench-$NAME.json"
sed "s/\"width\": 64, \"height\": 48/\"width\": $W, \"height\": $H/" "$SRC" >"$SCENE"
grep -q "\"width\": $W," "$SCENE" || { echo "bench_sampling: cannot set the resolution"; exit 1; }

# The reference is keyed by the scene's content and the binary, so a change to either redoes it.
REF="$OUT/$NAME-ref-${W}x$H-$REF_SPP-$(ref_key "$SCENE").exr"
if [ ! -f "$REF" ]; then
  echo "sampling: rendering the reference ($REF_SPP spp, once)"
  logged "$BUILD/master" "$SCENE" -o "$REF" --workers 1 --threads "$CORES" --spp "$REF_SPP" --seed 999 \
    --sampler independent
fi

# Time is CPU seconds (user + system) of the master and its worker, not wall time: the
# development machines are shared and noisy, and a render keeps every thread busy, so CPU
# time is the steadier measure of work; fixed costs drop out of the 64 -> 256 spp slope.
: >"$T/rows"
for smp in independent stratified sobol; do
  for spp in 1 4 16 64 256; do
    mse=0
    secs=0
    n=0
    for seed in $SEEDS; do
      w=$(cpu_secs "$BUILD/master" "$SCENE" -o "$T/img.exr" --workers 1 \
        --threads "$CORES" --spp "$spp" --seed "$seed" --sampler "$smp")
      r=$("$BUILD/exrtool" rmse "$T/img.exr" "$REF")
      mse=$(echo "$mse + $r * $r" | bc -l)
      secs=$(echo "$secs + $w" | bc -l)
      n=$((n + 1))
    done
    echo "$smp $spp $(echo "sqrt($mse / $n)" | bc -l) $(echo "$secs / $n" | bc -l)" >>"$T/rows"
  done
done

{
  printf 'scene %s (%sx%s), %s cores, RMSE vs a %s-spp reference, mean over seeds: %s\n' "$SRC" "$W" "$H" "$CORES" "$REF_SPP" "$SEEDS"
  printf '%-12s %6s %12s %10s\n' sampler spp rmse cpu_s
  awk '{printf "%-12s %6d %12.6f %10.4f\n", $1, $2, $3, $4}' "$T/rows"
  # Least-squares slope of log(rmse) against log(spp) per sampler. Equal time: a sampler's
  # cost per sample is the time slope between 64 and 256 spp (fixed costs drop out), and
  # independent sampling's error falls as 1/sqrt(time), so at the time the sampler spends
  # on 64 spp independent would reach rmse_ind(64) * sqrt(cost_ind / cost_s); the ratio is
  # the sampler's rmse over that. Below 1 means less error for the same time.
  awk '
    { s=$1; x=log($2); y=log($3); n[s]++; sx[s]+=x; sy[s]+=y; sxx[s]+=x*x; sxy[s]+=x*y;
      if ($2 == 64) { r64[s]=$3; t64[s]=$4 } if ($2 == 256) t256[s]=$4 }
    END {
      for (s in n) {
        b[s]=(n[s]*sxy[s]-sx[s]*sy[s])/(n[s]*sxx[s]-sx[s]*sx[s]);
        c[s]=(t256[s]-t64[s])/192;
      }
      split("independent stratified sobol", order, " ");
      for (k=1; k<=3; k++) {
        s=order[k];
        printf "%-12s slope vs spp %6.3f; cost per sample %.3fx independent; at 64 spp: rmse %.6f, %.3fx independent at equal spp, %.3fx at equal time\n",
          s, b[s], c[s]/c["independent"], r64[s], r64[s]/r64["independent"], r64[s]/(r64["independent"]*sqrt(c["independent"]/c[s]));
      }
    }' "$T/rows"
} | tee "$OUT/sampling.txt"

for smp in independent stratified sobol; do
  awk -v s="$smp" '$1 == s {print $2, $3, $4}' "$T/rows" >"$OUT/sampling-$smp.dat"
done
plot "$OUT/sampling.png" <<GP
set terminal png size 1000,450
set output "$OUT/sampling.png"
set multiplot layout 1,2 title "$NAME: RMSE against a converged reference (log-log)"
set logscale xy
set grid
set xlabel "samples per pixel"
set ylabel "RMSE"
plot "$OUT/sampling-independent.dat" using 1:2 with linespoints title "independent", \
     "$OUT/sampling-stratified.dat" using 1:2 with linespoints title "stratified", \
     "$OUT/sampling-sobol.dat" using 1:2 with linespoints title "sobol"
set xlabel "CPU seconds"
plot "$OUT/sampling-independent.dat" using 3:2 with linespoints title "independent", \
     "$OUT/sampling-stratified.dat" using 3:2 with linespoints title "stratified", \
     "$OUT/sampling-sobol.dat" using 3:2 with linespoints title "sobol"
unset multiplot
GP
