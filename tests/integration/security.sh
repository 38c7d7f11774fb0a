#!/bin/sh
# Keeping strangers out: CurveZMQ with an allow-list. A client without CurveZMQ and a
# worker with an unlisted key get no message to the master's code and no tile; a listed
# worker renders the same pixels. Binding a public address without keys is refused.
# A loopback bind without keys is CurveZMQ too (throw-away keys for the local workers):
# a stranger gets no JOB and no blob and cannot poison the image. A rogue whose key is on
# the allow-list cannot poison tiles it does not hold (KEPT, RESULT), cannot evict a
# worker by claiming its host and pid, and a flood of its HELLOs does not keep the real
# worker out. A tile that is non-finite on two workers fails the job, naming the cause.
# Peers that ask for blob chunks and read nothing do not grow the master's memory.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/security.sh
. "$(dirname "$0")/lib.sh"
lib_init sec
P=$(free_port) P1=$(free_port) P2=$(free_port) P3=$(free_port) P4=$(free_port) P5=$(free_port) P6=$(free_port)

if $M --keygen "$T/master.key" >/dev/null && $M --keygen "$T/good.key" >/dev/null && $M --keygen "$T/stranger.key" >/dev/null &&
  [ "$(stat -c %a "$T/good.key")" = 600 ] && [ "$(wc -c <"$T/good.key.pub")" = 41 ]; then
  ok "--keygen writes a private key pair and a public key"; else bad "--keygen writes a private key pair and a public key"; fi
cp "$T/good.key.pub" "$T/allow"
$M --keygen "$T/rogue.key" >/dev/null
cat "$T/good.key.pub" "$T/rogue.key.pub" >"$T/allow2"

if ! timeout 10 $M scenes/tiny/tiny.json -o "$T/x.exr" --workers 0 --bind "tcp://0.0.0.0:$P" >"$T/log" 2>&1 &&
  grep -q "insecure" "$T/log"; then ok "public bind without keys refused"; else bad "public bind without keys refused"; fi

timeout 60 $M scenes/tiny/tiny.json -o "$T/ref.exr" --workers 1 >"$T/log" 2>&1 || bad "reference render"
timeout 60 $M scenes/tiny/tiny.json -o "$T/s.exr" --workers 0 --bind "tcp://127.0.0.1:$P" \
  --curve-secret "$T/master.key" --allow "$T/allow" >"$T/log" 2>&1 &
mpid=$!
sleep 0.3
timeout 20 $W --connect "tcp://127.0.0.1:$P" --curve-secret "$T/stranger.key" --server-key "$T/master.key.pub" \
  --timeout-ms 2500 >/dev/null 2>&1 &
timeout 20 $BUILD/junkpeer "tcp://127.0.0.1:$P" >/dev/null 2>&1 &
sleep 1.5
timeout 60 $W --connect "tcp://127.0.0.1:$P" --curve-secret "$T/good.key" --server-key "$T/master.key.pub" >/dev/null 2>&1
wait $mpid && r=0 || r=1
rej=0
for c in rejected_decode rejected_envelope rejected_unknown_peer rejected_unexpected results_not_ours results_stale; do
  rej=$((rej + $(counter $c "$T/s.exr")))
done
echo "security: auth rejects $(counter auth_rejects "$T/s.exr"), handshake failures $(counter handshake_failures "$T/s.exr"), workers joined $(counter workers_joined "$T/s.exr")"
if [ $r = 0 ] && [ "$(counter workers_joined "$T/s.exr")" = 1 ] && [ $rej = 0 ] && [ "$(counter auth_rejects "$T/s.exr")" -ge 1 ] &&
  [ "$(counter handshake_failures "$T/s.exr")" -ge 1 ] && ! grep -q "junk" "$T/log" && $X cmp "$T/ref.exr" "$T/s.exr"; then
  ok "CurveZMQ: strangers get 0 messages in, listed worker renders identical pixels"
