#!/bin/sh
# Workers keep finished tiles until the master acknowledges them (after its journal sync)
# and reconnect when the master goes away. The master is frozen (SIGSTOP) so the worker
# finishes tiles nobody acknowledges, then killed (SIGKILL) and restarted on the same job:
# the worker reconnects, offers the kept tiles, the master takes them, the image is
# identical to an uninterrupted render, and no tile is rendered twice (the worker, which
# lives through both masters, rendered exactly as many tiles as the frame has). A master
# restarted on another job (other seed) gets none of them.
# Ends with "integration: N passed, N failed". Usage: BUILD=build TRIALS=2 sh tests/integration/reconnect.sh
. "$(dirname "$0")/lib.sh"
lib_init reconnect
TRIALS=${RECONNECT_TRIALS:-2}
BAD_LOGS="log1 log wlog"
BAD_TAIL=15
# waits up to $2 tenths of a second for pattern $1 in file $3
wait_for() { n=0; while ! grep -q "$1" "$3" 2>/dev/null && [ $n -lt "$2" ]; do sleep 0.1; n=$((n + 1)); done; grep -q "$1" "$3" 2>/dev/null; }
SCENE=scenes/cornell/cornell.json
ARGS="--spp 16 --tile 32"  # a frame of about 8 s CPU: the freeze lands mid-frame

timeout 120 $M $SCENE -o "$T/ref.exr" --workers 1 --threads 1 $ARGS >"$T/log" 2>&1 || bad "reference render"
# the frame's units: (tile, pass) pairs, 256 tiles in the reference's passes
NT=$(python3 -c 'import json, sys; s = json.load(open(sys.argv[1])); print(s["tiles"] * s["passes"])' "$T/ref.exr.stats.json")

# One trial: $1 = extra arguments of the restarted master, $2 = output name.
trial() {
  out="$T/$2.exr"
  for f in log1 log wlog; do [ -f "$T/$f" ] && mv "$T/$f" "$T/prev.$f"; done
  rm -f "$out" "$out.journal"
  $M $SCENE -o "$out" --workers 0 --bind "ipc://$T/k.sock" $ARGS --worker-timeout-ms 30000 >"$T/log1" 2>&1 &
  mpid=$!
  $W --connect "ipc://$T/k.sock" --threads 1 --timeout-ms 60000 >"$T/wlog" 2>&1 &
  wpid=$!
  echo "$mpid $wpid" >"$T/pids"
  wait_for "joined" 100 "$T/log1"
  sleep "0.$(( $(od -An -N2 -tu2 /dev/urandom) % 8 + 2 ))"
  kill -STOP $mpid            # results now go unacknowledged
  sleep 1                     # the worker finishes the tiles it had queued
  kill -9 $mpid
  wait $mpid 2>/dev/null
  timeout 120 $M $SCENE -o "$out" --workers 0 --bind "ipc://$T/k.sock" $ARGS $1 --worker-timeout-ms 30000 >"$T/log" 2>&1
  r=$?
  wait $wpid
  wr=$?
  kept=$(sed -n 's/.*reconnecting (\([0-9]*\) finished tile(s) kept).*/\1/p' "$T/wlog" | head -1)
  rendered=$(sed -n 's/.*rendered \([0-9]*\) tile(s); .*/\1/p' "$T/wlog" | tail -1)
  fj=$(counter tiles_from_journal "$out"); fk=$(counter tiles_from_kept "$out"); kd=$(counter kept_duplicate "$out")
  as=$(counter tiles_assigned "$out"); sc=$(counter straggler_copies "$out")
}

