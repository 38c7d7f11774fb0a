#!/bin/sh
# Benchmark: participating media, error against time, against an honest reference.
#
# For each scene (scenes/fog_spot: a spot light in a fog box, light shafts; scenes/cornell_fog:
# the Cornell box in thin fog; scenes/smoke: a dense grid cloud, strong multiple scattering)
# and nothing tuned per scene beyond its JSON:
#  1. The reference: VPT (--media-method vpt) at a path length that no longer matters. Probes
#     at PROBE_SPP spp render the scene at each max_depth of DEPTHS with the same seed
#     (common random numbers: the deeper image holds the same paths, only longer, so the
#     change of the mean is the light of the extra vertices with little noise); the first
#     depth whose mean moved less than the reference's standard error (the probe's, from its
#     variance channels, scaled to REF_SPP) from the depth before is the reference depth.
#     The reference is two independent seeds of REF_SPP/2 spp each at that depth, averaged;
#     its own relRMSE is RMS(A - B) / (2 mean): E|A - B|^2 = 2 var of one seed, and the
#     average has var / 2 (a bias the two seeds share, e.g. truncation, does not show in it:
#     that is what the depth search is for). Cached under bench-out/ref/ by a key of the
#     scene folder's files and these settings (not the binaries; REF_REDO=1 redoes it).
#  2. The photon method at its defaults (the scene's volume.method, no override) at the spp
#     of BUDGETS, and VPT, both at the reference depth, VPT at spp chosen (from one calibration render)
#     to take about the same times (one more VPT render past either end of the photon
#     method's times that the calibrated ones miss). Time is that of the whole master process (photon pass,
#     worker start, scene build, render, EXR written): wall time, or with TIME=cpu the CPU
#     seconds of the master and its worker. Each budget renders once per seed of SEEDS, and
#     its row holds the mean time and the RMS over the seeds of: relRMSE against the
#     reference, the same after an 8x8 box filter (low-frequency error: blotches), the
#     renderer's own estimate from its variance channels (exrtool errest); then the
#     estimate's ratio to the true error; for the photon method the ratio to VPT's relRMSE at the same
#     time (VPT's error-time curve interpolated on log-log axes; '*' marks an extrapolation),
#     and the same for the low-frequency parts (lf_vs_vpt);
#     per method the least-squares log-log slope of error against time.
# Writes bench-out/media.txt, bench-out/media.png (gnuplot) and bench-out/media-SCENE.dat.
# Timings are measurements of one run, never assertions; speed only as ratios of this run.
# Usage: BUILD=build sh scripts/bench_media.sh
#   env: SCENES ("fog_spot cornell_fog smoke"), BUDGETS (photon method spp, "2 8 30 100"; at 1 spp
#        the variance channels, hence errest, are 0),
#        REF_SPP (4096), PROBE_SPP (64), DEPTHS ("8 16 32 64"), BOX (8), SEEDS ("11 12 13": each
#        budget renders once per seed and reports the mean time and the RMS of each error over
#        the seeds: one image's error is a random draw, the method's is its expectation),
#        VPT_DEPTH ("ref", or "scene" for the scene's own max_depth), REF_REDO (0),
#        TIME ("wall", or "cpu": user + system seconds of the master and its worker, steadier on a
#        loaded machine), EXTRA (more photon methods, e.g. "beams", rendered with --media-method at
#        the same BUDGETS; each gets its rows, slope and ratio to VPT)
set -eu
. scripts/lib.sh
SCENES=${SCENES:-"fog_spot cornell_fog smoke"}
BUDGETS=${BUDGETS:-"2 8 30 100"}
REF_SPP=${REF_SPP:-4096}
PROBE_SPP=${PROBE_SPP:-64}
DEPTHS=${DEPTHS:-"8 16 32 64"}
BOX=${BOX:-8}
SEEDS=${SEEDS:-"11 12 13"}
SEED=${SEEDS%% *}
VPT_DEPTH=${VPT_DEPTH:-ref}
REF_REDO=${REF_REDO:-0}
TIME=${TIME:-wall}
EXTRA=${EXTRA:-}
CAL_SPP=8
bench_init bmedia gnuplot-nox bc
M="$BUILD/master"
X="$BUILD/exrtool"
mkdir -p "$OUT/ref"