else bad "CurveZMQ: strangers get 0 messages in, listed worker renders identical pixels"; fi

timeout 60 $M scenes/tiny/tiny.json -o "$T/l.exr" --workers 2 --bind "tcp://127.0.0.1:$P1" \
  --curve-secret "$T/master.key" --allow "$T/allow" >"$T/log" 2>&1 && r=0 || r=1
if [ $r = 0 ] && [ "$(counter auth_rejects "$T/l.exr")" = 0 ] && $X cmp "$T/ref.exr" "$T/l.exr"; then
  ok "CurveZMQ: local workers get their own key"; else bad "CurveZMQ: local workers get their own key"; fi

# --- a loopback bind without keys: CurveZMQ all the same; a stranger gets nothing in ---
SLOW="--spp 8192 --threads 1"
timeout 60 $M scenes/tiny/tiny.json -o "$T/sref.exr" --workers 1 $SLOW >"$T/log" 2>&1 || bad "reference render (slow)"
timeout 60 $M scenes/tiny/tiny.json -o "$T/d.exr" --workers 1 $SLOW --bind "tcp://127.0.0.1:$P2" >"$T/log" 2>&1 &
mpid=$!
sleep 0.3
timeout 20 $BUILD/junkpeer "tcp://127.0.0.1:$P2" rogue >"$T/jp" 2>&1
wait $mpid && r=0 || r=1
echo "security: stranger on a default loopback bind: $(cat "$T/jp"), handshake failures $(counter handshake_failures "$T/d.exr")"
if [ $r = 0 ] && grep -q "junkpeer: job no, blob bytes 0" "$T/jp" && grep -q "CurveZMQ on at" "$T/log" &&
  [ "$(counter handshake_failures "$T/d.exr")" -ge 1 ] &&
  [ "$(counter tiles_from_kept "$T/d.exr")" = 0 ] && $X cmp "$T/sref.exr" "$T/d.exr" >/dev/null; then
  ok "loopback bind without keys: CurveZMQ on, a stranger gets no JOB, no blob, no tile in"
else cat "$T/jp" >>"$T/log"; bad "loopback bind without keys: CurveZMQ on, a stranger gets no JOB, no blob, no tile in"; fi
# ... and with --workers 0 nobody could join: refused; --insecure is the way out, with a warning
if ! timeout 10 $M scenes/tiny/tiny.json -o "$T/x.exr" --workers 0 --bind "tcp://127.0.0.1:$P3" >"$T/log" 2>&1 &&
  grep -q -- "--curve-secret" "$T/log" && timeout 30 $M scenes/tiny/tiny.json -o "$T/i.exr" --bind "tcp://127.0.0.1:$P3" \
  --insecure >"$T/log" 2>&1 && grep -q "warning: --insecure" "$T/log" && $X cmp "$T/ref.exr" "$T/i.exr" >/dev/null; then
  ok "loopback bind, --workers 0, no keys: refused; --insecure renders with a warning"
else bad "loopback bind, --workers 0, no keys: refused; --insecure renders with a warning"; fi

