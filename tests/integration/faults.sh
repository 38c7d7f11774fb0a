#!/bin/sh
# Fault tolerance end to end: a SIGSTOPped worker, hung render threads, a straggler, a tile
# that crashes every worker, a worker that sends garbage, a master killed with SIGKILL at
# random times and restarted (journal), a torn journal, a dead master's temporary outputs
# (removed at the next start), a full disk. Every image must be
# bit-identical to an uninterrupted render. Ends with "integration: N passed, N failed".
# Usage: BUILD=build TRIALS=10 sh tests/integration/faults.sh
. "$(dirname "$0")/lib.sh"
lib_init faults
TRIALS=${TRIALS:-10}
cleanup() {
  kill_ours
  mountpoint -q "$T/full" 2>/dev/null && umount "$T/full"
  lib_cleanup
}
ms() { date +%s%3N; }
SCENE=scenes/cornell/cornell.json
ARGS="--spp 4 --tile 32"

timeout 120 $M $SCENE -o "$T/ref.exr" --workers 1 $ARGS >"$T/log" 2>&1 || bad "reference render"

# --- SIGSTOP a worker mid-render: evicted, tiles re-issued within 5 s, late results dropped ---
# (whether any result comes late is a race: on SIGCONT the worker reads the master's BYE,
# sends only the tiles already finished and leaves, and on a loaded machine it can read
# the BYE before a render thread finishes one; the image proves none was used, and
# security.sh counts stale results exactly)
# (the workers sleep 30 ms before each of the 256 tiles: the render outlasts the 2.5 s
# timeout plus the stop even on a fast idle machine, at the CPU cost of 4 spp)
timeout 120 $M $SCENE -o "$T/stop.exr" --workers 0 --bind "ipc://$T/stop.sock" $ARGS \
  --worker-timeout-ms 2500 >"$T/log" 2>&1 &
mpid=$!
# (no `timeout` wrapper: the signals must reach the worker itself)
$W --connect "ipc://$T/stop.sock" --threads 1 --timeout-ms 20000 --fault slow:30 >/dev/null 2>&1 &
w1=$!
$W --connect "ipc://$T/stop.sock" --threads 1 --timeout-ms 20000 --fault slow:30 >/dev/null 2>&1 &
w2=$!
echo "$w1 $w2" >"$T/pids"
# Stop w1 once both workers have joined and rendered a while (on a loaded machine a fixed
# sleep can stop a worker that holds no tile yet, and then nothing comes back late).
i=0
while [ "$(grep -c " joined with " "$T/log")" -lt 2 ] && [ $i -lt 200 ]; do sleep 0.05; i=$((i + 1)); done
sleep 1
t0=$(ms)
kill -STOP $w1
lat=""
while [ $(( $(ms) - t0 )) -lt 8000 ]; do
  if grep -q "removed (no heartbeat" "$T/log"; then lat=$(( $(ms) - t0 )); break; fi
  sleep 0.05
done
sleep 0.3
kill -CONT $w1
wait $mpid && r=0 || r=1
wait $w1 $w2 2>/dev/null
echo "faults: SIGSTOP: re-queued ${lat:-never} ms after SIGSTOP; late results dropped: $(counter results_stale "$T/stop.exr")"
if [ $r = 0 ] && [ -n "$lat" ] && [ "$lat" -lt 5000 ] && [ "$(counter evicted_silent "$T/stop.exr")" -ge 1 ] &&
  [ "$(counter tiles_reissued "$T/stop.exr")" -ge 1 ] && $X cmp "$T/ref.exr" "$T/stop.exr"; then
  ok "SIGSTOP: re-issued within 5 s, late results (if any) dropped, identical pixels"
else bad "SIGSTOP: re-issued within 5 s, late results (if any) dropped, identical pixels"; fi

# --- render threads hang while the worker's main thread still answers: evicted for no progress ---
# (the other worker sleeps 20 ms before each tile: the render outlasts the 1.5 s stall
# timeout, so the hung tiles are not all taken by straggler copies first)
timeout 120 $M $SCENE -o "$T/hang.exr" --workers 0 --bind "ipc://$T/hang.sock" $ARGS --stall-ms 1500 >"$T/log" 2>&1 &
mpid=$!
timeout 120 $W --connect "ipc://$T/hang.sock" --threads 1 --fault hang-after:2 >/dev/null 2>&1 &
h1=$!
timeout 120 $W --connect "ipc://$T/hang.sock" --threads 1 --fault slow:20 >/dev/null 2>&1 &
echo "$h1 $!" >"$T/pids"
wait $mpid && r=0 || r=1
if [ $r = 0 ] && [ "$(counter evicted_stalled "$T/hang.exr")" = 1 ] && [ "$(counter evicted_silent "$T/hang.exr")" = 0 ] && grep -q "no progress" "$T/log" &&
  $X cmp "$T/ref.exr" "$T/hang.exr"; then ok "hung render threads detected by progress heartbeats"; else bad "hung render threads detected by progress heartbeats"; fi

