#!/bin/sh
# Benchmark: analytic against sampled motion blur (camera.motion_blur, docs/motion.md) at
# equal CPU time. For each scene: a reference, the average of two sampled renders at REF_SPP
# with independent seeds (its own relRMSE, from their difference, printed and removed in
# quadrature from every error), a still render (shutter closed) for the mask of pixels that
# see motion (where the reference and the still render differ by more than TOL times the
# reference's mean), then both methods at each of SPPS (sampled also at 4x the largest, so
# equal time stays inside its curve). Time is CPU seconds of the whole process tree, the
# fixed cost removed: a least-squares line of CPU time against spp gives the cost per
# sample of each method; their ratio is the cost per camera sample of analytic against
# sampled. Equal time: sampled's relRMSE interpolated (log-log) at spp x that ratio.
# Usage: BUILD=build sh scripts/bench_motion_blur.sh (env: SCENES, SPPS, REF_SPP, TOL)
set -eu
. scripts/lib.sh
SCENES=${SCENES:-"edge fan motion dof_motion"}
SPPS=${SPPS:-"1 4 16 64"}
REF_SPP=${REF_SPP:-8192}
TOL=${TOL:-0.1}
REPS=${REPS:-3}
bench_init bench-motion-blur
X=$BUILD/exrtool
cpu() { cpu_secs "$BUILD/master" "$1" -o "$2" --workers 1 --spp "$3"; }
# true_err NOISE: the relRMSE on stdin with the reference's own relRMSE NOISE removed in
# quadrature (0 where the measured error is within the reference's noise).
true_err() { awk -v n="$1" '{e = $1 * $1 - n * n; printf "%.6g\n", (e > 0 ? sqrt(e) : 0)}'; }
largest=$(echo $SPPS | tr ' ' '\n' | sort -g | tail -1)
echo "analytic vs sampled motion blur, CPU time, $CORES cores; reference: sampled at $REF_SPP spp; mask: |ref - still| > $TOL x mean(ref)"
for sc in $SCENES; do
  D="$T/$sc"
  mkdir -p "$D"
  cp scenes/$sc/* "$D/"
  J="$D/$sc.json"
  sed 's/"shutter_close": 0.5/"shutter_close": 0.5, "motion_blur": "analytic"/' "$J" >"$D/an.json"
  sed 's/"shutter_close": 0.5/"shutter_close": 0/' "$J" >"$D/still.json"
  grep -q '"motion_blur": "analytic"' "$D/an.json" || { echo "bench: cannot make the analytic variant of $sc" >&2; exit 1; }
  # The reference is the average of two sampled renders at REF_SPP with independent seeds,
  # cached by scene and renderer (ref_key): the slowest part of the run. Their difference
  # measures the reference's own error: the average's relRMSE is relRMSE(ref1, ref2) / 2,
  # and it is removed in quadrature from every error below ("true"), so that the
  # reference's noise does not flatter the method with the larger error.
  key=$(ref_key "$J")
  ref1="$OUT/motion-ref-$sc-$REF_SPP-s1-$key.exr"
  ref2="$OUT/motion-ref-$sc-$REF_SPP-s2-$key.exr"
  ref="$D/ref.exr"
  [ -f "$ref1" ] || logged "$BUILD/master" "$J" -o "$ref1" --workers 1 --spp "$REF_SPP" --seed 1001 --no-journal
  [ -f "$ref2" ] || logged "$BUILD/master" "$J" -o "$ref2" --workers 1 --spp "$REF_SPP" --seed 2002 --no-journal
  logged "$X" average "$ref" "$ref1" "$ref2"
  logged "$BUILD/master" "$D/still.json" -o "$D/still.exr" --workers 1 --spp 256
  rnm=$($X relrmse "$ref1" "$ref2" --mask "$D/still.exr" --tol "$TOL" 2>/dev/null | awk '{print $1 / 2}')
  rnw=$($X relrmse "$ref1" "$ref2" | awk '{print $1 / 2}')
  : >"$D/rows"
  for m in an sa; do
    spps=$SPPS
    [ $m = sa ] && spps="$SPPS $((largest * 4))"
    f=$J
    [ $m = an ] && f=$D/an.json
    for s in $spps; do
      logged "$BUILD/master" "$f" -o "$D/$m$s.exr" --workers 1 --spp "$s"
      em=$($X relrmse "$D/$m$s.exr" "$ref" --mask "$D/still.exr" --tol "$TOL" 2>"$D/maskinfo" | true_err "$rnm")
      ew=$($X relrmse "$D/$m$s.exr" "$ref" | true_err "$rnw")
      echo "$m $s $em $ew" >>"$D/rows"
    done
  done
  # Cost per camera sample: CPU seconds between 4 and HI spp over the spp between, median
  # of REPS (renders are deterministic: only the timings repeat).
  per_spp() {
    i=0
    while [ $i -lt "$REPS" ]; do
      lo=$(cpu "$1" "$D/t.exr" 4)
      hi=$(cpu "$1" "$D/t.exr" "$2")
      awk -v lo="$lo" -v hi="$hi" -v n=$(($2 - 4)) 'BEGIN {printf "%.6g\n", (hi - lo) / n}'
      i=$((i + 1))
    done | median
  }
  ca=$(per_spp "$D/an.json" "$largest")
  cs=$(per_spp "$J" $((largest * 4)))
  ratio=$(awk -v a="$ca" -v b="$cs" 'BEGIN {printf "%.3f", a / b}')
  px=$(sed -n 's/.*mask holds \([0-9]*\) of \([0-9]*\) pixels.*/\1 of \2/p' "$D/maskinfo")
  echo
  echo "$sc: reference's own relRMSE $rnm moving pixels, $rnw whole image (from two seeds; removed in quadrature below); mask $px pixels; cost per camera sample analytic / sampled $ratio ($ca / $cs s per spp)"
  printf '%6s %12s %12s %12s %8s %12s %12s %8s\n' spp "an masked" "sa masked" "sa eq.time" ratio "an whole" "sa eq.time" ratio
  for s in $SPPS; do
    eq=$(awk -v s="$s" -v r="$ratio" 'BEGIN {print s * r}')
    am=$(awk -v s="$s" '$1 == "an" && $2 == s {print $3}' "$D/rows")
    aw=$(awk -v s="$s" '$1 == "an" && $2 == s {print $4}' "$D/rows")
    sm=$(awk -v s="$s" '$1 == "sa" && $2 == s {print $3}' "$D/rows")
    sme=$(awk '$1 == "sa" {print $2, $3}' "$D/rows" | loglog_interp "$eq")
    swe=$(awk '$1 == "sa" {print $2, $4}' "$D/rows" | loglog_interp "$eq")
    printf '%6s %12.4g %12.4g %12s %8.3f %12.4g %12s %8.3f\n' "$s" "$am" "$sm" "$sme" \
      "$(awk -v a="$am" -v b="${sme%\*}" 'BEGIN {print a / b}')" "$aw" "$swe" "$(awk -v a="$aw" -v b="${swe%\*}" 'BEGIN {print a / b}')"
    echo "$sc $s $(awk -v s="$s" -v c="$ca" 'BEGIN {print s * c}') $am" >>"$T/plot_an"
  done
  awk -v sc="$sc" -v c="$cs" '$1 == "sa" {print sc, $2, $2 * c, $3}' "$D/rows" >>"$T/plot_sa"
  cp "$D/rows" "$OUT/motion-blur-$sc.txt"
done
echo
echo "ratio: analytic's relRMSE over sampled's at equal CPU time (* = sampled extrapolated); target <= 0.25 in the mask at 1-16 spp"
{
  echo "set terminal png size 1000,800 noenhanced; set output '$OUT/motion_blur.png'"
  echo "set multiplot layout 2,2; set logscale xy; set xlabel 'CPU s (fixed cost removed)'; set ylabel 'relRMSE, moving pixels'; set key bottom left"
  for sc in $SCENES; do
    echo "set title '$sc'"
    echo "plot '$T/plot_an' using (strcol(1) eq '$sc' ? \$3 : 1/0):4 with linespoints title 'analytic', '$T/plot_sa' using (strcol(1) eq '$sc' ? \$3 : 1/0):4 with linespoints title 'sampled'"
  done
  echo "unset multiplot"
} | plot "$OUT/motion_blur.png"