# --- a rogue with a key on the allow-list, holding no tile: KEPT and RESULT for every tile
# (pixels 7.0) are dropped; the image is the clean render's ---
KEYS="--curve-secret $T/master.key --allow $T/allow2"
WKEY="--curve-secret $T/good.key --server-key $T/master.key.pub"
timeout 60 $M scenes/tiny/tiny.json -o "$T/k.exr" --workers 0 --bind "tcp://127.0.0.1:$P4" $KEYS >"$T/log" 2>&1 &
mpid=$!
sleep 0.3
timeout 20 $BUILD/junkpeer --key "$T/rogue.key" "$T/master.key.pub" "tcp://127.0.0.1:$P4" rogue >"$T/jp" 2>&1
timeout 60 $W --connect "tcp://127.0.0.1:$P4" $WKEY >/dev/null 2>&1
wait $mpid && r=0 || r=1
echo "security: authenticated rogue: $(cat "$T/jp"); kept untied $(counter kept_untied "$T/k.exr"), results stale $(counter results_stale "$T/k.exr")"
# (junkpeer sends one KEPT and three RESULTs per unit: a (tile, pass) pair)
nu=$(python3 -c 'import json, sys; s = json.load(open(sys.argv[1])); print(s["tiles"] * s["passes"])' "$T/k.exr.stats.json" 2>/dev/null)
if [ $r = 0 ] && grep -q "junkpeer: job yes" "$T/jp" && [ "$(counter tiles_from_kept "$T/k.exr")" = 0 ] && [ -n "$nu" ] &&
  [ "$(counter kept_untied "$T/k.exr")" = "$nu" ] && [ "$(counter results_stale "$T/k.exr")" = $((3 * nu)) ] && $X cmp "$T/ref.exr" "$T/k.exr" >/dev/null; then
  ok "an allowed rogue's KEPT and RESULT for tiles it does not hold are dropped; image identical"
else cat "$T/jp" >>"$T/log"; bad "an allowed rogue's KEPT and RESULT for tiles it does not hold are dropped; image identical"; fi

# --- impersonation: a HELLO with the real worker's host and pid does not evict it ---
# (the log emptied here, not only by the master's redirection: the wait below must not find
# the last case's "joined" before the master's shell has truncated the file)
: >"$T/log"
timeout 60 $M scenes/tiny/tiny.json -o "$T/m.exr" --workers 0 --bind "tcp://127.0.0.1:$P5" $KEYS $SLOW >"$T/log" 2>&1 &
mpid=$!
$W --connect "tcp://127.0.0.1:$P5" $WKEY --threads 1 --timeout-ms 20000 >/dev/null 2>&1 &
wpid=$!
echo "$wpid" >>"$T/pids"
i=0
while ! grep -q "joined" "$T/log" && [ $i -lt 600 ]; do sleep 0.1; i=$((i + 1)); done
who=$(sed -n 's/.*worker \(.*\) joined.*/\1/p' "$T/log" | head -1)
timeout 20 $BUILD/junkpeer --key "$T/rogue.key" "$T/master.key.pub" "tcp://127.0.0.1:$P5" hello-as "${who%:*}" "${who##*:}" >/dev/null 2>&1
wait $mpid && r=0 || r=1
wait $wpid && wr=0 || wr=1
if [ $r = 0 ] && [ $wr = 0 ] && [ -n "$who" ] && [ "${who##*:}" = "$wpid" ] && ! grep -q "reconnected" "$T/log" &&
  [ "$(counter workers_joined "$T/m.exr")" = 2 ] && $X cmp "$T/sref.exr" "$T/m.exr" >/dev/null; then
  ok "a HELLO claiming the real worker's host:pid ($who) does not evict it; image identical"
else bad "a HELLO claiming the real worker's host:pid (${who:-?}) does not evict it; image identical (master rc $r, worker rc $wr)"; fi

# --- an allowed peer's ERROR text with a newline, a forged log line, terminal escapes and
# bytes that are not UTF-8: logged on one line, printable, naming the peer ---
P7=$(free_port)
timeout 60 $M scenes/tiny/tiny.json -o "$T/e.exr" --workers 0 --bind "tcp://127.0.0.1:$P7" $KEYS >"$T/log" 2>&1 &
mpid=$!
sleep 0.3
timeout 20 $BUILD/junkpeer --key "$T/rogue.key" "$T/master.key.pub" "tcp://127.0.0.1:$P7" error >/dev/null 2>&1
timeout 60 $W --connect "tcp://127.0.0.1:$P7" $WKEY >/dev/null 2>&1
wait $mpid && r=0 || r=1
if [ $r = 0 ] && grep -q "error: worker liar:4243: bad?brume: info: forged line?\[2J??? end$" "$T/log" &&
  ! grep -q "^brume: info: forged" "$T/log" && ! LC_ALL=C grep -q "$(printf '[\033\177\200-\377]')" "$T/log" &&
  $X cmp "$T/ref.exr" "$T/e.exr" >/dev/null; then
  ok "a worker's ERROR text is logged printable, on one line, with the peer's name"