# --- a straggler: an idle worker takes a second attempt; the first result wins ---
timeout 120 $M $SCENE -o "$T/slow.exr" --workers 1 --threads 1 --bind "ipc://$T/slow.sock" $ARGS >"$T/log" 2>&1 &
mpid=$!
timeout 120 $W --connect "ipc://$T/slow.sock" --threads 1 --fault slow:4000 >/dev/null 2>&1 &
echo "$!" >"$T/pids"
wait $mpid && r=0 || r=1
if [ $r = 0 ] && [ "$(counter straggler_copies "$T/slow.exr")" -ge 1 ] && $X cmp "$T/ref.exr" "$T/slow.exr"; then
  ok "straggler copies issued, identical pixels"; else bad "straggler copies issued, identical pixels"; fi

# --- a tile that crashes every worker fails the job, naming the tile and the command for it ---
timeout 120 $M $SCENE -o "$T/crash.exr" --workers 0 --bind "ipc://$T/crash.sock" $ARGS --worker-timeout-ms 3000 >"$T/log" 2>&1 &
mpid=$!
pids=""
for i in 1 2 3 4; do
  timeout 60 $W --connect "ipc://$T/crash.sock" --threads 1 --fault crash-tile:37 >/dev/null 2>&1 &
  pids="$pids $!"
done
echo "$pids" >"$T/pids"
wait $mpid && r=0 || r=1
cmd=$(sed -n 's/.*render it alone with: //p' "$T/log" | head -1)
if [ $r = 1 ] && grep -q "tile 37 (pixels .*) took down 3 different workers" "$T/log" && [ -n "$cmd" ] &&
  [ ! -e "$T/crash.exr" ]; then ok "a tile crashing 3 workers fails the job, naming it"; else bad "a tile crashing 3 workers fails the job, naming it"; fi
# the printed command (with local workers instead of the crashing ones) renders just that tile
cmd=$(echo "$cmd" | sed "s|--workers 0 --bind ipc://[^ ]*|--workers 1|")
if timeout 60 sh -c "$cmd" >"$T/log" 2>&1 && [ -e "$T/crash.tile37.exr" ] &&
  $X cmprect "$T/ref.exr" "$T/crash.tile37.exr" $((37 % 16 * 32)) $((37 / 16 * 32)) 32 32 >/dev/null &&
  ! $X cmp "$T/ref.exr" "$T/crash.tile37.exr" >/dev/null 2>&1 &&
  grep -q "(0 from the journal, [0-9]* outside --tiles)" "$T/log"; then
  ok "--tiles renders only the named tile (its log: none from the journal, the rest outside --tiles)"
else bad "--tiles renders only the named tile"; fi

# --- a worker sending invalid tiles is banned after 3 in a row; image unchanged ---
timeout 120 $M $SCENE -o "$T/garb.exr" --workers 1 --threads 1 --bind "ipc://$T/garb.sock" $ARGS >"$T/log" 2>&1 &
mpid=$!
timeout 60 $W --connect "ipc://$T/garb.sock" --threads 1 --fault garbage >/dev/null 2>&1 &
echo "$!" >"$T/pids"
wait $mpid && r=0 || r=1
if [ $r = 0 ] && [ "$(counter workers_banned "$T/garb.exr")" = 1 ] && [ "$(counter results_invalid "$T/garb.exr")" -ge 3 ] && grep -q "banned for the job" "$T/log" &&
  $X cmp "$T/ref.exr" "$T/garb.exr"; then ok "garbage worker banned after 3 invalid tiles"; else bad "garbage worker banned after 3 invalid tiles"; fi

# --- SIGKILL K of N local workers at random times: identical pixels, every trial ---
KILL_TRIALS=${KILL_TRIALS:-20}
KARGS="--workers 4 --threads 1 --tile 8 --spp 4096"
timeout 120 $M scenes/tiny/tiny.json -o "$T/kref.exr" $KARGS >"$T/log" 2>&1 || bad "reference render (worker kills)"
good=0
landed=0
killed_total=0
t0=$(ms)
i=0
while [ $i -lt "$KILL_TRIALS" ]; do
  i=$((i + 1))
  k=$(( (i % 3) + 1 ))   # K = 1, 2 or 3 of the 4 workers
  $M scenes/tiny/tiny.json -o "$T/wk.exr" $KARGS >"$T/klog" 2>&1 &
  mpid=$!
  echo $mpid >"$T/pids"
  sleep 0.05
  for w in $(pgrep -P $mpid | shuf -n $k); do
    sleep "0.$(( $(od -An -N2 -tu2 /dev/urandom) % 25 ))"
    kill -9 "$w" 2>/dev/null
  done
  wait $mpid && r=0 || r=1
  died=$(counter evicted_died "$T/wk.exr")
  if [ $r = 0 ] && $X cmp "$T/kref.exr" "$T/wk.exr" >/dev/null; then
    good=$((good + 1)); killed_total=$((killed_total + ${died:-0})); [ "${died:-0}" -gt 0 ] && landed=$((landed + 1))
  else cat "$T/klog" >"$T/log"; echo "trial $i (K=$k): rc $r"; fi
  rm -f "$T/wk.exr"