# render SCENE OUT SPP SEED [args]: one master run; prints its wall seconds (process start
# to exit, photon pass included).
render() {
  r_s=$1; r_o=$2; r_spp=$3; r_seed=$4; shift 4
  if [ "$TIME" = cpu ]; then tsecs=cpu_secs; else tsecs=wall_secs; fi
  $tsecs "$M" "scenes/$r_s/$r_s.json" -o "$r_o" --workers 1 --threads "$CORES" --no-journal --spp "$r_spp" \
    --seed "$r_seed" "$@"
}
pass_secs() { sed -n 's/.*photon pass: .* in \([0-9.]*\) s on.*/\1/p' "$1" | head -1; }
# measure SCENE OUT SPP [args]: render once per seed of SEEDS; prints "secs relRMSE lowfreq
# errest pass_s": the mean time and photon-pass time, the RMS over the seeds of each error.
measure() {
  m_s=$1; m_o=$2; m_spp=$3; shift 3
  for m_seed in $SEEDS; do
    m_t=$(render "$m_s" "$m_o" "$m_spp" "$m_seed" "$@")
    m_ps=$(pass_secs "$T/log")
    echo "$m_t $("$X" relrmse "$m_o" "$REF") $("$X" relrmse "$m_o" "$REF" --box "$BOX") $("$X" errest "$m_o") ${m_ps:-0}"
  done | awk '{ n++; t += $1; r += $2 * $2; l += $3 * $3; e += $4 * $4; p += $5 }
    END { printf "%.4f %.9g %.9g %.9g %.4f\n", t / n, sqrt(r / n), sqrt(l / n), sqrt(e / n), p / n }'
}