else bad "a worker's ERROR text is logged printable, on one line, with the peer's name (master rc $r)"; fi

# --- a flood: 4,200 HELLOs from an allowed key and 500 connects without one; the real
# worker still joins and the render finishes ---
timeout 120 $M scenes/tiny/tiny.json -o "$T/f.exr" --workers 0 --bind "tcp://127.0.0.1:$P6" $KEYS >"$T/log" 2>&1 &
mpid=$!
sleep 0.3
t0=$(date +%s)
timeout 100 $BUILD/junkpeer "tcp://127.0.0.1:$P6" flood 500 >/dev/null 2>&1 &
timeout 100 $BUILD/junkpeer --key "$T/rogue.key" "$T/master.key.pub" "tcp://127.0.0.1:$P6" flood 4200 >"$T/jp" 2>&1
timeout 60 $W --connect "tcp://127.0.0.1:$P6" $WKEY >/dev/null 2>&1 && wr=0 || wr=1
wait $mpid && r=0 || r=1
echo "security: flood: $(cat "$T/jp") in $(($(date +%s) - t0)) s; joined $(counter workers_joined "$T/f.exr"), refused $(counter hellos_refused "$T/f.exr")"
if [ $r = 0 ] && [ $wr = 0 ] && [ "$(counter hellos_refused "$T/f.exr")" -ge 1 ] &&
  grep -q "worker $(hostname):[0-9]* joined" "$T/log" && $X cmp "$T/ref.exr" "$T/f.exr" >/dev/null; then
  ok "a HELLO flood from an allowed key and unauthenticated connects do not keep the real worker out"
else bad "a HELLO flood from an allowed key and unauthenticated connects do not keep the real worker out (master rc $r, worker rc $wr)"; fi

# --- a tile non-finite on two workers (as a scene past float's range makes it): the job
# fails naming the tile and the cause; no worker is banned ---
# (tiles of 4096 samples: the second worker is ready before the first returns tile 2)
timeout 60 $M scenes/tiny/tiny.json -o "$T/n.exr" --workers 0 --bind "ipc://$T/n.sock" --spp 4096 >"$T/log" 2>&1 &
mpid=$!
for k in 1 2; do
  $W --connect "ipc://$T/n.sock" --threads 1 --fault nonfinite-tile:2 --timeout-ms 20000 >/dev/null 2>&1 &
  echo "$!" >>"$T/pids"
done
wait $mpid && r=0 || r=$?
# Rendered again on the other worker, or, when that one is still busy after the scheduler's
# wait (a loaded machine), again on the same one: either way the job fails with the cause.
if [ $r = 1 ] && tail -1 "$T/log" | grep -Eq "non-finite values at tile 2 pass 0 .*(two workers|twice on worker).*check the emission and intensity values; the brightest emitter is material .lamp. with emission 8" &&
  [ "$(counter workers_banned "$T/n.exr")" = 0 ]; then
  ok "a tile non-finite on two workers fails the job with the scene's cause, no ban"
else bad "a tile non-finite on two workers fails the job with the scene's cause, no ban (rc $r)"; fi