done
echo "faults: workers killed: $good of $KILL_TRIALS trials identical; $landed trials with kills mid-render, $killed_total workers evicted as dead; $(( $(ms) - t0 )) ms"
if [ $good = "$KILL_TRIALS" ] && [ $((landed * 2)) -ge "$KILL_TRIALS" ]; then ok "K of 4 workers SIGKILLed at random times: identical pixels in every trial"
else bad "K of 4 workers SIGKILLed at random times: identical pixels in every trial"; fi

# --- kill -9 the master at random times, restart: no journaled tile re-rendered, identical ---
good=0
from_journal_total=0
i=0
while [ $i -lt "$TRIALS" ]; do
  i=$((i + 1))
  out="$T/kill$i.exr"
  $M $SCENE -o "$out" --workers 2 --threads 1 $ARGS >"$T/klog" 2>&1 &
  mpid=$!
  sleep "0.$(( ($(od -An -N2 -tu2 /dev/urandom) % 9) + 1 ))"
  kill -9 $mpid 2>/dev/null
  wait $mpid 2>/dev/null
  [ $((i % 3)) = 0 ] && [ -s "$out.journal" ] && {
    sz=$(stat -c %s "$out.journal"); cut=$(( $(od -An -N4 -tu4 /dev/urandom) % sz ));
    truncate -s "$cut" "$out.journal"; }   # a torn journal, cut at a random byte
  timeout 120 $M $SCENE -o "$out" --workers 2 --threads 1 $ARGS >"$T/log" 2>&1 && r=0 || r=1
  fj=$(counter tiles_from_journal "$out"); as=$(counter tiles_assigned "$out"); sc=$(counter straggler_copies "$out")
  # every unit (tile, pass) not from the journal was assigned exactly once (plus straggler copies)
  nt=$(python3 -c 'import json, sys; s = json.load(open(sys.argv[1])); print(s["tiles"] * s["passes"])' "$out.stats.json" 2>/dev/null)
  if [ $r = 0 ] && [ -n "$nt" ] && [ $((fj + as - sc)) = "$nt" ] && [ ! -e "$out.journal" ] && $X cmp "$T/ref.exr" "$out" >/dev/null; then
    good=$((good + 1)); from_journal_total=$((from_journal_total + fj)); else cat "$T/klog" >>"$T/log"; fi
done
echo "faults: master killed: $good of $TRIALS trials identical; $from_journal_total tiles taken from journals"
if [ $good = "$TRIALS" ] && [ $from_journal_total -gt 0 ]; then ok "master kill -9 + restart (incl. torn journals): identical, journaled tiles not re-rendered"
else bad "master kill -9 + restart (incl. torn journals): identical, journaled tiles not re-rendered"; fi

# --- many passes (over FOLD_KEEP_ALL_PASSES: each tile's passes folded in batches as they
# come, master/fold.h): 1 vs 3 workers, without the checker pool, and a master killed
# mid-frame and restarted from its journal, all identical ---
sed 's/"width": 512/"width": 256/; s/"height": 512/"height": 256/' $SCENE >"$T/c256.json"
cp scenes/cornell/cornell.obj scenes/cornell/cornell.mtl "$T/"
PB="--spp 24 --passes 24 --tile 32"
timeout 120 $M "$T/c256.json" -o "$T/pb1.exr" --workers 1 --threads 2 --no-journal $PB >"$T/log" 2>&1 && r1=0 || r1=1
timeout 120 $M "$T/c256.json" -o "$T/pb3.exr" --workers 3 --threads 1 --no-journal $PB >"$T/log" 2>&1 && r3=0 || r3=1
timeout 120 $M "$T/c256.json" -o "$T/pb0.exr" --workers 2 --threads 1 --no-journal --check-threads 0 $PB >"$T/log" 2>&1 &&
  $X cmp "$T/pb1.exr" "$T/pb0.exr" || r3=1   # without the checker pool: the loop folds the batches
