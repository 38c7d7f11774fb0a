#!/bin/sh
# exrtool's error metrics (relrmse, relrmse --box, errtop, errest, semean, average, oracle, pixerr) on synthetic
# EXRs with known differences, written by `exrtool synth`.
# Usage: BUILD=build sh tests/integration/exrtool.sh
. "$(dirname "$0")/lib.sh"
lib_init exrtool

# near NAME GOT WANT: |GOT - WANT| <= 1e-5 (1 + |WANT|)
near() {
  if awk -v g="$2" -v w="$3" 'BEGIN { d = g - w; if (d < 0) d = -d; a = w < 0 ? -w : w; exit !(g != "" && d <= 1e-5 * (1 + a)) }'; then
    ok "$1: $2"
  else
    bad "$1: got '$2', want $3"
  fi
}

# near3 NAME GOT WANT: |GOT - WANT| <= 1e-3 (1 + |WANT|) (figures printed with 3 decimals)
near3() {
  if awk -v g="$2" -v w="$3" 'BEGIN { d = g - w; if (d < 0) d = -d; a = w < 0 ? -w : w; exit !(g != "" && d <= 1e-3 * (1 + a)) }'; then
    ok "$1: $2"
  else
    bad "$1: got '$2', want $3"
  fi
}

# 9x5 images: REF = 1; A = 1 +- 0.2 in a pixel checkerboard (+ where x + y is even), its
# variance channels 0.01; B = 1.1 everywhere.
$X synth "$T/ref.exr" 9 5 1 && $X synth "$T/a.exr" 9 5 1 --checker 0.2 --var 0.01 && $X synth "$T/b.exr" 9 5 1.1 \
  && ok "synth writes three images" || bad "synth failed"
near "relrmse of identical images" "$($X relrmse "$T/ref.exr" "$T/ref.exr")" 0
near "relrmse, checker +-0.2 on 1" "$($X relrmse "$T/a.exr" "$T/ref.exr")" 0.2
near "relrmse, offset 0.1 on 1" "$($X relrmse "$T/b.exr" "$T/ref.exr")" 0.1
near "relrmse divides by the reference's mean" "$($X relrmse "$T/ref.exr" "$T/b.exr")" "$(awk 'BEGIN { print 0.1 / 1.1 }')"
# --box 8 on 9x5: blocks 8x5 (the checker cancels) and 1x5 (+ - + - +: mean 0.2 / 5 = 0.04):
# RMS over the two blocks sqrt(0.04^2 / 2).
near "relrmse --box 8, partial edge block" "$($X relrmse "$T/a.exr" "$T/ref.exr" --box 8)" "$(awk 'BEGIN { print 0.04 / sqrt(2) }')"
near "relrmse --box 2 keeps an offset" "$($X relrmse "$T/b.exr" "$T/ref.exr" --box 2)" 0.1
near "relrmse --box 1 is relrmse" "$($X relrmse "$T/a.exr" "$T/ref.exr" --box 1)" 0.2
# errest: sqrt(0.01) over the mean of A (23 pixels at 1.2, 22 at 0.8: 45.2 / 45).
near "errest from the variance channels" "$($X errest "$T/a.exr")" "$(awk 'BEGIN { print 0.1 / (45.2 / 45) }')"
near "errest without variance is 0" "$($X errest "$T/ref.exr")" 0
set -- $($X semean "$T/a.exr")
near "semean: mean" "${1:-}" "$(awk 'BEGIN { print 45.2 / 45 }')"
near "semean: standard error sqrt(45 x 0.01) / 45" "${2:-}" "$(awk 'BEGIN { print sqrt(0.45) / 45 }')"
# average of A and REF: the checker halves, the variance quarters.
$X average "$T/m.exr" "$T/a.exr" "$T/ref.exr" || bad "average failed"
near "average: relrmse halves" "$($X relrmse "$T/m.exr" "$T/ref.exr")" 0.1
near "average: variance / 4" "$($X errest "$T/m.exr")" "$(awk 'BEGIN { print 0.05 / (45.1 / 45) }')"
# errtop: the share of the squared error in the worst 0.1 % and 1 % of pixels (1 of 45
# each here): even noise 1/45; one bright pixel over a faint checker nearly all.
set -- $($X errtop "$T/a.exr" "$T/ref.exr")
near "errtop: even checker, top 0.1 %" "${1:-}" "$(awk 'BEGIN { print 1 / 45 }')"
near "errtop: even checker, top 1 %" "${2:-}" "$(awk 'BEGIN { print 1 / 45 }')"
$X synth "$T/s.exr" 9 5 1 --checker 0.01 --spot 3 || bad "synth --spot failed"
set -- $($X errtop "$T/s.exr" "$T/ref.exr" 1)
# pixel (1, 2) is odd: 1 - 0.01 + 3; the 44 others err by 0.01
near "errtop: a firefly's share" "${1:-}" "$(awk 'BEGIN { f = 2.99 * 2.99; print f / (f + 44 * 0.0001) }')"
[ "${3:-} ${4:-}" = "1 2" ] && ok "errtop names the worst pixel (1, 2)" || bad "errtop's worst pixel: '${3:-} ${4:-}'"
# oracle: 4 "renders" of 16x16. Even noise (every pixel 1.0, 1.1, 1.2 or 1.3): no
# allocation gains (1 at every size). One noisy pixel (1, 2) among still ones: the best
# allocation costs what its unit's pixels cost, s^2 / 256 for units of s px (1 from 16 px).
# oracle_at OUTPUT LINE SIZE: the figure after "SIZEpx" on the line starting with LINE.
oracle_at() { printf '%s\n' "$1" | awk -v l="$2" -v s="$3px" 'index($0, l) == 1 { for (i = 1; i < NF; i++) if ($i == s) { print $(i + 1); exit } }'; }
for k in 0 1 2 3; do
  $X synth "$T/o$k.exr" 16 16 1.$k && $X synth "$T/q$k.exr" 16 16 1 --spot $k || bad "synth for oracle failed"
