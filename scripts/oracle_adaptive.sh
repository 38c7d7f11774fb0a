#!/bin/sh
# What adaptive sampling can gain at all (docs/adaptive.md, "Oracle"): for each scene,
# ORACLE_SEEDS renders at ORACLE_SPP spp (the default 2 streams, seeds 1000, 1001, ...,
# tiles of 32 px) give each pixel's variance from their spread; `exrtool oracle` then prints
# the best equal-error time ratio of any allocation to uniform spp, per pixel and per unit
# of 2..32 px (8: the adaptive render's blocks; 32: its tiles), without a floor and, for
# each target of TARGETS, with every unit given at least FLOOR spp (an adaptive render's
# first round: ADAPT_FIRST_SPP), in-sample and with the allocation chosen on half the
# renders and judged on the other half. Uniform cost per sample (the renderer counts cost
# per unit, not per pixel).
# Each entry of SCENES is NAME[:WxH] (scenes/NAME/NAME.json at that resolution).
# Renders are cached under bench-out/oracle/ by the scene's files and the settings
# (ORACLE_REDO=1 redoes); CPU seconds of each set are printed.
# Writes bench-out/oracle.txt.
# Usage: BUILD=build sh scripts/oracle_adaptive.sh
#   env: SCENES ("motion:64x48 textured:80x45 dof_motion:64x48 cornell_glass:64x64 fog_spot:40x30"),
#        ORACLE_SPP (256), ORACLE_SEEDS (16), TARGETS ("0.05 0.02 0.01"), FLOOR (32), ORACLE_REDO (0)
set -eu
. scripts/lib.sh
SCENES=${SCENES:-"motion:64x48 textured:80x45 dof_motion:64x48 cornell_glass:64x64 fog_spot:40x30"}
ORACLE_SPP=${ORACLE_SPP:-256}
ORACLE_SEEDS=${ORACLE_SEEDS:-16}
TARGETS=${TARGETS:-"0.05 0.02 0.01"}
FLOOR=${FLOOR:-32}
ORACLE_REDO=${ORACLE_REDO:-0}
bench_init boracle
M="$BUILD/master"
X="$BUILD/exrtool"
TXT="$OUT/oracle.txt"
targs=""
for E in $TARGETS; do targs="$targs --target $E"; done
echo "# oracle_adaptive: $ORACLE_SEEDS renders at $ORACLE_SPP spp per scene; floor $FLOOR spp; units of 1..32 px" >"$TXT"
for entry in $SCENES; do
  s=${entry%%:*}
  res=${entry#"$s"}
  res=${res#:}
  J=$(scene_at "$s" "$res" "$T/scene-$s")
  key=$(files_key "$(dirname "$J")"/* | cut -c1-12)
  d="$OUT/oracle/$s${res:+-$res}-$key-$ORACLE_SPP"
  mkdir -p "$d"
  cpu=0
  files=""
  k=0
  while [ "$k" -lt "$ORACLE_SEEDS" ]; do
    f="$d/seed$((1000 + k)).exr"
    if [ "$ORACLE_REDO" = 1 ] || [ ! -f "$f" ]; then
      c=$(cpu_secs "$M" "$J" -o "$f" --workers 1 --threads "$CORES" --no-journal --spp "$ORACLE_SPP" \
        --seed $((1000 + k)) --tile 32)
      cpu=$(awk -v a="$cpu" -v b="$c" 'BEGIN { print a + b }')
    fi
    files="$files $f"
    k=$((k + 1))
  done
  {
    echo "== $s${res:+@$res} (renders: $cpu CPU s this run)"
    # shellcheck disable=SC2086
    "$X" oracle --spp "$ORACLE_SPP" --floor "$FLOOR" $targs $files
  } >>"$TXT"
done
cat "$TXT"
