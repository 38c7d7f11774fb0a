#!/bin/sh
# Runs every integration script and ends with one line for CI:
# "integration: N passed, N failed" summed over every script in the list below.
# Each script's own output (and its closing line, as "part:") is kept.
# Usage: BUILD=build sh tests/integration/all.sh
set -u
pass=0
fail=0
rc=0
for s in run.sh loadpeers.sh packets.sh faults.sh frames.sh framegrid.sh security.sh reconnect.sh ssh.sh media.sh textures.sh stability.sh exrtool.sh safety.sh adaptive.sh materials.sh aovs.sh meshes.sh smoke.sh motion.sh showcase.sh loading.sh; do
  out=$(mktemp /tmp/brume-all.XXXXXX)
  sh "$(dirname "$0")/$s" 2>&1 | tee "$out" | sed 's/^integration: /part '"$s"': /'
  line=$(grep "^integration: " "$out" | tail -1)
  p=$(echo "$line" | sed -n 's/^integration: \([0-9]*\) passed, \([0-9]*\) failed.*/\1/p')
  f=$(echo "$line" | sed -n 's/^integration: \([0-9]*\) passed, \([0-9]*\) failed.*/\2/p')
  if [ -z "$p" ]; then
    echo "FAIL: $s ended without its summary line"
    f=1
    p=0
  fi
  pass=$((pass + p))
  fail=$((fail + f))
  rm -f "$out"
done
echo "integration: $pass passed, $fail failed"
[ "$fail" = 0 ]