done
even=$($X oracle --spp 1 --floor 4 --target 0.1 --target 0.01 "$T"/o[0-3].exr)
spot=$($X oracle --spp 1 "$T"/q[0-3].exr)
for sz in 1 2 4 8 16 32; do
  near "oracle: even noise, bound at ${sz}px" "$(oracle_at "$even" bound "$sz")" 1
  near3 "oracle: one noisy pixel, bound at ${sz}px" "$(oracle_at "$spot" bound "$sz")" \
    "$(awk -v s="$sz" 'BEGIN { r = s * s / 256; print r < 1 ? r : 1 }')"
done
# even noise: v = var{1, 1.1, 1.2, 1.3} = 1/60 a sample; E = 0.1 needs v / (E mean)^2 = 1.26 spp
# uniform, so the 4-spp floor costs 4 / 1.26 of it; E = 0.01 (126 spp): no gain, no loss.
near3 "oracle: a floor above uniform's spp costs floor / uniform" "$(oracle_at "$even" "target 0.1 " 8 | cut -d/ -f1)" \
  "$(awk 'BEGIN { print 4 / ((1 / 60) / (0.01 * 1.15 * 1.15)) }')"
near3 "oracle: even noise at 126 spp, halves" "$(oracle_at "$even" "target 0.01 " 8 | cut -d/ -f2)" 1
if $X oracle --spp 1 "$T"/o[0-2].exr >/dev/null 2>&1; then bad "oracle with 3 renders accepted"; else ok "oracle needs 4 renders"; fi
if $X relrmse "$T/a.exr" "$T/ref.exr" --box 0 >/dev/null 2>&1; then bad "--box 0 accepted"; else ok "--box 0 refused"; fi
# pixerr: a checker of 0.2 (23 pixels) and black (22) (image mean 0.1022, floor 0.01022),
# every pixel's standard error 0.001: 0.005 relative on the bright pixels, 0.0978 on the
# black ones (against the floor, not their zero); and a true error of 0.1 / 1.1 on every pixel.
$X synth "$T/pe.exr" 9 5 0.1 --checker 0.1 --var 1e-6 || bad "synth for pixerr failed"
[ "$($X pixerr "$T/pe.exr" 0.05)" = "estimate: over 22 of 45 (0 at the cap), worst 0.0978261" ] &&
  [ "$($X pixerr "$T/pe.exr" 0.2)" = "estimate: over 0 of 45 (0 at the cap), worst 0.0978261" ] &&
  ok "pixerr: black pixels against the floor (22 of 45 above 0.05, none above 0.2)" || bad "pixerr: the floor ($($X pixerr "$T/pe.exr" 0.05))"
$X synth "$T/pf.exr" 9 5 1 --var 1e-4 && $X synth "$T/pr.exr" 9 5 1.1 || bad "synth for pixerr failed"
[ "$($X pixerr "$T/pf.exr" 0.05 --ref "$T/pr.exr" | tail -1)" = "true above 2P, P, P/2: 0.0000 1.0000 1.0000; estimate: 0.0000 0.0000 0.0000" ] &&
  ok "pixerr: true error 0.091 above P = 0.05, not 2P; estimate 0.0091 under P/2" || bad "pixerr --ref: $($X pixerr "$T/pf.exr" 0.05 --ref "$T/pr.exr" | tail -1)"
$X synth "$T/small.exr" 4 4 1
if $X relrmse "$T/a.exr" "$T/small.exr" >/dev/null 2>&1; then bad "sizes that differ accepted"; else ok "sizes that differ refused"; fi
finish