# reference SCENE: sets RDIR (the cache folder holding ref.exr and ref.txt), rendering what
# is missing.
reference() {
  sc=$1
  # v2: VPT's area-light sampling changed (equiangular toward area lights, an emitter's
  # light times the transmittance); v1 references of scenes with area lights were noisier.
  key=$( (find "scenes/$sc" -type f | LC_ALL=C sort | xargs cat; echo "ref v2 $REF_SPP $PROBE_SPP $DEPTHS") | sha256sum | cut -c1-16)
  RDIR="$OUT/ref/$sc-$key"
  if [ "$REF_REDO" != 1 ] && [ -f "$RDIR/ref.txt" ] && [ -f "$RDIR/ref.exr" ]; then
    echo "media: $sc: cached reference $RDIR" >&2
    return 0
  fi
  rm -rf "$RDIR" "$RDIR.tmp"
  mkdir -p "$RDIR.tmp"
  echo "media: $sc: reference depth search, vpt at $PROBE_SPP spp, max_depth $DEPTHS" >&2
  prev=""; pmean=""; dref=""; note=""; mv_=0; sref=0
  for d in $DEPTHS; do
    render "$sc" "$RDIR.tmp/probe-$d.exr" "$PROBE_SPP" 7 --media-method vpt --max-depth "$d" >/dev/null
    set -- $("$X" semean "$RDIR.tmp/probe-$d.exr")
    mean=$1; se=$2
    # the reference's standard error: the probe's, scaled from PROBE_SPP to REF_SPP spp
    sref=$(awk -v se="$se" -v a="$PROBE_SPP" -v b="$REF_SPP" 'BEGIN { printf "%.6g", se * sqrt(a / b) }')
    echo "depth $d: mean $mean, standard error $se at $PROBE_SPP spp ($sref at $REF_SPP spp)" >>"$RDIR.tmp/probes.txt"
    if [ -n "$prev" ]; then
      mv_=$(awk -v a="$mean" -v b="$pmean" 'BEGIN { d = a - b; printf "%.6g", d }')
      if awk -v m="$mv_" -v s="$sref" 'BEGIN { if (m < 0) m = -m; exit !(m < s) }'; then
        dref=$d
        note="mean moved $mv_ from max_depth $prev to $d, less than the reference's standard error $sref"
        break
      fi
    fi
    prev=$d; pmean=$mean
  done
  if [ -z "$dref" ]; then
    dref=$prev
    note="NOT CONVERGED: the mean still moved $mv_ from the depth before to $dref, more than the reference's standard error $sref"
  fi
  half=$((REF_SPP / 2))
  echo "media: $sc: reference, vpt, max_depth $dref, 2 seeds x $half spp" >&2
  ta=$(render "$sc" "$RDIR.tmp/a.exr" "$half" 1001 --media-method vpt --max-depth "$dref")
  tb=$(render "$sc" "$RDIR.tmp/b.exr" "$half" 1002 --media-method vpt --max-depth "$dref")
  logged "$X" average "$RDIR.tmp/ref.exr" "$RDIR.tmp/a.exr" "$RDIR.tmp/b.exr"
  rel=$(awk -v r="$("$X" relrmse "$RDIR.tmp/a.exr" "$RDIR.tmp/b.exr")" 'BEGIN { printf "%.6g", r / 2 }')
  rlf=$(awk -v r="$("$X" relrmse "$RDIR.tmp/a.exr" "$RDIR.tmp/b.exr" --box "$BOX")" 'BEGIN { printf "%.6g", r / 2 }')
  set -- $("$X" semean "$RDIR.tmp/ref.exr")
  # ref.txt: depth, relRMSE, low-frequency relRMSE, mean, seconds of the two renders, note
  printf '%s %s %s %s %s\n%s\n' "$dref" "$rel" "$rlf" "$1" "$(echo "$ta + $tb" | bc -l)" "$note" >"$RDIR.tmp/ref.txt"
  rm -f "$RDIR.tmp/a.exr" "$RDIR.tmp/b.exr" "$RDIR.tmp"/probe-*.exr "$RDIR.tmp"/*.stats.json
  mv "$RDIR.tmp" "$RDIR"
}

: >"$T/summary"
: >"$OUT/media.txt"
for sc in $SCENES; do
  [ -f "scenes/$sc/$sc.json" ] || { echo "bench_media: no scene scenes/$sc/$sc.json" >&2; exit 1; }
  reference "$sc"
  REF="$RDIR/ref.exr"
  { read -r dref rrel rlf rmean rsecs; read -r note; } <"$RDIR/ref.txt"
  pm=$(sed -n 's/.*"method": *"\([a-z]*\)".*/\1/p' "scenes/$sc/$sc.json" | head -1)
  pm=${pm:-beam}
  sdepth=$(sed -n 's/.*"max_depth": *\([0-9]*\).*/\1/p' "scenes/$sc/$sc.json" | head -1)
  vdepth=$dref
  [ "$VPT_DEPTH" = scene ] && vdepth=$sdepth
  : >"$T/rows-$sc"
  # The photon method at its defaults (no --media-method: the scene's method and settings),
  # at VPT's depth: max_depth bounds both methods' paths alike (docs/media.md).
  for spp in $BUDGETS; do
    echo "media: $sc: $pm, $spp spp (max_depth $vdepth)" >&2
    echo "$pm $spp $(measure "$sc" "$T/p.exr" "$spp" --max-depth "$vdepth")" >>"$T/rows-$sc"
  done
  for xm in $EXTRA; do
    for spp in $BUDGETS; do
      echo "media: $sc: $xm, $spp spp (max_depth $vdepth)" >&2
      echo "$xm $spp $(measure "$sc" "$T/p.exr" "$spp" --max-depth "$vdepth" --media-method "$xm")" >>"$T/rows-$sc"
    done
  done
  # VPT: spp for the same times, from one calibration render at CAL_SPP spp.
  tc=$(render "$sc" "$T/c.exr" "$CAL_SPP" "$SEED" --media-method vpt --max-depth "$vdepth")
  for t in $(awk -v m="$pm" '$1 == m {print $3}' "$T/rows-$sc"); do
    spp=$(awk -v t="$t" -v c="$tc" -v n="$CAL_SPP" 'BEGIN { s = int(n * t / c + 0.5); print s < 1 ? 1 : s }')
    echo "media: $sc: vpt, $spp spp (max_depth $vdepth)" >&2
    echo "vpt $spp $(measure "$sc" "$T/v.exr" "$spp" --media-method vpt --max-depth "$vdepth")" >>"$T/rows-$sc"
  done
  # VPT's curve must span the photon method's times, so that its ratios are interpolated,
  # not extrapolated: one more VPT render past each end it missed (the calibration is one
  # render, and VPT's time per sample is not constant), its spp scaled by the time missing.
  for end in hi lo; do
    set -- $(awk -v m="$pm" -v e="$end" '$1 == m { if (!n++ || (e == "hi" ? $3 > p : $3 < p)) p = $3 }
             $1 == "vpt" { if (!k++ || (e == "hi" ? $3 > v : $3 < v)) { v = $3; s = $2 } }
             END { if (e == "hi" && v < p) print int(s * p / v * 1.15) + 1
                   else if (e == "lo" && v > p && s > 1) { x = int(s * p / v * 0.85); print x < 1 ? 1 : x } }' "$T/rows-$sc")
    [ -n "${1:-}" ] || continue
    echo "media: $sc: vpt, $1 spp (max_depth $vdepth), to span $pm's times" >&2
    echo "vpt $1 $(measure "$sc" "$T/v.exr" "$1" --media-method vpt --max-depth "$vdepth")" >>"$T/rows-$sc"
  done
  # Each method's rows in order of time (the renders that span the photon method's times
  # come last otherwise), for the table and the plot's lines.
  awk -v order="$pm $EXTRA vpt" 'BEGIN { n = split(order, o, " "); for (i = 1; i <= n; i++) rank[o[i]] = i }
    { print rank[$1], $0 }' "$T/rows-$sc" | sort -s -k1,1n -k4,4g | cut -d' ' -f2- >"$T/rows2" && mv "$T/rows2" "$T/rows-$sc"
  # The true error: the reference's own error removed in quadrature (the two are
  # independent, so E relRMSE^2 = true^2 + ref_rel^2); 0 where the reference's noise hides it.
  # Columns of rows: method spp secs relRMSE lowfreq errest pass_s true lowfreq_true
  awk -v rr="$rrel" -v rl="$rlf" '{ x = $4 * $4 - rr * rr; y = $5 * $5 - rl * rl
    print $0, (x > 0 ? sqrt(x) : 0), (y > 0 ? sqrt(y) : 0) }' "$T/rows-$sc" >"$T/rows2" && mv "$T/rows2" "$T/rows-$sc"
  awk -v m=vpt '$1 == m {print $3, $8}' "$T/rows-$sc" >"$T/vcurve"
  awk -v m=vpt '$1 == m {print $3, $9}' "$T/rows-$sc" >"$T/vcurve-lf"
  # matched MEASURE CURVE: geometric mean over the photon budgets of photon / VPT at the same time
  matched() {
    awk -v m="$pm" -v c="$1" '$1 == m {print $3, $c}' "$T/rows-$sc" | while read -r t r; do
      vr=$(loglog_interp "$t" <"$2"); echo "$r ${vr%\*}"; done |
      awk '$1 > 0 && $2 > 0 && $2 != "nan" { s += log($1 / $2); n++ } END { if (n) printf "%.3f", exp(s / n); else print "nan" }'
  }
  gm=$(matched 8 "$T/vcurve")
  gml=$(matched 9 "$T/vcurve-lf")
  {
    echo "== $sc: reference vpt, max_depth $dref (scene: $sdepth), $REF_SPP spp (2 seeds x $((REF_SPP / 2))), mean $rmean, own relRMSE $rrel, low-frequency (box $BOX) $rlf, $(printf '%.1f' "$rsecs") s"
    echo "   depth: $note"
    printf '%-6s %5s %8s %9s %9s %9s %9s %9s %8s %9s %9s %8s %8s %8s\n' method spp secs relRMSE true lowfreq lf_true errest est/true ref_rel ref_lf vs_vpt lf_vs_vpt pass_s
    while read -r m spp t r lf e ps tr tl; do
      ratio=""
      lratio=""
      if [ "$m" != vpt ]; then
        vr=$(loglog_interp "$t" <"$T/vcurve")
        ratio=$(awk -v r="$tr" -v v="${vr%\*}" -v x="$vr" 'BEGIN { if (r > 0 && v > 0) printf "%.3f%s", r / v, (x ~ /\*/) ? "*" : ""; else print "-" }')
        vl=$(loglog_interp "$t" <"$T/vcurve-lf")
        lratio=$(awk -v r="$tl" -v v="${vl%\*}" -v x="$vl" 'BEGIN { if (r > 0 && v > 0) printf "%.3f%s", r / v, (x ~ /\*/) ? "*" : ""; else print "-" }')
      fi
      awk -v m="$m" -v spp="$spp" -v t="$t" -v r="$r" -v lf="$lf" -v e="$e" -v tr="$tr" -v tl="$tl" -v rr="$rrel" -v rl="$rlf" -v q="$ratio" -v ql="$lratio" -v ps="$ps" \
        'BEGIN { printf "%-6s %5d %8.3f %9.5f %9.5f %9.5f %9.5f %9.5f %8s %9.5f %9.5f %8s %8s %8s\n", m, spp, t, r, tr, lf, tl, e,
                 (tr > 0 && e > 0 ? sprintf("%.3f", e / tr) : "-"), rr, rl, (q == "" ? "-" : q), (ql == "" ? "-" : ql), (m == "vpt" ? "-" : sprintf("%.3f", ps)) }'
    done <"$T/rows-$sc"
    for m in "$pm" $EXTRA vpt; do
      sl=$(awk -v m="$m" '$1 == m {print $3, $8}' "$T/rows-$sc" | loglog_slope)
      sll=$(awk -v m="$m" '$1 == m {print $3, $9}' "$T/rows-$sc" | loglog_slope)
      span=$(awk -v m="$m" '$1 == m { if (!n++ || $3 < lo) lo = $3; if ($3 > hi) hi = $3 } END { printf "%.1f", hi / lo }' "$T/rows-$sc")
      echo "   $m: log-log slope of the true relRMSE against time $sl (low-frequency $sll), over a time span of ${span}x (-0.5: unbiased Monte Carlo)"
    done
    echo "   $pm / vpt true relRMSE at matched time: $gm (geometric mean over the budgets; low-frequency $gml); below 1: $pm wins"
    for xm in $EXTRA; do
      pm0=$pm; pm=$xm
      echo "   $xm / vpt true relRMSE at matched time: $(matched 8 "$T/vcurve") (low-frequency $(matched 9 "$T/vcurve-lf"))"
      pm=$pm0
    done
    echo
  } | tee -a "$OUT/media.txt"
  echo "$sc $pm $dref $rrel $gm $gml" >>"$T/summary"
  awk '{print $1, $2, $3, $4, $5, $8, $9}' "$T/rows-$sc" >"$OUT/media-$sc.dat"
  echo "$rrel $rlf" >"$OUT/media-$sc-ref.dat"
