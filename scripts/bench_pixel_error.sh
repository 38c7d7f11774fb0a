#!/bin/sh
# bench_pixel_error: the per-pixel bound (--pixel-error P, docs/adaptive.md "A per-pixel
# bound") against the true per-pixel error and against uniform spp.
# For each entry of SCENES (NAME:WxH, scenes/NAME/NAME.json at that resolution):
#  1. A reference: REF_SPP spp in REF_PASSES passes, seed 99 (cached under
#     bench-out/ref-pixel/ by the scene's files and these settings; REF_REDO=1 redoes).
#  2. For each P in BOUNDS: --pixel-error P --spp CAP --tile 32 --seed SEED; `exrtool pixerr`
#     against the reference: the shares of pixels whose true relative error (RMS over R, G,
#     B of the render less the reference, over max(the reference's pixel, 0.1 x its mean))
#     exceeds 2P, P and P / 2, the estimate's own count above P and at the cap, and the work
#     (rays + camera samples of OUT.stats.json: counted, the load does not move it).
#  3. Uniform renders (--passes 2, the default) of seed SEED at 32, 64, ... spp up to
#     MAX_UNIFORM_SPP, the same shares; the uniform spp and work at which the share above P
#     falls to the adaptive render's (interpolated linearly in log spp between the two
#     renders around it; '*': beyond the renders), and the work ratio adaptive / uniform;
#     and the fewest of these spp at which the uniform render's own estimate has at most as
#     many pixels above P as the adaptive render's (the same rule applied to uniform spp).
# Writes bench-out/pixel_error.txt. Usage: BUILD=build sh scripts/bench_pixel_error.sh
# Env: SCENES ("dof_motion:64x48"), BOUNDS ("0.1 0.05"), REF_SPP (65536), REF_PASSES (16),
#      CAP (16384), SEED (17), MAX_UNIFORM_SPP (16384), REF_REDO (0)
set -eu
. scripts/lib.sh
SCENES=${SCENES:-"dof_motion:64x48"}
BOUNDS=${BOUNDS:-"0.1 0.05"}
REF_SPP=${REF_SPP:-65536}
REF_PASSES=${REF_PASSES:-16}
CAP=${CAP:-16384}
SEED=${SEED:-17}
MAX_UNIFORM_SPP=${MAX_UNIFORM_SPP:-16384}
REF_REDO=${REF_REDO:-0}
bench_init bpixel
M="$BUILD/master"
X="$BUILD/exrtool"
TXT="$OUT/pixel_error.txt"
mkdir -p "$OUT/ref-pixel"

run() { r_j=$1; r_o=$2; shift 2; cpu_secs "$M" "$r_j" -o "$r_o" --workers 1 --threads "$CORES" --no-journal "$@"; }
# shares IMG REF P: "above-2P above-P above-P/2" of the true per-pixel error, then the
# pixels whose estimate is above P.
shares() {
  "$X" pixerr "$1" "$3" --ref "$2" | sed -n -e 's/^estimate: over \([0-9]*\) of.*/\1/p' \
    -e 's/^true above 2P, P, P\/2: \([0-9.]*\) \([0-9.]*\) \([0-9.]*\);.*/\1 \2 \3/p' | tac | tr '\n' ' ' | sed 's/ $//'
}

echo "# bench_pixel_error: true per-pixel relative error against a $REF_SPP-spp reference (seed 99), seed $SEED, on $CORES cores" >"$TXT"
echo "# scene P | adaptive: share of pixels with true error > 2P, > P, > P/2; estimate: over P, at the cap; mean spp; work; CPU s |" \
     "uniform: spp and work at the adaptive share above P; work adaptive / uniform | uniform spp whose estimate has as few pixels above P; its work" >>"$TXT"
for entry in $SCENES; do
  s=${entry%%:*}
  res=${entry#*:}
  J=$(scene_at "$s" "$res" "$T/scene-$s")
  rd="$OUT/ref-pixel/$s-$res-$(files_key "$(dirname "$J")"/* | cut -c1-12)-$REF_SPP-$REF_PASSES"
  if [ "$REF_REDO" = 1 ] || [ ! -f "$rd/ref.exr" ]; then
    mkdir -p "$rd"
    rc=$(run "$J" "$rd/ref.exr" --spp "$REF_SPP" --passes "$REF_PASSES" --seed 99)
    echo "reference $s: $REF_SPP spp in $REF_PASSES passes, $rc s CPU" >&2
  fi
  R="$rd/ref.exr"
  # The uniform curve: spp work share-above-P for each P.
  U="$T/uniform-$s.dat"
  : >"$U"
  spp=32
  while [ "$spp" -le "$MAX_UNIFORM_SPP" ]; do
    run "$J" "$T/u.exr" --spp "$spp" --seed "$SEED" >/dev/null
    line="$spp $(work "$T/u.exr")"
    for P in $BOUNDS; do line="$line $(shares "$T/u.exr" "$R" "$P")"; done
    echo "$line" >>"$U"
    echo "uniform $s $spp spp: $line" >&2
    spp=$((spp * 2))
  done
  k=0
  for P in $BOUNDS; do
    c=$(run "$J" "$T/a.exr" --pixel-error "$P" --spp "$CAP" --tile 32 --seed "$SEED")
    sh=$(shares "$T/a.exr" "$R" "$P" | cut -d' ' -f1-3)
    est=$("$X" pixerr "$T/a.exr" "$P" --cap "$CAP" | sed -n 's/^estimate: over \([0-9]*\) of [0-9]* (\([0-9]*\) at the cap).*/\1 \2/p')
    sppm=$(sed -n 's/.*spp min [0-9]* mean \([0-9.]*\) max.*/\1/p' "$T/log")
    wa=$(work "$T/a.exr")
    above=$(echo "$sh" | awk '{print $2}')
    # columns of this P's share above P and estimate's count above P in the uniform curve
    col=$((4 + 4 * k))
    uni=$(awk -v c="$col" -v q="$above" '{ s[NR] = $1; w[NR] = $2; f[NR] = $c }
      END { for (i = 1; i < NR; i++) if (f[i] > q && f[i + 1] <= q) {
              t = (f[i] - q) / (f[i] - f[i + 1]); ls = log(s[i]) + t * (log(s[i + 1]) - log(s[i]))
              lw = log(w[i]) + t * (log(w[i + 1]) - log(w[i])); printf "%.0f %.4g\n", exp(ls), exp(lw); exit }
            if (f[1] <= q) printf "%d* %s*\n", s[1], w[1]; else printf "%d* %s*\n", s[NR], w[NR] }' "$U")
    ratio=$(awk -v a="$wa" -v u="${uni#* }" 'BEGIN { sub(/\*/, "", u); printf "%.3f\n", a / u }')
    same=$(awk -v c="$((col + 2))" -v n="${est% *}" '$c <= n { print $1, $2; f = 1; exit } END { if (!f) print "none", "-" }' "$U")
    echo "$s $P | $sh; $est; $sppm; $wa; $c | $uni; $ratio | $same" >>"$TXT"
    k=$((k + 1))
  done
  sed 's/^/# uniform '"$s"': /' "$U" >>"$TXT"
done
cat "$TXT"
