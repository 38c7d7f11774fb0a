#!/bin/sh
# Benchmark: participating media, error against time. For three scenes (scenes/fog_spot: a
# spot light in a fog box, light shafts; scenes/smoke: a dense grid cloud, strong multiple
# scattering; scenes/cornell_fog: the Cornell box in thin fog) it renders the volumetric
# path tracer (vpt), Jensen ray marching with a photon lookup per step (march) and with the
# beam radiance estimate (beam) at several spp and two seeds, and reports RMSE against a
# converged VPT reference (REF_SPP spp, cached in bench-out/ by scene and binary), time,
# efficiency 1 / (MSE x time), the photon pass (time, photons/s, bytes/photon, share of the
# render), and on fog_spot a sweep of photon count and gather radius with bias and variance
# split (variance from two seeds: E|A - B|^2 = 2 var; bias^2 = MSE - var), and on smoke the
# shadow transmittance cache against exact marched shadow rays. Writes
# bench-out/media.txt and bench-out/media.png. Timings are measurements, never assertions.
# Usage: BUILD=build sh scripts/bench_media.sh   (env: REF_SPP, SCENES, SWEEP=0 to skip the sweep)
set -eu
. scripts/lib.sh
REF_SPP=${REF_SPP:-2048}
SCENES=${SCENES:-"fog_spot smoke cornell_fog"}
SWEEP=${SWEEP:-1}
bench_init bmedia gnuplot-nox bc
M="$BUILD/master"
X="$BUILD/exrtool"
pass_secs() { sed -n 's/.*photon pass: .* in \([0-9.]*\) s on.*/\1/p' "$1" | head -1; }

render() { # scene method spp seed out [extra args]
  s=$1; m=$2; spp=$3; seed=$4; o=$5; shift 5
  logged "$M" "scenes/$s/$s.json" -o "$o" --workers 1 --threads "$CORES" --no-journal --spp "$spp" --seed "$seed" \
    --media-method "$m" "$@"
}

: >"$T/rows"
for s in $SCENES; do
  REF="$OUT/$s-ref-$REF_SPP-$(ref_key "scenes/$s/$s.json").exr"
  if [ ! -f "$REF" ]; then
    echo "media: rendering the $s reference (vpt, $REF_SPP spp, once)"
    render "$s" vpt "$REF_SPP" 999 "$REF"
  fi
  for cfg in "vpt 4" "vpt 16" "vpt 64" "march 1" "march 4" "beam 1" "beam 4"; do
    set -- $cfg
    m=$1; spp=$2
    for seed in 11 12; do
      render "$s" "$m" "$spp" "$seed" "$T/$seed.exr"
      w=$(render_secs)
      ps=$(pass_secs "$T/log")
      [ -n "$ps" ] && [ ! -s "$T/pass-$s" ] && grep "photon pass:" "$T/log" | head -1 | sed "s/^master: info: media: /$s: /" >"$T/pass-$s"
      echo "$w ${ps:-0}" >"$T/t$seed"
    done
    r1=$("$X" rmse "$T/11.exr" "$REF")
    r2=$("$X" rmse "$T/12.exr" "$REF")
    d=$("$X" rmse "$T/11.exr" "$T/12.exr")
    t1=$(cut -d' ' -f1 "$T/t11"); t2=$(cut -d' ' -f1 "$T/t12"); p1=$(cut -d' ' -f2 "$T/t11")
    # time = render wall + photon pass (the pass is the master's, before the render)
    echo "$s $m $spp $r1 $r2 $d $t1 $t2 $p1" >>"$T/rows"
  done
done

{
  printf 'Media benchmark: %s cores, 1 worker x %s threads; RMSE vs a %s-spp VPT reference; time = render + photon pass; mean of seeds 11, 12\n' "$CORES" "$CORES" "$REF_SPP"
  printf '%-12s %-6s %5s %11s %11s %11s %9s %9s %12s\n' scene method spp rmse bias var secs pass_s 'eff=1/(mse*s)'
  awk '{ mse=($4*$4+$5*$5)/2; var=$6*$6/2; b2=mse-var; if (b2<0) b2=0; t=($7+$8)/2+$9;
         printf "%-12s %-6s %5d %11.6f %11.6f %11.6f %9.3f %9.3f %12.1f\n", $1, $2, $3, sqrt(mse), sqrt(b2), sqrt(var), t, $9, 1/(mse*t) }' "$T/rows"
  echo
  echo "Best efficiency per scene and method, and ratios:"
  awk '{ mse=($4*$4+$5*$5)/2; t=($7+$8)/2+$9; e=1/(mse*t); k=$1" "$2; if (e>best[k]) best[k]=e; sc[$1]=1 }
       END { for (s in sc) {
               printf "%-12s vpt %10.1f  march %10.1f  beam %10.1f   beam/march %6.2fx   best photon map/vpt %6.2fx\n", s,
                 best[s" vpt"], best[s" march"], best[s" beam"], best[s" beam"]/best[s" march"],
                 (best[s" beam"]>best[s" march"]?best[s" beam"]:best[s" march"])/best[s" vpt"] } }' "$T/rows"
  echo
  echo "Photon pass (master, $CORES threads), first run per scene:"
  for s in $SCENES; do [ -f "$T/pass-$s" ] && cat "$T/pass-$s"; done
} | tee "$OUT/media.txt"

