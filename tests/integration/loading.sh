#!/bin/sh
# A worker keeps heartbeating while it loads a job (blob fetches, scene parsing, BVH
# build run beside its main loop), so a load longer than the master's --worker-timeout-ms
# does not get it evicted. The load is made slow on purpose (worker --fault slow-load:MS,
# tests only). Also: the next frame's JOB waits for a load of the same scene, another
# job's JOB (a restarted master's) cancels the load in progress, and a BYE
# during a load ends the worker at once; pixels are identical to a plain render.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/loading.sh
. "$(dirname "$0")/lib.sh"
lib_init loading
BAD_LOGS="log wlog"
SCENE=scenes/tiny/tiny.json
ARGS="--tile 8"
# frames long enough that the slow worker joins before the last one ends
FSCENE=scenes/cornell/cornell.json
FARGS="--spp 1 --tile 64"

# both SCENE "MASTER ARGS" "WORKER ARGS": a master and one worker (words split; $T has no
# spaces); r and wr are their exit codes, the logs $T/log and $T/wlog
both() {
  timeout 120 $M $1 $2 >"$T/log" 2>&1 &
  mpid=$!
  timeout 120 $W $3 >"$T/wlog" 2>&1 &
  wpid=$!
  echo "$mpid $wpid" >"$T/pids"
  wait $mpid && r=0 || r=1
  wait $wpid && wr=0 || wr=1
}

run $M $SCENE -o "$T/ref.exr" --workers 1 --threads 1 $ARGS || bad "reference render"
run $M $FSCENE -o "$T/reff.exr" --frames 1:3 --workers 1 --threads 1 $FARGS || bad "reference render of frames 1:3"

# --- a job of 1200 blobs: more requests than a socket queues (ZMQ_SNDHWM 1000) if every
# blob's fetch opened its window at once; the worker then saw a full queue as a lost
# master and reconnected for ever. The files are fetched, the image is the one-command
# render's ---
mkdir "$T/many"
cp scenes/tiny/tiny.obj scenes/tiny/tiny.mtl scenes/tiny/lamp.obj "$T/many/"
objs=""
i=0
while [ $i -lt 1200 ]; do
  { echo "# copy $i"; cat scenes/tiny/lamp.obj; } >"$T/many/m$i.obj"
  objs="$objs, {\"type\": \"obj\", \"file\": \"m$i.obj\", \"transform\": {\"translate\": [$((100 + 3 * i)), 0, 0]}}"
  i=$((i + 1))
done
sed "s|{\"type\": \"sphere\"|${objs#, }, {\"type\": \"sphere\"|" $SCENE >"$T/many/tiny.json"
run $M "$T/many/tiny.json" -o "$T/manyref.exr" --workers 1 --threads 1 $ARGS && rr=0 || rr=1
both "$T/many/tiny.json" "-o $T/many.exr --workers 0 --bind ipc://$T/m.sock $ARGS" "--connect ipc://$T/m.sock --threads 1"
if [ $rr = 0 ] && [ $r = 0 ] && [ $wr = 0 ] && ! grep -q "reconnecting" "$T/wlog" &&
  [ "$(counter workers_joined "$T/many.exr")" = 1 ] && $X cmp "$T/manyref.exr" "$T/many.exr" >/dev/null; then
  ok "a job of 1200 blobs is fetched without reconnecting; identical pixels"
else
  bad "a job of 1200 blobs is fetched without reconnecting; identical pixels (one command rc $rr)"
fi

# --- a load of 5 s against a 3 s silence timeout: not evicted, identical pixels ---
both $SCENE "-o $T/slow.exr --workers 0 --bind ipc://$T/s.sock $ARGS --worker-timeout-ms 3000" \
  "--connect ipc://$T/s.sock --threads 1 --fault slow-load:5000"
