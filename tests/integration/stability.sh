#!/bin/sh
# Hard media stay renderable (docs/design.md, principle 4) and a signal stops a render
# promptly without losing anything (principle 5):
# - the smoke with its density x1e6 and x1e-6, albedo 1, g = 0.99, a gather radius of
#   1e-5, and all of these at once, each rendered small by vpt, march and beam: every
#   render finishes, drops no NaN/Inf sample, no ray reaches the tracking bound, and the
#   image is finite;
# - x1e-6: the image matches the scene without the medium (means within 2 % at 64 spp);
# - x1e6 and albedo 0: the cloud is opaque: a view of the floor through it is black (the
#   same view without the medium is not);
# - SIGTERM during a long photon pass: the master exits within 10 s with one error line,
#   no output, no journal;
# - SIGTERM during rendering: the master exits within 10 s with one error line, no output,
#   its local workers gone, journaled tiles kept; a restart resumes from the journal and
#   the image is bit-identical to an uninterrupted render.
# The time limits are liveness bounds, not timings. Ends with "integration: N passed, N
# failed". Usage: BUILD=build sh tests/integration/stability.sh
. "$(dirname "$0")/lib.sh"
lib_init stability
ms() { date +%s%3N; }
t_start=$(ms)
SMOKE=scenes/smoke

# variant NAME 'python statements on s (the scene) and md (the smoke medium)'
variant() {
  mkdir -p "$T/$1"
  cp "$SMOKE/floor.obj" "$SMOKE/smoke.grid" "$T/$1/"
  python3 - "$SMOKE/smoke.json" "$T/$1/smoke.json" "$2" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))