for s in $SCENES; do
  for m in vpt march beam; do
    awk -v s="$s" -v m="$m" '$1 == s && $2 == m { mse=($4*$4+$5*$5)/2; print ($7+$8)/2+$9, sqrt(mse) }' "$T/rows" >"$OUT/media-$s-$m.dat"
  done
done

# Shadow transmittance cache against exact marched shadow rays (grid scenes: smoke), beam at
# 1 spp, same seed: the RMSE between the two images is the cache's bias plus the marched
# shadows' own noise.
if echo " $SCENES " | grep -q " smoke "; then
  mkdir -p "$T/exact"
  cp scenes/smoke/* "$T/exact/"
  sed 's/"volume": {/"volume": {"shadow_cache": false, /' scenes/smoke/smoke.json >"$T/exact/smoke.json"
  logged "$M" scenes/smoke/smoke.json -o "$T/c.exr" --workers 1 --threads "$CORES" --no-journal --spp 1 --seed 11
  wc_=$(render_secs)
  logged "$M" "$T/exact/smoke.json" -o "$T/e.exr" --workers 1 --threads "$CORES" --no-journal --spp 1 --seed 11
  we_=$(render_secs)
  REF="$OUT/smoke-ref-$REF_SPP-$(ref_key scenes/smoke/smoke.json).exr"
  printf 'smoke beam 1 spp: shadow cache %.3f s rmse %s; exact marched shadows %.3f s rmse %s; cached vs exact %s\n' \
    "$wc_" "$("$X" rmse "$T/c.exr" "$REF")" "$we_" "$("$X" rmse "$T/e.exr" "$REF")" "$("$X" rmse "$T/c.exr" "$T/e.exr")" | tee -a "$OUT/media.txt"
fi

# Default-settings share: photon pass against the render at the scene's own spp.
for s in $SCENES; do
  logged "$M" "scenes/$s/$s.json" -o "$T/d.exr" --workers 1 --threads "$CORES" --no-journal
  w=$(render_secs); p=$(pass_secs "$T/log")
  # Broadcast: the worker's fetch of every blob (the volume blob is nearly all of it) and
  # its scene build, from the JOB's arrival to READY.
  bc=$(sed -n 's/.*fetched and the scene built in \([0-9.]*\) s.*/\1/p' "$T/log" | sort -n | tail -1)
  printf '%-12s default settings: render %.3f s, photon pass %.3f s, broadcast and load %.3f s (%.1f %% of the render)\n' \
    "$s" "$w" "${p:-0}" "${bc:-0}" "$(echo "100 * (${p:-0} + ${bc:-0}) / $w" | bc -l)" | tee -a "$OUT/media.txt"
done

if [ "$SWEEP" = 1 ]; then
  s=fog_spot
  REF="$OUT/$s-ref-$REF_SPP-$(ref_key "scenes/$s/$s.json").exr"
  echo | tee -a "$OUT/media.txt"
  echo "Sweep on $s (beam, 2 spp): photons x gather radius; bias and variance (RMSE units)" | tee -a "$OUT/media.txt"
  printf '%9s %7s %11s %11s %11s %9s\n' photons radius rmse bias var secs | tee -a "$OUT/media.txt"
  for n in 12500 50000 200000; do
    for r in 0.035 0.07 0.14; do
      render "$s" beam 2 11 "$T/a.exr" --photons "$n" --gather-radius "$r"
      ta=$(render_secs); pa=$(pass_secs "$T/log")
      render "$s" beam 2 12 "$T/b.exr" --photons "$n" --gather-radius "$r"
      ra=$("$X" rmse "$T/a.exr" "$REF"); rb=$("$X" rmse "$T/b.exr" "$REF"); d=$("$X" rmse "$T/a.exr" "$T/b.exr")
      awk -v n="$n" -v r="$r" -v ra="$ra" -v rb="$rb" -v d="$d" -v t="$ta" -v p="${pa:-0}" 'BEGIN {
        mse=(ra*ra+rb*rb)/2; var=d*d/2; b2=mse-var; if (b2<0) b2=0;
        printf "%9d %7.3f %11.6f %11.6f %11.6f %9.3f\n", n, r, sqrt(mse), sqrt(b2), sqrt(var), t+p }' | tee -a "$OUT/media.txt"
    done
  done
fi

set -- $SCENES
n=$#
{
  echo "set terminal png size $((450 * n)),420 noenhanced"
  echo "set output \"$OUT/media.png\""
  echo "set multiplot layout 1,$n title \"Media: RMSE against a converged VPT reference vs time (log-log)\""
  echo "set logscale xy; set grid; set xlabel \"seconds (render + photon pass)\"; set ylabel \"RMSE\""
  for s in $SCENES; do
    echo "set title \"$s\""
    echo "plot \"$OUT/media-$s-vpt.dat\" using 1:2 with linespoints title \"vpt\", \"$OUT/media-$s-march.dat\" using 1:2 with linespoints title \"march (per-step lookups)\", \"$OUT/media-$s-beam.dat\" using 1:2 with linespoints title \"beam\""
  done
  echo "unset multiplot"
} | plot "$OUT/media.png"