good=0
kept_total=0
i=0
while [ $i -lt "$TRIALS" ]; do
  i=$((i + 1))
  trial "" "same$i"
  echo "reconnect: trial $i: kept by the worker ${kept:-?}, taken from it $fk (already journaled $kd), from the journal $fj, assigned $as; the worker rendered ${rendered:-?} tiles in all"
  if [ $r = 0 ] && [ $wr = 0 ] && [ -n "$kept" ] && [ "$kept" -ge 1 ] && [ "$fk" -ge 1 ] && [ $((fk + kd)) = "$kept" ] &&
    [ $((fj + fk + as - sc)) = $NT ] && [ "$rendered" = $NT ] && [ "$(counter results_not_ours "$out")" = 0 ] &&
    grep -q "offered $kept finished tile(s) kept for this job" "$T/wlog" && [ ! -e "$T/same$i.exr.journal" ] &&
    $X cmp "$T/ref.exr" "$T/same$i.exr" >/dev/null; then
    good=$((good + 1)); kept_total=$((kept_total + fk))
  else bad "trial $i: master rc $r, worker rc $wr"; fi
done
if [ $good = "$TRIALS" ]; then
  ok "master frozen, killed and restarted: the worker reconnects, delivers $kept_total kept tiles, none rendered twice, identical pixels"
else bad "master frozen, killed and restarted: kept tiles delivered, none rendered twice, identical pixels"; fi

# The restarted master renders another job (another seed): the kept tiles are not its own.
timeout 120 $M $SCENE -o "$T/ref2.exr" --workers 1 --threads 1 $ARGS --seed 2 >"$T/log" 2>&1 || bad "reference render (seed 2)"
trial "--seed 2" "other"
if [ $r = 0 ] && [ $wr = 0 ] && [ -n "$kept" ] && [ "$kept" -ge 1 ] && [ "$fk" = 0 ] && [ "$kd" = 0 ] &&
  ! grep -q "finished tile(s) kept for this job" "$T/wlog" && $X cmp "$T/ref2.exr" "$T/other.exr" >/dev/null; then
  ok "a master restarted on another job gets none of the kept tiles; its image is its own"
else bad "a master restarted on another job gets none of the kept tiles; its image is its own (master rc $r, worker rc $wr)"; fi

# A load that ends after a reconnection: the worker loads slowly while the master is frozen,
# reconnects (at 4, 5 and 7 s of silence), and the load ends (8.5 s) on a connection whose
# HELLO the master has not read yet. That master then sends its JOB on it, whose reload runs
# while the first TILEs arrive: a READY for the old connection's load must not go out on
# the new one, or those TILEs are dropped and the master waits for them until it evicts us.
timeout 120 $M $SCENE -o "$T/lref.exr" --workers 1 --threads 1 --spp 4 --tile 64 --no-journal >"$T/log" 2>&1 || bad "reference render (slow load)"
rm -f "$T/late.exr"
$M $SCENE -o "$T/late.exr" --workers 0 --bind "ipc://$T/l.sock" --spp 4 --tile 64 --no-journal >"$T/log1" 2>&1 &
mpid=$!
$W --connect "ipc://$T/l.sock" --threads 1 --fault slow-load:8500 --timeout-ms 60000 --verbose >"$T/wlog" 2>&1 &
wpid=$!
echo "$mpid $wpid" >"$T/pids"
# Frozen once the worker has its blobs and loads (frozen before it has them, the load would
# start only after the freeze, on a loaded machine after the master's "joined")
wait_for "loading the scene" 200 "$T/wlog"
kill -STOP $mpid
sleep 9.5
kill -CONT $mpid
# without a TILE lost, the frame ends in seconds; a lost one waits for the stall eviction
( sleep 25; ours $mpid && kill $mpid 2>/dev/null ) &
guard=$!
wait $mpid
r=$?
kill $guard 2>/dev/null
wait $wpid
wr=$?
if [ $r = 0 ] && [ $wr = 0 ] && grep -q "loaded after a reconnection: READY waits" "$T/wlog" &&
  ! grep -q "dropping TILE" "$T/wlog" && $X cmp "$T/lref.exr" "$T/late.exr" >/dev/null; then
  ok "a load that ends after a reconnection waits for the new connection's JOB: no TILE dropped, identical pixels"
else bad "a load that ends after a reconnection: no TILE dropped (master rc $r, worker rc $wr)"; fi

finish