s["render"].update({"width": 32, "height": 32, "tile_size": 16})
md = s.get("media", {}).get("smoke")
exec(sys.argv[3])
json.dump(s, open(sys.argv[2], "w"), indent=1)
EOF
}
# nan_samples of a render (top level of OUT.stats.json)
nans() { python3 -c 'import json, sys; print(json.load(open(sys.argv[1] + ".stats.json"))["nan_samples"])' "$1" 2>/dev/null; }
# the image's mean, when it is a finite number
finite_mean() { $X mean "$1" 2>/dev/null | python3 -c 'import math, sys
v = sum(map(float, sys.stdin.read().split()[:3])) / 3; print(v) if math.isfinite(v) else sys.exit(1)' 2>/dev/null; }

variant x1e6 'md["density"]["scale"] *= 1e6'
variant x1em6 'md["density"]["scale"] *= 1e-6'
variant albedo1 'md["sigma_a"] = [0, 0, 0]'
variant g099 'md["g"] = 0.99'
variant radius 's["volume"]["radius"] = 1e-5'
variant all 'md["density"]["scale"] *= 1e6; md["sigma_a"] = [0, 0, 0]; md["g"] = 0.99; s["volume"]["radius"] = 1e-5'
variant nomed 'del s["media"]; del s["volume"]'
A="--spp 2 --no-journal --workers 1 --threads 2 --photons 20000"

for v in x1e6 x1em6 albedo1 g099 radius all; do
  for meth in vpt march beam; do
    out="$T/$v-$meth.exr"
    t0=$(ms)
    TMO=120 run $M "$T/$v/smoke.json" -o "$out" $A --media-method $meth && r=0 || r=1
    n=$(nans "$out")
    mean=$(finite_mean "$out") || mean=""
    echo "stability: $v $meth: $(( $(ms) - t0 )) ms, mean ${mean:-not finite}, NaN/Inf samples ${n:-?}"
    if [ $r = 0 ] && [ "$n" = 0 ] && [ -n "$mean" ] && ! grep -q "reached the bound" "$T/log"; then
      ok "smoke $v by $meth: finishes, no NaN/Inf sample, tracking bound never reached, finite image"
    else bad "smoke $v by $meth: finishes, no NaN/Inf sample, tracking bound never reached, finite image"; fi
  done
done

# x1e-6: the scene without its medium, within noise (64 spp: at 2, vpt's noise is ~4 %).
run $M "$T/nomed/smoke.json" -o "$T/nomed.exr" --spp 64 --no-journal --workers 1 --threads 2 && ref=$(finite_mean "$T/nomed.exr") || ref=""
for meth in vpt march beam; do
  run $M "$T/x1em6/smoke.json" -o "$T/thin-$meth.exr" $A --spp 64 --media-method $meth && m=$(finite_mean "$T/thin-$meth.exr") || m=""
  if [ -n "$ref" ] && [ -n "$m" ] && python3 -c 'import sys; a, b = map(float, sys.argv[1:]); sys.exit(abs(a - b) > 0.02 * b)' "$m" "$ref"; then
    ok "x1e-6 by $meth: mean $m, without the medium $ref"
  else bad "x1e-6 by $meth: mean ${m:-?}, without the medium ${ref:-?} (2 %)"; fi
done

# x1e6, albedo 0: a narrow view of the floor through the cloud is black.
view='s["camera"].update({"look_at": [0, 0.5, 0], "fov_y": 3}); s["render"].update({"width": 16, "height": 16})'
variant opaque "md[\"density\"][\"scale\"] *= 1e6; md[\"sigma_a\"] = [2.55, 2.55, 2.55]; md[\"sigma_s\"] = [0, 0, 0]; $view"
variant floor "del s[\"media\"]; del s[\"volume\"]; $view"
run $M "$T/floor/smoke.json" -o "$T/floor.exr" --spp 2 --no-journal --workers 1 --threads 2 && fm=$(finite_mean "$T/floor.exr") || fm=""
for meth in vpt march beam; do
  run $M "$T/opaque/smoke.json" -o "$T/opaque-$meth.exr" $A --media-method $meth && m=$(finite_mean "$T/opaque-$meth.exr") || m=""
  if [ -n "$fm" ] && [ -n "$m" ] && python3 -c 'import sys; a, b = map(float, sys.argv[1:]); sys.exit(not (b > 0 and a <= 1e-6 * b))' "$m" "$fm"; then
    ok "x1e6, albedo 0, by $meth: the floor behind the cloud is black (mean $m; $fm without the medium)"
  else bad "x1e6, albedo 0, by $meth: the floor behind the cloud is black (mean ${m:-?}; ${fm:-?} without the medium)"; fi
done

# wait_exit PID: waits up to 10 s for PID to exit; its exit status in $rc ("" if it did not).
wait_exit() {
  i=0
  while kill -0 "$1" 2>/dev/null && [ $i -lt 100 ]; do sleep 0.1; i=$((i + 1)); done
  if kill -0 "$1" 2>/dev/null; then rc=""; kill -9 "$1" 2>/dev/null; wait "$1" 2>/dev/null; else wait "$1"; rc=$?; fi
}
# errors LOG: the master's error lines
errors() { grep -c "^master: error:" "$1"; }

# SIGTERM during a long photon pass.
$M scenes/smoke/smoke.json -o "$T/pp.exr" --spp 1 --media-method march --photons 100000000 >"$T/pp.log" 2>&1 &
mp=$!
echo $mp >>"$T/pids"
sleep 1.5
t0=$(ms)
kill -TERM $mp
wait_exit $mp
echo "stability: photon pass: exit $(( $(ms) - t0 )) ms after SIGTERM"
if [ -n "$rc" ] && [ "$rc" != 0 ] && [ "$(errors "$T/pp.log")" = 1 ] && grep -q "^master: error: photon pass interrupted" "$T/pp.log" &&
   [ ! -e "$T/pp.exr" ] && [ ! -e "$T/pp.exr.journal" ]; then
  ok "SIGTERM in the photon pass: exit within 10 s, non-zero, one error line, no output, no journal"
else BAD_LOGS=pp.log bad "SIGTERM in the photon pass: exit within 10 s (rc ${rc:-none}), non-zero, one error line, no output, no journal"; fi

# SIGTERM during rendering, then a restart: bit-identical with an uninterrupted render.
R="--spp 512 --tile 16 --workers 1 --threads 2 --media-method vpt"
variant big 's["render"].update({"width": 64, "height": 64})'
$M "$T/big/smoke.json" -o "$T/int.exr" $R >"$T/int.log" 2>&1 &
mp=$!
echo $mp >>"$T/pids"
# Until a few tiles are journaled (each record holds a tile's chunk: the file grows).
i=0
while [ $i -lt 600 ] && [ "$(stat -c %s "$T/int.exr.journal" 2>/dev/null || echo 0)" -lt 12000 ] && kill -0 $mp 2>/dev/null; do
  sleep 0.1; i=$((i + 1))
done
t0=$(ms)
kill -TERM $mp
wait_exit $mp
echo "stability: rendering: exit $(( $(ms) - t0 )) ms after SIGTERM"
sleep 0.2
left=0
for p in $(pgrep -f "$T" 2>/dev/null); do ours "$p" && left=$((left + 1)); done
if [ -n "$rc" ] && [ "$rc" != 0 ] && [ "$(errors "$T/int.log")" = 1 ] && grep -q "^master: error: interrupted" "$T/int.log" &&
   [ ! -e "$T/int.exr" ] && [ -s "$T/int.exr.journal" ] && [ $left = 0 ]; then
  ok "SIGTERM while rendering: exit within 10 s, non-zero, one error line, no output, journal kept, workers gone"
else BAD_LOGS=int.log bad "SIGTERM while rendering: exit within 10 s (rc ${rc:-none}), non-zero, one error line, no output, journal kept, workers gone ($left left)"; fi
run $M "$T/big/smoke.json" -o "$T/int.exr" $R && r1=0 || r1=1
resumed=$(sed -n 's/.* \(tiles\|units\) (\([0-9]*\) from the journal).*/\2/p' "$T/log" | head -1)
run $M "$T/big/smoke.json" -o "$T/ref.exr" $R --no-journal && r2=0 || r2=1
if [ $r1 = 0 ] && [ $r2 = 0 ] && [ "${resumed:-0}" -gt 0 ] && $X cmp "$T/int.exr" "$T/ref.exr"; then
  ok "restart after SIGTERM: $resumed tiles from the journal, bit-identical with an uninterrupted render"
else bad "restart after SIGTERM: ${resumed:-no} tiles from the journal, bit-identical with an uninterrupted render"; fi

echo "stability: $(( $(ms) - t_start )) ms in all"
finish