$M "$T/c256.json" -o "$T/pbk.exr" --workers 2 --threads 1 $PB >"$T/klog" 2>&1 &
mpid=$!
i=0   # killed once its journal holds a quarter of the units or so (not at a fixed time)
while [ $i -lt 400 ] && [ "$(stat -c %s "$T/pbk.exr.journal" 2>/dev/null || echo 0)" -lt 4000000 ]; do sleep 0.01; i=$((i + 1)); done
kill -9 $mpid 2>/dev/null
wait $mpid 2>/dev/null
timeout 120 $M "$T/c256.json" -o "$T/pbk.exr" --workers 2 --threads 1 $PB >"$T/log" 2>&1 && rk=0 || rk=1
fj=$(counter tiles_from_journal "$T/pbk.exr")
echo "faults: 24 passes, master killed: ${fj:-0} units from the journal"
if [ $r1 = 0 ] && [ $r3 = 0 ] && [ $rk = 0 ] && $X cmp "$T/pb1.exr" "$T/pb3.exr" && $X cmp "$T/pb1.exr" "$T/pbk.exr" &&
  [ "${fj:-0}" -gt 0 ]; then
  ok "24 passes (folded in batches): 1 vs 3 workers, no checker pool, a master kill -9 + restart: identical"
else bad "24 passes (folded in batches): 1 vs 3 workers, no checker pool, a master kill -9 + restart: identical (rc $r1 $r3 $rk, journal ${fj:-0})"; fi

# --- a second master on the same output is refused while the first holds its journal ---
# (the first waits for a worker, so it is surely running; the second asks for other
# settings, which once started the journal afresh under the first one's records)
timeout 120 $M $SCENE -o "$T/two.exr" --workers 0 --bind "ipc://$T/two.sock" $ARGS >"$T/klog" 2>&1 &
mpid=$!
echo $mpid >"$T/pids"
i=0
while [ $i -lt 400 ] && [ ! -s "$T/two.exr.journal" ]; do sleep 0.05; i=$((i + 1)); done
timeout 60 $M $SCENE -o "$T/two.exr" --workers 1 --spp 2 --tile 32 >"$T/log" 2>&1 && r2=0 || r2=1
# (the first writes its stats only at its end: any there now is the refused one's)
[ -e "$T/two.exr.stats.json" ] && stats2=written || stats2=none
timeout 60 $W --connect "ipc://$T/two.sock" --threads 2 >/dev/null 2>&1 &
echo "$mpid $!" >"$T/pids"
wait $mpid && r1=0 || r1=1
if [ $r2 = 1 ] && tail -1 "$T/log" | grep -q "^master: error: $T/two\.exr\.journal: the journal is in use by another master" &&
  [ $stats2 = none ] && [ $r1 = 0 ] && $X cmp "$T/ref.exr" "$T/two.exr" >/dev/null; then
  ok "a second master on the same output is refused (journal in use) and writes no stats; the first one finishes identical"
else cat "$T/klog" >>"$T/log"; bad "a second master on the same output is refused (journal in use) and writes no stats; the first one finishes identical (rc $r2 $r1, stats $stats2)"; fi

# --- temporary outputs of a master killed while it wrote (OUT.exr.tmp.PID): removed at the
# next start when that PID is no live process; a live one's stays ---
sh -c 'exit 0' &
dead=$!
wait $dead
for f in stale.exr.tmp.$dead stale.exr.stats.json.tmp.$dead stale.exr.tmp.$$; do echo partial >"$T/$f"; done
timeout 120 $M $SCENE -o "$T/stale.exr" --workers 1 $ARGS >"$T/log" 2>&1 && r=0 || r=1
if [ $r = 0 ] && [ ! -e "$T/stale.exr.tmp.$dead" ] && [ ! -e "$T/stale.exr.stats.json.tmp.$dead" ] &&
  [ -e "$T/stale.exr.tmp.$$" ] && grep -q "removed 2 temporary file(s)" "$T/log" && $X cmp "$T/ref.exr" "$T/stale.exr" >/dev/null; then
  ok "a dead master's temporary outputs removed at start (one log line), a live one's kept"
else bad "a dead master's temporary outputs removed at start (one log line), a live one's kept (rc $r)"; fi
rm -f "$T/stale.exr.tmp.$$"

# --- a full disk is a clear error, never a truncated frame ---
mkdir -p "$T/full"
if mount -t tmpfs -o size=96k tmpfs "$T/full" 2>/dev/null; then
  timeout 120 $M $SCENE -o "$T/full/f.exr" --workers 1 $ARGS >"$T/log" 2>&1 && r=0 || r=1
  if [ $r = 1 ] && grep -q "No space left on device" "$T/log" && [ ! -e "$T/full/f.exr" ] && ! ls "$T/full" | grep -q "\.tmp\."; then
    ok "full disk: clear error, no output file"; else bad "full disk: clear error, no output file"; fi
  umount "$T/full"
else
  echo "skip: full disk test (cannot mount a tmpfs here)"
fi

finish
