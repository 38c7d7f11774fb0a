#!/bin/sh
# Keeping strangers out: CurveZMQ with an allow-list. A client without CurveZMQ and a
# worker with an unlisted key get no message to the master's code and no tile; a listed
# worker renders the same pixels. Binding a public address without keys is refused.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/security.sh
. "$(dirname "$0")/lib.sh"
lib_init sec
P=$((21000 + ($$ % 20000)))

if $M --keygen "$T/master.key" >/dev/null && $M --keygen "$T/good.key" >/dev/null && $M --keygen "$T/stranger.key" >/dev/null &&
  [ "$(stat -c %a "$T/good.key")" = 600 ] && [ "$(wc -c <"$T/good.key.pub")" = 41 ]; then
  ok "--keygen writes a private key pair and a public key"; else bad "--keygen writes a private key pair and a public key"; fi
cp "$T/good.key.pub" "$T/allow"

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

timeout 60 $M scenes/tiny/tiny.json -o "$T/l.exr" --workers 2 --bind "tcp://127.0.0.1:$((P + 1))" \
  --curve-secret "$T/master.key" --allow "$T/allow" >"$T/log" 2>&1 && r=0 || r=1
if [ $r = 0 ] && [ "$(counter auth_rejects "$T/l.exr")" = 0 ] && $X cmp "$T/ref.exr" "$T/l.exr"; then
  ok "CurveZMQ: local workers get their own key"; else bad "CurveZMQ: local workers get their own key"; fi

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

finish
