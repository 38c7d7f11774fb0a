#!/bin/sh
# Benchmark: adaptive rendering to a target error (docs/adaptive.md) against uniform spp,
# at equal true error, and the calibration of --target-error.
#
# For each scene of SCENES (scenes with uneven noise: depth of field and motion blur, textures,
# caustics through a glass ball in the Cornell box, light shafts in fog, a small motion scene):
#  1. A reference: REF_SPP spp in REF_PASSES passes, seed 99; its own relRMSE is its
#     batch-means estimate (exrtool errest; the passes are independent replicates) and is
#     taken out of every measured error in quadrature: true = sqrt(rel^2 - ref^2). Cached
#     under bench-out/ref-adaptive/ by the scene's files and these settings (REF_REDO=1 redoes).
#  2. Adaptive: --target-error E for E of TARGETS (seed SEED, --spp cap CAP): CPU seconds,
#     true relRMSE, its ratio to E (the calibration), the mean spp.
#  3. Uniform: plain renders (one pass, the scene's sampler) at spp 8, 16, 32, ... until the
#     true error is below the smallest adaptive one; the uniform CPU time at the adaptive
#     render's true error is interpolated on the log-log error-time curve ('*': extrapolated);
#     the ratio adaptive / uniform is the equal-error time ratio.
#  4. Overhead on uniform noise: OVERHEAD_SCENE (the plain Cornell box at 128x128) at 64 spp
#     uniform, then adaptive with the target set to that render's true error.
# CPU seconds (user + system of the master and its local worker, /usr/bin/time) on a shared
# machine; timings are measurements of one run, never assertions.
# Writes bench-out/adaptive.txt, bench-out/adaptive.png (gnuplot), bench-out/adaptive-SCENE.dat.
# Usage: BUILD=build sh scripts/bench_adaptive.sh
#   env: SCENES ("dof_motion textured cornell_glass fog_spot motion"), TARGETS ("0.05 0.02 0.01"),
#        REF_SPP (4096), REF_PASSES (16), CAP (8192), SEED (17), MAX_UNIFORM_SPP (8192), REF_REDO (0)
set -eu
. scripts/lib.sh
SCENES=${SCENES:-"dof_motion textured cornell_glass fog_spot motion"}
TARGETS=${TARGETS:-"0.05 0.02 0.01"}
REF_SPP=${REF_SPP:-4096}
REF_PASSES=${REF_PASSES:-16}
CAP=${CAP:-8192}
SEED=${SEED:-17}
MAX_UNIFORM_SPP=${MAX_UNIFORM_SPP:-8192}
REF_REDO=${REF_REDO:-0}
bench_init badaptive gnuplot-nox
M="$BUILD/master"
X="$BUILD/exrtool"
mkdir -p "$OUT/ref-adaptive"
TXT="$OUT/adaptive.txt"

# run SCENE_JSON OUT [args]: CPU seconds of one master run with one local worker.
run() { r_j=$1; r_o=$2; shift 2; cpu_secs "$M" "$r_j" -o "$r_o" --workers 1 --threads "$CORES" --no-journal "$@"; }
# truerr IMG REF REFERR: relRMSE against the reference with the reference's own error removed.
truerr() { awk -v a="$($X relrmse "$1" "$2")" -v r="$3" 'BEGIN { d = a * a - r * r; printf "%.5f\n", (d > 0) ? sqrt(d) : 0 }'; }

