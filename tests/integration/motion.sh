#!/bin/sh
# Analytic motion blur (camera.motion_blur "analytic", docs/motion.md): the same decoded
# pixels for 1 or 3 workers, other thread counts and tile sizes, on scenes/motion (keys,
# deformation frames, a moving sphere) and scenes/fan (fast rotation); analytic is not a
# no-op; a bad value is a file:line:col error. Ends with "integration: N passed, N failed".
# Usage: BUILD=build sh tests/integration/motion.sh
. "$(dirname "$0")/lib.sh"
lib_init motion

for sc in motion fan; do
  mkdir -p "$T/$sc"
  cp scenes/$sc/* "$T/$sc/"
  sed 's/"shutter_close": 0.5}/"shutter_close": 0.5, "motion_blur": "analytic"}/' scenes/$sc/$sc.json >"$T/$sc/an.json"
  grep -q '"motion_blur": "analytic"' "$T/$sc/an.json" || bad "$sc: cannot make the analytic variant"
  run $M "$T/$sc/an.json" -o "$T/${sc}1.exr" --workers 1 --threads 1 --spp 4 && r1=0 || r1=1
  run $M "$T/$sc/an.json" -o "$T/${sc}3.exr" --workers 3 --threads 2 --spp 4 --tile 8 && r3=0 || r3=1
  if [ $r1 = 0 ] && [ $r3 = 0 ] && grep -q "analytic camera visibility" "$T/log" && $X cmp "$T/${sc}1.exr" "$T/${sc}3.exr"; then
    ok "$sc analytic: 1 vs 3 workers, 1 vs 2 threads, tile 8 vs default bit-identical"
  else bad "$sc analytic: 1 vs 3 workers, 1 vs 2 threads, tile 8 vs default bit-identical"; fi
  run $M "$T/$sc/$sc.json" -o "$T/${sc}s.exr" --workers 1 --spp 4 && r=0 || r=1
  if [ $r = 0 ] && ! $X cmp "$T/${sc}1.exr" "$T/${sc}s.exr" >/dev/null; then ok "$sc: analytic differs from sampled"
  else bad "$sc: analytic differs from sampled"; fi
done

sed 's/"motion_blur": "analytic"/"motion_blur": "smooth"/' "$T/fan/an.json" >"$T/fan/bad.json"
if ! run $M "$T/fan/bad.json" -o "$T/bad.exr" --workers 1 && grep -qE "bad.json:[0-9]+:[0-9]+: .*motion_blur" "$T/log"; then
  ok "bad motion_blur named as file:line:col"; else bad "bad motion_blur named as file:line:col"; fi
finish