if [ $r = 0 ] && [ $wr = 0 ] && [ "$(counter evicted_silent "$T/slow.exr")" = 0 ] &&
  [ "$(counter workers_joined "$T/slow.exr")" = 1 ] && $X cmp "$T/ref.exr" "$T/slow.exr" >/dev/null; then
  ok "a worker loading for 5 s is not evicted at --worker-timeout-ms 3000; identical pixels"
else
  bad "a worker loading for 5 s is not evicted at --worker-timeout-ms 3000; identical pixels"
fi

# --- frames 1:3 of one scene: a local worker renders every frame while the slow one still
# loads; the next frames' JOBs wait for that load (same scene: its parse is kept), the BYE
# at the end cancels it ---
both $FSCENE "-o $T/fr.exr --frames 1:3 --workers 1 --threads 1 --bind ipc://$T/f.sock $FARGS --worker-timeout-ms 3000" \
  "--connect ipc://$T/f.sock --threads 1 --fault slow-load:100000"
cancelled=$(grep -c "load of job .* cancelled" "$T/wlog")
kept=$(grep -c "the same scene, kept for it" "$T/wlog")
same=1
for f in 1 2 3; do $X cmp "$T/reff.000$f.exr" "$T/fr.000$f.exr" >/dev/null || same=0; done
echo "loading: frames: JOBs kept waiting for the load $kept, loads cancelled $cancelled"
if [ $r = 0 ] && [ $wr = 0 ] && [ $same = 1 ] && [ "$kept" -ge 1 ] && [ "$cancelled" = 1 ] &&
  [ "$(counter evicted_silent "$T/fr.exr")" = 0 ]; then
  ok "the next frame's JOB waits for a load of the same scene, a BYE cancels it; not evicted, identical frames"
else
  bad "the next frame's JOB waits for a load of the same scene, a BYE cancels it; not evicted, identical frames"
fi

# --- a master restarted on another job (seed 2) while the worker loads the first: the new
# JOB cancels that load; a helper worker (slow tiles, little CPU) renders the new job ---
run $M $SCENE -o "$T/ref2.exr" --workers 1 --threads 1 $ARGS --seed 2 || bad "reference render (seed 2)"
$M $SCENE -o "$T/c1.exr" --workers 0 --bind "ipc://$T/c.sock" $ARGS --no-journal >"$T/log1" 2>&1 &
mpid=$!
timeout 120 $W --connect "ipc://$T/c.sock" --threads 1 --timeout-ms 60000 --fault slow-load:100000 --verbose \
  >"$T/wlog" 2>&1 &
wpid=$!
echo "$mpid $wpid" >"$T/pids"
# (the master dies once the worker's load is under way, not once it joined: on a loaded
# machine the JOB could still be on its way then, and the new master's JOB would start
# the first load instead of cancelling one)
n=0; while ! grep -q "loading the scene" "$T/wlog" 2>/dev/null && [ $n -lt 300 ]; do sleep 0.1; n=$((n + 1)); done
kill -9 $mpid; wait $mpid 2>/dev/null
timeout 120 $M $SCENE -o "$T/c2.exr" --workers 0 --bind "ipc://$T/c.sock" $ARGS --seed 2 \
  --worker-timeout-ms 3000 >"$T/log" 2>&1 &
mpid=$!
timeout 120 $W --connect "ipc://$T/c.sock" --threads 1 --fault slow:1000 >/dev/null 2>&1 &
echo "$mpid $wpid $!" >"$T/pids"
wait $mpid && r=0 || r=1
wait $wpid && wr=0 || wr=1
if [ $r = 0 ] && [ $wr = 0 ] && grep -q "that load is cancelled" "$T/wlog" &&
  [ "$(grep -c "load of job .* cancelled" "$T/wlog")" = 2 ] && [ "$(counter workers_joined "$T/c2.exr")" = 2 ] &&
  [ "$(counter evicted_silent "$T/c2.exr")" = 0 ] && $X cmp "$T/ref2.exr" "$T/c2.exr" >/dev/null; then
  ok "a JOB naming another job cancels the load under way; identical pixels"
else
  bad "a JOB naming another job cancels the load under way; identical pixels"
fi
finish
