#!/bin/sh
# Benchmark: adaptive rendering to a target error (docs/adaptive.md) against uniform spp,
# at equal true error, and the calibration of --target-error.
#
# Each entry of SCENES is NAME[:WxH[:E1,E2,...[:REFSPP]]]: scenes/NAME/NAME.json at that
# resolution (the scene's own without one) with those targets (TARGETS without them) and
# reference spp (REF_SPP without it). For each:
#  1. A reference: REF_SPP spp in REF_PASSES passes, seed 99; its own relRMSE is its
#     batch-means estimate (exrtool errest: the passes' streams are independent replicates)
#     and is taken out of every measured error in quadrature: true = sqrt(rel^2 - ref^2).
#     Cached under bench-out/ref-adaptive/ by the scene's files, the resolution and these
#     settings (REF_REDO=1 redoes).
#  2. Adaptive: --target-error E (seed SEED, --spp cap CAP, tiles of ADAPT_TILE px): CPU
#     seconds, true relRMSE, its ratio to E (the calibration), the estimate, the mean spp, the
#     work (rays + camera samples, from the render's stats: a cost the machine's load does
#     not move).
#     With CALIB_SEEDS (e.g. "18 19 20 21 22"), the same again with each of those seeds: a
#     "calibration" line per scene and target gives each run's true / target and their RMS
#     (on a scene whose error is a few bright pixels one image's true error scatters by
#     tens of percent between seeds at any settings, so one seed says little).
#  3. Uniform, the same mechanism: --passes STREAMS (one pass per sampler stream, what a
#     tile of the adaptive render is) at spp 8, 16, 32, ... until the true error is below
#     0.9 x the smallest adaptive one (at most MAX_UNIFORM_SPP); and plain uniform Sobol
#     (one pass) likewise. The uniform CPU time at the adaptive render's true error is
#     interpolated on the log-log error-time curve ('*': extrapolated), and so is its work;
#     the ratios adaptive / uniform are the equal-error time (and work) ratios. SWEEP=0 skips this (calibration
#     only; the ratio columns are then nan).
#  With BASE (a folder holding another build's master and worker, e.g. the commit before a
#  change), each adaptive render of seed SEED runs again with that master (tiles of
#  BASE_TILE px) against the same references and uniform curves: "base" lines.
#  4. Overhead on uniform noise: OVERHEAD_SCENE (the plain Cornell box at 128x128) at 64 spp
#     uniform (streams, and one pass), then adaptive with the target set to the streamed
#     render's true error.
# CPU seconds (user + system of the master and its local worker, /usr/bin/time) on a shared
# machine; timings are measurements of one run, never assertions.
# Writes bench-out/adaptive.txt, bench-out/adaptive.png (gnuplot), bench-out/adaptive-SCENE.dat.
# Usage: BUILD=build sh scripts/bench_adaptive.sh
#   env: SCENES ("dof_motion motion:64x48 textured:160x90 cornell_glass:64x64:0.05 fog_spot:40x30:0.05"),
#        TARGETS ("0.05 0.02 0.01"), REF_SPP (16384), REF_PASSES (16), CAP (16384), SEED (17),
#        MAX_UNIFORM_SPP (16384), STREAMS (2: the sampler's SAMPLER_STREAMS), ADAPT_TILE (32),
#        BASE (none), BASE_TILE (8),
#        OVERHEAD (1), OVERHEAD_REF_SPP (4096), REF_REDO (0), CALIB_SEEDS (none), SWEEP (1)
set -eu
. scripts/lib.sh
SCENES=${SCENES:-"dof_motion motion:64x48 textured:160x90 cornell_glass:64x64:0.05 fog_spot:40x30:0.05"}
TARGETS=${TARGETS:-"0.05 0.02 0.01"}
REF_SPP=${REF_SPP:-16384}
REF_PASSES=${REF_PASSES:-16}
CAP=${CAP:-16384}
SEED=${SEED:-17}
MAX_UNIFORM_SPP=${MAX_UNIFORM_SPP:-16384}
STREAMS=${STREAMS:-2}
ADAPT_TILE=${ADAPT_TILE:-32}
BASE=${BASE:-}
BASE_TILE=${BASE_TILE:-8}
OVERHEAD=${OVERHEAD:-1}
REF_REDO=${REF_REDO:-0}
CALIB_SEEDS=${CALIB_SEEDS:-}
SWEEP=${SWEEP:-1}
bench_init badaptive gnuplot-nox
M="$BUILD/master"
X="$BUILD/exrtool"
mkdir -p "$OUT/ref-adaptive"
TXT="$OUT/adaptive.txt"