# A corpus of malformed and out-of-order messages from one peer, then a real worker: the
# master survives, rejects each message under the reason the corpus predicts (the
# counters add up to every message sent) and renders the same pixels.
timeout 60 $M scenes/tiny/tiny.json -o "$T/c.exr" --workers 0 --bind "ipc://$T/c.sock" >"$T/log" 2>&1 &
mpid=$!
timeout 30 $BUILD/replay "ipc://$T/c.sock" $$ >"$T/replay" 2>&1 && rr=0 || rr=1
# The replay's frames may still sit in the master's queue when it exits: start the real
# worker only once the master has read the corpus's closing BYE (else the tiny job could
# end with part of the corpus unread).
i=0
while ! grep -q "replay0:[0-9]* removed (it left)" "$T/log" && [ $i -lt 300 ]; do sleep 0.1; i=$((i + 1)); done
timeout 60 $W --connect "ipc://$T/c.sock" --threads 2 >/dev/null 2>&1
wait $mpid && r=0 || r=1
sent=$(sed -n 's/^replay: sent \([0-9]*\) messages.*/\1/p' "$T/replay")
agree=0
sum=0
for c in $(sed -n 's/^replay: expect \([a-z_]*\) .*/\1/p' "$T/replay"); do
  want=$(sed -n "s/^replay: expect $c //p" "$T/replay")
  got=$(counter $c "$T/c.exr")
  sum=$((sum + ${got:-0}))
  if [ "$want" = "$got" ]; then agree=$((agree + 1)); else echo "security: $c: expected $want, master counted ${got:-nothing}"; fi
done
echo "security: corpus of ${sent:-?} malformed or out-of-order messages; master rejected $sum; $(sed -n 's/^replay: expect //p' "$T/replay" | tr '\n' ',')"
if [ $rr = 0 ] && [ $r = 0 ] && [ -n "$sent" ] && [ "$sent" -ge 1000 ] && [ $agree = 8 ] && [ $sum = "$sent" ] &&
  [ "$(counter workers_joined "$T/c.exr")" = 2 ] && $X cmp "$T/ref.exr" "$T/c.exr"; then
  ok "malformed corpus: every message rejected with its reason, render identical"
else cat "$T/replay" >>"$T/log"; bad "malformed corpus: every message rejected with its reason, render identical"; fi

# --- three connections that each ask for 1000 chunks of a 3.6 MB blob and read nothing:
# the answers libzmq holds for a peer are capped (17 chunks), the master's memory stays
# bounded (without a cap every answer, 256 KiB, queued: +750 MB) ---
mkdir -p "$T/hd"
python3 scripts/gen_mesh.py 250 "$T/hd/big" >/dev/null
cp scenes/tiny/tiny.json scenes/tiny/tiny.obj scenes/tiny/tiny.mtl scenes/tiny/lamp.obj "$T/hd/"
python3 -c 'import json, sys
d = json.load(open(sys.argv[1])); d["objects"].append({"type": "ply", "file": "big.ply", "transform": {"translate": [-3, 0, 2]}})
json.dump(d, open(sys.argv[1], "w"), indent=1)' "$T/hd/tiny.json"
$M "$T/hd/tiny.json" -o "$T/hd.exr" --workers 0 --no-journal --bcast-mbps 0 --bind "ipc://$T/hd.sock" >"$T/log" 2>&1 &
mpid=$! # the master itself (its /proc), ended below
echo $mpid >>"$T/pids"
hwm() { awk '/^VmHWM:/ {print $2}' "/proc/$mpid/status"; }
timeout 30 $BUILD/junkpeer "ipc://$T/hd.sock" hoard 1 1 0 >/dev/null 2>&1 # the master has loaded the scene
h0=$(hwm)
timeout 30 $BUILD/junkpeer "ipc://$T/hd.sock" hoard 3 1000 3 >"$T/jp" 2>&1
h1=$(hwm)
kill $mpid 2>/dev/null
wait $mpid 2>/dev/null
echo "security: hoard: master peak RSS ${h0:-?} kB before, ${h1:-?} kB after"
if grep -q "junkpeer: hoard 3 connections" "$T/jp" && [ -n "$h0" ] && [ -n "$h1" ] && [ $((h1 - h0)) -lt 102400 ]; then
  ok "peers asking for blob chunks without reading them grow the master's peak RSS by under 100 MB ($((h1 - h0)) kB)"
else bad "peers asking for blob chunks without reading them grow the master's peak RSS by under 100 MB (${h0:-?} -> ${h1:-?} kB)"; fi

finish
