#!/bin/sh
# Runs every integration script and ends with one line for CI:
# "integration: N passed, N failed" summed over every script in the two lists below.
# Each script's own output (and its closing line, as "part:", with its wall seconds) is kept.
# The parts of LANE2 mostly wait (silence and stall timeouts, workers that sleep on
# purpose, a master frozen for seconds, one render thread): they run one after another
# beside the parts of LANE1, and their output is printed whole, each part's in one piece,
# once LANE1 is done. LANES=1 runs every part one after another, with live output.
# Usage: BUILD=build sh tests/integration/all.sh
set -u
dir=$(dirname "$0")
LANE1="run.sh loadpeers.sh packets.sh frames.sh framegrid.sh security.sh ssh.sh media.sh textures.sh stability.sh exrtool.sh safety.sh adaptive.sh materials.sh aovs.sh meshes.sh smoke.sh motion.sh showcase.sh"
LANE2="faults.sh reconnect.sh loading.sh"
D=$(mktemp -d /tmp/brume-all.XXXXXX)
lane2=""
stop() {
  [ -n "$lane2" ] && kill "$lane2" 2>/dev/null
  [ -s "$D/current" ] && kill "$(cat "$D/current")" 2>/dev/null
  rm -rf "$D"
  exit 130
}
trap stop INT TERM
pass=0
fail=0
# tally PART OUT: adds the part's closing line in OUT to the sums
tally() {
  line=$(grep "^integration: " "$2" | tail -1)
  p=$(echo "$line" | sed -n 's/^integration: \([0-9]*\) passed, \([0-9]*\) failed.*/\1/p')
  f=$(echo "$line" | sed -n 's/^integration: \([0-9]*\) passed, \([0-9]*\) failed.*/\2/p')
  if [ -z "$p" ]; then
    echo "FAIL: $1 ended without its summary line"
    f=1
    p=0
  fi
  pass=$((pass + p))
  fail=$((fail + f))
}
if [ "${LANES:-2}" = 1 ]; then
  LANE1="$LANE1 $LANE2"
  LANE2=""
else
  # (`sh ... &` with its pid kept: an interrupted all.sh stops the part under way)
  (for s in $LANE2; do
    t0=$(date +%s)
    sh "$dir/$s" >"$D/$s.out" 2>&1 &
    echo $! >"$D/current"
    wait $!
    echo $(($(date +%s) - t0)) >"$D/$s.s"
  done) &
  lane2=$!
  echo "all: $LANE2 run beside the other parts; their output follows theirs"
fi
for s in $LANE1; do
  t0=$(date +%s)
  sh "$dir/$s" 2>&1 | tee "$D/$s.out" | sed '/^integration: /d'
  echo "part $s: $(sed -n 's/^integration: //p' "$D/$s.out" | tail -1) ($(($(date +%s) - t0)) s)"
  tally "$s" "$D/$s.out"
done
if [ -n "$lane2" ]; then
  wait "$lane2"
  lane2=""
  for s in $LANE2; do
    [ -f "$D/$s.out" ] || : >"$D/$s.out"
    sed '/^integration: /d' "$D/$s.out"
    echo "part $s: $(sed -n 's/^integration: //p' "$D/$s.out" | tail -1) ($(cat "$D/$s.s" 2>/dev/null || echo "?") s, beside the others)"
    tally "$s" "$D/$s.out"
  done
fi
rm -rf "$D"
echo "integration: $pass passed, $fail failed"
[ "$fail" = 0 ]
