#!/bin/sh
# Several hosts on one machine (make test-netns; needs root): the master and two workers
# each in a network namespace of their own, linked by veth pairs (master 10.77.1.1 and
# 10.77.2.1, workers 10.77.1.2 and 10.77.2.2), over TCP with CurveZMQ. One worker is cut
# off (its link down) for longer than --worker-timeout-ms and then healed: the master
# evicts it and re-queues its tiles, the worker reconnects, rejoins and offers the tiles it
# finished while cut off, and the image is identical to a local render. Without root or
# `ip netns` it says why and skips. Ends with "integration: N passed, N failed".
# Usage: BUILD=build sh tests/netns/run.sh
set -u
cd "$(dirname "$0")/../.." || exit 2
BUILD=${BUILD:-build}
M=$(pwd)/$BUILD/master
W=$(pwd)/$BUILD/worker
X=$BUILD/exrtool
T=$(mktemp -d /tmp/brume-netns.XXXXXX)
pass=0
fail=0
id=$$
NM=brm-m-$id N1=brm-w1-$id N2=brm-w2-$id
skip() { echo "skip: network namespace test: $1"; echo "integration: 0 passed, 0 failed (skipped)"; rm -rf "$T"; exit 0; }
[ "$(id -u)" = 0 ] || skip "not root (ip netns needs it)"
command -v ip >/dev/null 2>&1 || skip "ip (iproute2) not installed"
ip netns add $NM 2>"$T/err" || skip "cannot create a network namespace: $(cat "$T/err")"
ours() { tr '\0' ' ' 2>/dev/null <"/proc/$1/cmdline" | grep -q "$T"; }
cleanup() {
  # only processes of this test (their command lines name $T): a pid that exited may
  # have been reused by someone else's process by now
  for p in $(cat "$T/pids" 2>/dev/null); do ours "$p" && kill -9 "$p" 2>/dev/null; done
  for n in $NM $N1 $N2; do ip netns del $n 2>/dev/null; done
  rm -rf "$T"
}
trap cleanup EXIT
ok() { pass=$((pass + 1)); echo "ok: $1"; }
bad() { fail=$((fail + 1)); echo "FAIL: $1"; for f in "$T/log" "$T/w1.log" "$T/w2.log"; do [ -s "$f" ] && { echo "  $f:"; tail -12 "$f" | sed 's/^/    /'; }; done; }
# A counter of the networked master, from its stats file (net.exr.stats.json).
counter() {
  python3 -c 'import json, sys
try: print(json.load(open(sys.argv[1]))["counters"][sys.argv[2]])
except (OSError, ValueError, KeyError): pass' "$T/net.exr.stats.json" "$1"
}

ip netns add $N1 && ip netns add $N2 || { bad "namespaces"; exit 1; }
# master <-> w1 on 10.77.1.0/24, master <-> w2 on 10.77.2.0/24
for k in 1 2; do
  ip link add m$k-$id type veth peer name w$k-$id &&
    ip link set m$k-$id netns $NM && ip link set w$k-$id netns brm-w$k-$id &&
    ip -n $NM addr add 10.77.$k.1/24 dev m$k-$id && ip -n brm-w$k-$id addr add 10.77.$k.2/24 dev w$k-$id &&
    ip -n $NM link set m$k-$id up && ip -n brm-w$k-$id link set w$k-$id up && ip -n brm-w$k-$id link set lo up ||
    { bad "veth pair $k"; echo "integration: $pass passed, $fail failed"; exit 1; }
done
ip -n $NM link set lo up
if ip -n $NM -4 addr show | grep -q "10.77.1.1/24" && ip -n $NM -4 addr show | grep -q "10.77.2.1/24" &&
  ip -n $N1 -4 addr show | grep -q "10.77.1.2/24" && ip -n $N2 -4 addr show | grep -q "10.77.2.2/24" &&
  ! ip -n $N1 -4 addr show | grep -q "10.77.2."; then
  ok "three namespaces linked by veth pairs: master 10.77.1.1 + 10.77.2.1, workers 10.77.1.2 and 10.77.2.2"
else bad "three namespaces linked by veth pairs: master 10.77.1.1 + 10.77.2.1, workers 10.77.1.2 and 10.77.2.2"; fi

SCENE=scenes/cornell/cornell.json
ARGS="--spp 128 --tile 32"
timeout 300 $M $SCENE -o "$T/ref.exr" --workers 2 --threads 1 $ARGS >"$T/log" 2>&1 || bad "reference render"
$M --keygen "$T/m.key" >/dev/null && $M --keygen "$T/w.key" >/dev/null && cp "$T/w.key.pub" "$T/allow"
P=$((21000 + (id % 20000)))
ip netns exec $NM $M $SCENE -o "$T/net.exr" $ARGS --workers 0 --bind "tcp://0.0.0.0:$P" --curve-secret "$T/m.key" \
  --allow "$T/allow" --worker-timeout-ms 3000 >"$T/log" 2>&1 &
mpid=$!
ip netns exec $N1 $W --connect "tcp://10.77.1.1:$P" --threads 1 --curve-secret "$T/w.key" --server-key "$T/m.key.pub" \
  --timeout-ms 60000 >"$T/w1.log" 2>&1 &
w1=$!
ip netns exec $N2 $W --connect "tcp://10.77.2.1:$P" --threads 1 --curve-secret "$T/w.key" --server-key "$T/m.key.pub" \
  --timeout-ms 60000 >"$T/w2.log" 2>&1 &
w2=$!
echo "$mpid $w1 $w2" >"$T/pids"
i=0
while [ "$(grep -c "joined" "$T/log")" -lt 2 ] && [ $i -lt 100 ]; do sleep 0.1; i=$((i + 1)); done
sleep 1
ip -n $N1 link set w1-$id down      # worker 1 is cut off
i=0
while ! grep -q "removed (no heartbeat" "$T/log" && [ $i -lt 100 ]; do sleep 0.1; i=$((i + 1)); done
sleep 3                              # the worker notices too and keeps trying
ip -n $N1 link set w1-$id up        # healed
wait $mpid && r=0 || r=1
wait $w1; r1=$?
wait $w2; r2=$?
grep "removed" "$T/log" | sed "s/^/netns: /"
kept=$(sed -n 's/.*reconnecting (\([0-9]*\) finished tile(s) kept).*/\1/p' "$T/w1.log" | head -1)
fk=$(counter tiles_from_kept); kd=$(counter kept_duplicate)
echo "netns: worker 1 cut off and healed: evicted $(counter evicted_silent), joined $(counter workers_joined) times in all," \
  "kept ${kept:-?} tiles while cut off, master took $fk of them ($kd already done), re-issued $(counter tiles_reissued)"
if [ $r = 0 ] && [ $r1 = 0 ] && [ $r2 = 0 ] && [ "$(counter evicted_silent)" = 1 ] && [ "$(counter workers_joined)" = 3 ] &&
  [ -n "$kept" ] && [ $((fk + kd)) = "$kept" ] && $X cmp "$T/ref.exr" "$T/net.exr" >/dev/null; then
  ok "a worker cut off and healed: evicted, its tiles re-queued, it rejoins and offers its kept tiles, identical pixels"
else bad "a worker cut off and healed: evicted, its tiles re-queued, it rejoins and offers its kept tiles, identical pixels"; fi

echo "integration: $pass passed, $fail failed"
[ $fail = 0 ]