{
  echo "# bench_adaptive: CPU seconds, true relRMSE (reference error removed), on $(nproc) cores"
  echo "# scene target cpu_adaptive true true/target est spp_mean uniform_cpu_at_equal_error ratio"
} >"$TXT"
for s in $SCENES; do
  J="scenes/$s/$s.json"
  key=$(files_key scenes/$s/* "$0" | cut -c1-12)
  RD="$OUT/ref-adaptive/$s-$key-$REF_SPP-$REF_PASSES"
  if [ "$REF_REDO" = 1 ] || [ ! -f "$RD/ref.exr" ]; then
    mkdir -p "$RD"
    c=$(run "$J" "$RD/ref.exr" --spp "$REF_SPP" --passes "$REF_PASSES" --seed 99)
    echo "reference $s: $REF_SPP spp in $REF_PASSES passes, $c s CPU"
  fi
  referr=$($X errest "$RD/ref.exr")
  DAT="$OUT/adaptive-$s.dat"
  : >"$DAT.u"
  : >"$DAT.a"
  minerr=1
  for E in $TARGETS; do
    c=$(run "$J" "$T/a.exr" --target-error "$E" --spp "$CAP" --seed "$SEED")
    e=$(truerr "$T/a.exr" "$RD/ref.exr" "$referr")
    est=$($X errest "$T/a.exr")
    sppm=$(sed -n 's/.*spp min [0-9]* mean \([0-9.]*\) max.*/\1/p' "$T/log")
    echo "$E $c $e $est $sppm" >>"$DAT.a"
    minerr=$(awk -v a="$minerr" -v b="$e" 'BEGIN { print (b < a) ? b : a }')
  done
  spp=8
  while [ "$spp" -le "$MAX_UNIFORM_SPP" ]; do
    c=$(run "$J" "$T/u.exr" --spp "$spp" --seed "$SEED")
    e=$(truerr "$T/u.exr" "$RD/ref.exr" "$referr")
    echo "$spp $c $e" >>"$DAT.u"
    awk -v e="$e" -v m="$minerr" 'BEGIN { exit !(e < 0.9 * m) }' && break
    spp=$((spp * 2))
  done
  while read -r E c e est sppm; do
    uc=$(awk '{ print $3, $2 }' "$DAT.u" | loglog_interp "$e")
    ratio=$(awk -v a="$c" -v u="${uc%\*}" 'BEGIN { printf "%.3f\n", (u > 0) ? a / u : 0 }')
    printf "%s %s %s %s %.3f %s %s %s %s\n" "$s" "$E" "$c" "$e" "$(awk -v e="$e" -v t="$E" 'BEGIN { print e / t }')" "$est" \
      "$sppm" "$uc" "$ratio" >>"$TXT"
  done <"$DAT.a"
  { echo "# uniform: spp cpu true"; cat "$DAT.u"; echo; echo; echo "# adaptive: target cpu true est spp_mean"; cat "$DAT.a"; } >"$DAT"
  rm -f "$DAT.u" "$DAT.a"
  echo "reference $s: own relRMSE $referr" >>"$TXT"
done

# Overhead on uniform noise: the Cornell box at 128x128.
mkdir -p "$T/cb"
cp scenes/cornell/cornell.obj scenes/cornell/cornell.mtl "$T/cb/"
sed -e 's/"width": 512/"width": 128/' -e 's/"height": 512/"height": 128/' scenes/cornell/cornell.json >"$T/cb/cb.json"
CR="$OUT/ref-adaptive/cornell128-$(files_key "$T/cb/cb.json" "$0" | cut -c1-12)-$REF_SPP"
if [ "$REF_REDO" = 1 ] || [ ! -f "$CR/ref.exr" ]; then
  mkdir -p "$CR"
  run "$T/cb/cb.json" "$CR/ref.exr" --spp "$REF_SPP" --passes "$REF_PASSES" --seed 99 >/dev/null
fi
cref=$($X errest "$CR/ref.exr")
cu=$(run "$T/cb/cb.json" "$T/u64.exr" --spp 64 --seed "$SEED")
eu=$(truerr "$T/u64.exr" "$CR/ref.exr" "$cref")
ca=$(run "$T/cb/cb.json" "$T/a64.exr" --target-error "$eu" --spp "$CAP" --seed "$SEED")
ea=$(truerr "$T/a64.exr" "$CR/ref.exr" "$cref")
echo "overhead cornell128: uniform 64 spp $cu s true $eu; adaptive to $eu: $ca s true $ea; ratio $(awk -v a="$ca" -v u="$cu" 'BEGIN { printf "%.3f", a / u }')" >>"$TXT"
cat "$TXT"

{
  echo "set terminal pngcairo size 1200,800; set output '$OUT/adaptive.png'"
  echo "set logscale xy; set xlabel 'CPU seconds'; set ylabel 'true relRMSE'; set key outside"
  printf "plot "
  sep=""
  for s in $SCENES; do
    printf "%s'%s' index 0 using 2:3 with linespoints title '%s uniform', '%s' index 1 using 2:3 with points pt 7 title '%s adaptive'" \
      "$sep" "$OUT/adaptive-$s.dat" "$s" "$OUT/adaptive-$s.dat" "$s"
    sep=", "
  done
  echo
} | plot "$OUT/adaptive.png"