done

{
  echo "Summary (1 worker x $CORES threads; load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)):"
  printf '%-12s %-6s %9s %9s %14s %14s\n' scene method ref_depth ref_rel "true/vpt" "lf_true/vpt"
  awk '{ printf "%-12s %-6s %9s %9.5f %14s %14s\n", $1, $2, $3, $4, $5, $6 }' "$T/summary"
} | tee -a "$OUT/media.txt"

set -- $SCENES
n=$#
{
  echo "set terminal png size $((460 * n)),520 noenhanced"
  echo "set output \"$OUT/media.png\""
  if [ "$TIME" = cpu ]; then clock="CPU time"; else clock="wall time"; fi
  echo "set multiplot layout 1,$n title \"Media: true relRMSE vs $clock\""
  echo "set logscale xy; set grid; set xlabel \"seconds (whole run, photon pass included)\"; set ylabel \"relRMSE\"; set key below"
  for sc in $SCENES; do
    d="$OUT/media-$sc.dat"
    r=$(cut -d' ' -f1 "$OUT/media-$sc-ref.dat")
    echo "set title \"$sc\""
    echo "plot \"< grep -v '^vpt' $d\" using 3:6 with linespoints lt 1 pt 7 title \"photon (scene default)\", \"< grep -v '^vpt' $d\" using 3:7 with linespoints lt 1 pt 6 title \"photon, box $BOX\", \"< grep '^vpt' $d\" using 3:6 with linespoints lt 2 pt 5 title \"vpt\", \"< grep '^vpt' $d\" using 3:7 with linespoints lt 2 pt 4 title \"vpt, box $BOX\", $r with lines lt 0 title \"reference's own relRMSE\""
  done
  echo "unset multiplot"
} | plot "$OUT/media.png"