# run SCENE_JSON OUT [args]: CPU seconds of one master run with one local worker.
run() { r_j=$1; r_o=$2; shift 2; cpu_secs "$M" "$r_j" -o "$r_o" --workers 1 --threads "$CORES" --no-journal "$@"; }
# run_base: the same with BASE's master.
run_base() { r_j=$1; r_o=$2; shift 2; cpu_secs "$BASE/master" "$r_j" -o "$r_o" --workers 1 --threads "$CORES" --no-journal "$@"; }
# truerr IMG REF REFERR: relRMSE against the reference with the reference's own error removed.
truerr() { awk -v a="$($X relrmse "$1" "$2")" -v r="$3" 'BEGIN { d = a * a - r * r; printf "%.5f\n", (d > 0) ? sqrt(d) : 0 }'; }
# reference JSON NAME: renders (or finds cached) the reference of JSON; prints its folder.
reference() {
  rkey=$(files_key "$(dirname "$1")"/* | cut -c1-12)
  rd="$OUT/ref-adaptive/$2-$rkey-$REF_SPP-$REF_PASSES"
  if [ "$REF_REDO" = 1 ] || [ ! -f "$rd/ref.exr" ]; then
    mkdir -p "$rd"
    rc=$(run "$1" "$rd/ref.exr" --spp "$REF_SPP" --passes "$REF_PASSES" --seed 99)
    echo "reference $2: $REF_SPP spp in $REF_PASSES passes, $rc s CPU" >&2
  fi
  echo "$rd"
}
# sweep JSON REF REFERR DAT MINERR [args]: uniform renders at spp 8, 16, ... into DAT
# ("spp cpu true work") until the error is below 0.9 MINERR or MAX_UNIFORM_SPP.
sweep() {
  w_j=$1 w_r=$2 w_e=$3 w_d=$4 w_m=$5
  shift 5
  : >"$w_d"
  spp=8
  while [ "$spp" -le "$MAX_UNIFORM_SPP" ]; do
    c=$(run "$w_j" "$T/u.exr" --spp "$spp" --seed "$SEED" "$@")
    e=$(truerr "$T/u.exr" "$w_r" "$w_e")
    echo "$spp $c $e $(work "$T/u.exr")" >>"$w_d"
    awk -v e="$e" -v m="$w_m" 'BEGIN { exit !(e < 0.9 * m) }' && break
    spp=$((spp * 2))
  done
}
# at_error DAT ERR: the CPU seconds interpolated at ERR on DAT's uniform curve.
at_error() { awk '{ print $3, $2 }' "$1" | loglog_interp "$2"; }
# at_work DAT ERR: the work interpolated at ERR on DAT's uniform curve.
at_work() { awk '{ print $3, $4 }' "$1" | loglog_interp "$2"; }
ratio() { awk -v a="$1" -v u="${2%\*}" 'BEGIN { if (u == "nan" || !(u + 0 > 0)) print "nan"; else printf "%.3f\n", a / u }'; }

{
  echo "# bench_adaptive: CPU seconds, true relRMSE (reference error removed), on $(nproc) cores;"
  echo "# uniform_s: --passes $STREAMS (the same streams); uniform_1: one pass; adaptive tiles of $ADAPT_TILE px"
  echo "# work: rays + camera samples (the renders' stats); work_s, work_1: the work ratios adaptive / uniform at equal error"
  echo "# scene target cpu_adaptive true true/target est spp_mean uniform_s_cpu ratio_s uniform_1_cpu ratio_1 work_s work_1"
  echo "# base scene target cpu true true/target spp_mean uniform_s_cpu ratio_s uniform_1_cpu ratio_1 work_s work_1 (BASE=$BASE, tiles of $BASE_TILE px)"
} >"$TXT"
for entry in $SCENES; do
  s=${entry%%:*}
  rest=${entry#"$s"}
  rest=${rest#:}
  res=${rest%%:*}
  rest=${rest#"$res"}
  rest=${rest#:}
  tg=$(echo "${rest%%:*}" | tr ',' ' ')
  [ -n "$tg" ] || tg=$TARGETS
  rs=${rest#*:}
  [ "$rs" != "$rest" ] && [ -n "$rs" ] || rs=$REF_SPP
  J=$(scene_at "$s" "$res" "$T/scene-$s")
  RD=$(REF_SPP=$rs reference "$J" "$s${res:+-$res}")
  referr=$($X errest "$RD/ref.exr")
  DAT="$OUT/adaptive-$s.dat"
  : >"$DAT.a"
  : >"$DAT.b"
  minerr=1
  : >"$T/calib"
  for E in $tg; do
    first=1
    for sd in $SEED $CALIB_SEEDS; do
      c=$(run "$J" "$T/a.exr" --target-error "$E" --spp "$CAP" --seed "$sd" --tile "$ADAPT_TILE")
      e=$(truerr "$T/a.exr" "$RD/ref.exr" "$referr")
      est=$($X errest "$T/a.exr")
      sppm=$(sed -n 's/.*spp min [0-9]* mean \([0-9.]*\) max.*/\1/p' "$T/log")
      if [ $first = 1 ]; then
        echo "$E $c $e $est $sppm $(work "$T/a.exr")" >>"$DAT.a"
        if [ -n "$BASE" ]; then
          cb=$(run_base "$J" "$T/b.exr" --target-error "$E" --spp "$CAP" --seed "$sd" --tile "$BASE_TILE")
          eb=$(truerr "$T/b.exr" "$RD/ref.exr" "$referr")
          sppb=$(sed -n 's/.*spp min [0-9]* mean \([0-9.]*\) max.*/\1/p' "$T/log")
          echo "$E $cb $eb $sppb $(work "$T/b.exr")" >>"$DAT.b"
        fi
        minerr=$(awk -v a="$minerr" -v b="$e" 'BEGIN { print (b < a) ? b : a }')
        first=0
      fi
      echo "$E $sd $e $c $sppm" >>"$T/calib"
    done
  done
  if [ -n "$CALIB_SEEDS" ]; then
    # Calibration over the seeds: each run's true / target, and their RMS.
    awk -v s="$s${res:+@$res}" '{ r = $3 / $1; k[$1] = k[$1] sprintf(" %.2f", r); ss[$1] += r * r; n[$1]++
                                   c[$1] += $4; sp[$1] += $5; if (!($1 in o)) o[$1] = ++no }
      END { for (e in o) printf "calibration %s %s: true/target per seed%s; RMS %.3f; mean CPU %.2f s, mean spp %.1f\n",
                                 s, e, k[e], sqrt(ss[e] / n[e]), c[e] / n[e], sp[e] / n[e] }' "$T/calib" | sort -k3,3gr >>"$T/calib.txt"
  fi
  : >"$DAT.s"
  : >"$DAT.1"
  if [ "$SWEEP" = 1 ]; then
    sweep "$J" "$RD/ref.exr" "$referr" "$DAT.s" "$minerr" --passes "$STREAMS"
    sweep "$J" "$RD/ref.exr" "$referr" "$DAT.1" "$minerr" --passes 1
  fi
  while read -r E c e est sppm wk; do
    us=$(at_error "$DAT.s" "$e")
    u1=$(at_error "$DAT.1" "$e")
    printf "%s %s %s %s %.3f %s %s %s %s %s %s %s %s\n" "$s${res:+@$res}" "$E" "$c" "$e" \
      "$(awk -v e="$e" -v t="$E" 'BEGIN { print e / t }')" "$est" "$sppm" "$us" "$(ratio "$c" "$us")" "$u1" \
      "$(ratio "$c" "$u1")" "$(ratio "$wk" "$(at_work "$DAT.s" "$e")")" "$(ratio "$wk" "$(at_work "$DAT.1" "$e")")" >>"$TXT"
  done <"$DAT.a"
  while read -r E cb eb sppb wk; do
    us=$(at_error "$DAT.s" "$eb")
    u1=$(at_error "$DAT.1" "$eb")
    printf "base %s %s %s %s %.3f %s %s %s %s %s %s %s\n" "$s${res:+@$res}" "$E" "$cb" "$eb" \
      "$(awk -v e="$eb" -v t="$E" 'BEGIN { print e / t }')" "$sppb" "$us" "$(ratio "$cb" "$us")" "$u1" \
      "$(ratio "$cb" "$u1")" "$(ratio "$wk" "$(at_work "$DAT.s" "$eb")")" "$(ratio "$wk" "$(at_work "$DAT.1" "$eb")")" >>"$TXT"
  done <"$DAT.b"
  {
    echo "# uniform, $STREAMS streams: spp cpu true work"; cat "$DAT.s"; echo; echo
    echo "# adaptive: target cpu true est spp_mean work"; cat "$DAT.a"; echo; echo
    echo "# uniform, one pass: spp cpu true work"; cat "$DAT.1"
  } >"$DAT"
  rm -f "$DAT.s" "$DAT.a" "$DAT.1" "$DAT.b"
  echo "reference $s${res:+@$res}: own relRMSE $referr" >>"$TXT"
done

# Overhead on uniform noise: the Cornell box at 128x128.
if [ "$OVERHEAD" = 1 ]; then
  CJ=$(scene_at cornell 128x128 "$T/cb")
  CR=$(REF_SPP=${OVERHEAD_REF_SPP:-4096} reference "$CJ" cornell-128x128)
  cref=$($X errest "$CR/ref.exr")
  cs=$(run "$CJ" "$T/us.exr" --spp 64 --seed "$SEED" --passes "$STREAMS")
  es=$(truerr "$T/us.exr" "$CR/ref.exr" "$cref")
  c1=$(run "$CJ" "$T/u1.exr" --spp 64 --seed "$SEED" --passes 1)
  e1=$(truerr "$T/u1.exr" "$CR/ref.exr" "$cref")
  ws=$(work "$T/us.exr")
  ca=$(run "$CJ" "$T/a64.exr" --target-error "$es" --spp "$CAP" --seed "$SEED" --tile "$ADAPT_TILE")
  ea=$(truerr "$T/a64.exr" "$CR/ref.exr" "$cref")
  sa=$(sed -n 's/.*spp min [0-9]* mean \([0-9.]*\) max.*/\1/p' "$T/log")
  {
    echo "overhead cornell128: uniform 64 spp in $STREAMS streams $cs s true $es; one pass $c1 s true $e1;" \
      "adaptive to $es: $ca s true $ea; ratio to streams $(ratio "$ca" "$cs"), to one pass at equal error" \
      "$(awk -v a="$ca" -v u="$c1" -v ea="$ea" -v e1="$e1" 'BEGIN { printf "%.3f", a / (u * (e1 / ea) ^ 2) }') (one pass scaled by (e1/ea)^2)"
    echo "overhead cornell128: adaptive mean spp $sa (tiles of $ADAPT_TILE px), true / target $(awk -v a="$ea" -v e="$es" 'BEGIN { printf "%.3f", a / e }'), work ratio to streams $(ratio "$(work "$T/a64.exr")" "$ws")"
    if [ -n "$BASE" ]; then
      cb=$(run_base "$CJ" "$T/b64.exr" --target-error "$es" --spp "$CAP" --seed "$SEED" --tile "$BASE_TILE")
      eb=$(truerr "$T/b64.exr" "$CR/ref.exr" "$cref")
      echo "overhead cornell128, base (tiles of $BASE_TILE px): adaptive to $es: $cb s true $eb; ratio to streams $(ratio "$cb" "$cs"), work ratio $(ratio "$(work "$T/b64.exr")" "$ws")"
    fi
    echo "reference cornell128: own relRMSE $cref"
  } >>"$TXT"
fi
[ ! -f "$T/calib.txt" ] || cat "$T/calib.txt" >>"$TXT"
cat "$TXT"

{
  echo "set terminal pngcairo size 1200,800 noenhanced; set output '$OUT/adaptive.png'"
  echo "set logscale xy; set xlabel 'CPU seconds'; set ylabel 'true relRMSE'; set key outside"
  printf "plot "
  sep=""
  for entry in $SCENES; do
    s=${entry%%:*}
    printf "%s'%s' index 0 using 2:3 with linespoints title '%s uniform', '%s' index 1 using 2:3 with points pt 7 title '%s adaptive'" \
      "$sep" "$OUT/adaptive-$s.dat" "$s" "$OUT/adaptive-$s.dat" "$s"
    sep=", "
  done
  echo
} | plot "$OUT/adaptive.png"
