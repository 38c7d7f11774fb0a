#!/bin/sh
# The master under load: build/loadpeers plays 16 fake workers (the real protocol: HELLO,
# blob fetches checked by hash, READY, a valid EXR chunk per TILE at once) against a real
# master, over ipc and over tcp with CurveZMQ. Every unit is done and acknowledged
# exactly once, nothing is rejected, and the output decodes to the very pixels the fake
# workers were given (a real render's), for the checker pool and for checks in the loop.
# Usage: BUILD=build sh tests/integration/loadpeers.sh
. "$(dirname "$0")/lib.sh"
lib_init load
L=$BUILD/loadpeers
port() { echo $((20000 + ($$ + 7) % 20000)); }

# The pixels the fake workers send: a real render of the Cornell box at 1 spp, 32 px tiles.
run $M scenes/cornell/cornell.json -o "$T/ref.exr" --workers 1 --spp 1 --tile 32 || bad "reference render"

# load NAME ENDPOINT MASTER_OPTIONS... : master and 16 fake workers; checks counters and pixels.
load() {
  name=$1 ep=$2
  shift 2
  timeout 120 $M scenes/cornell/cornell.json -o "$T/$name.exr" --spp 1 --tile 32 --workers 0 --bind "$ep" "$@" \
    >"$T/m.log" 2>&1 &
  mp=$!
  echo $mp >>"$T/pids"
  timeout 120 $L "$ep" -n 16 --image "$T/ref.exr" --master-pid $mp $KEYARGS >"$T/log" 2>&1 && lr=0 || lr=1
  wait $mp && mr=0 || mr=1
  cat "$T/m.log" >>"$T/log"
  units=256
  if [ $lr = 0 ] && [ $mr = 0 ] && grep -q "acked $units acked_twice [0-9]* unacked 0 peers 16" "$T/log" &&
    [ "$(counter tiles_done "$T/$name.exr")" = $units ] && [ "$(counter workers_joined "$T/$name.exr")" = 16 ]; then
    ok "$name: 16 fake workers, every one of $units tiles done and acknowledged"; else bad "$name: 16 fake workers, every one of $units tiles done and acknowledged"; fi
  rej=0
  for c in results_invalid results_stale results_not_ours results_nonfinite rejected_decode rejected_envelope \
    rejected_unknown_peer rejected_unexpected rejected_wrong_job rejected_blob_req tiles_reissued evicted_silent \
    evicted_stalled auth_rejects; do
    v=$(counter $c "$T/$name.exr")
    [ "$v" = 0 ] || { echo "  $c = $v"; rej=1; }
  done
  dup=$(counter results_duplicate "$T/$name.exr") cp=$(counter straggler_copies "$T/$name.exr")
  if [ $rej = 0 ] && [ -n "$dup" ] && [ "$dup" -le "$cp" ]; then
    ok "$name: nothing rejected, duplicates ($dup) only from straggler copies ($cp)"; else bad "$name: nothing rejected, duplicates ($dup) only from straggler copies ($cp)"; fi
  if $X cmp "$T/ref.exr" "$T/$name.exr" >"$T/log" 2>&1; then
    ok "$name: the output holds every tile, bit-identical to the pixels sent"; else bad "$name: the output holds every tile, bit-identical to the pixels sent"; fi
}

KEYARGS=
load ipc "ipc://$T/m.sock"
load inloop "ipc://$T/m2.sock" --check-threads 0 --no-journal

$M --keygen "$T/master.key" >/dev/null && $M --keygen "$T/w.key" >/dev/null
cp "$T/w.key.pub" "$T/allow"
KEYARGS="--key $T/w.key $T/master.key.pub"
load curve "tcp://127.0.0.1:$(port)" --curve-secret "$T/master.key" --allow "$T/allow"
finish
