#!/bin/sh
# The master under load: build/loadpeers plays 16 fake workers (the real protocol: HELLO,
# blob fetches checked by hash, READY, a valid EXR chunk per TILE at once) against a real
# master, over ipc and over tcp with CurveZMQ. Every unit is done and acknowledged
# exactly once, nothing is rejected, and the output decodes to the very pixels the fake
# workers were given (a real render's), for the checker pool and for checks in the loop.
# Over tcp, two strangers subscribed to everything on the broadcast socket (one without
# CurveZMQ, one with a key the allow-list lacks) receive nothing.
# Blob delivery: 16 fake workers take a 3.6 MB PLY from the master's broadcast (the
# master sends about one copy, against 16 point to point), and a fake worker that loses
# or gets corrupted broadcast chunks refuses them by their hash and fetches them point to
# point. A new frame's JOB that a worker's full queue refuses is sent again until it goes.
# Usage: BUILD=build sh tests/integration/loadpeers.sh
. "$(dirname "$0")/lib.sh"
lib_init load
L=$BUILD/loadpeers
port() { free_port; }

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
  cp "$T/log" "$T/$name.llog"
  units=256
  if [ $lr = 0 ] && [ $mr = 0 ] && grep -q "acked $units acked_twice [0-9]* unacked 0 peers 16" "$T/log" &&
    [ "$(counter tiles_done "$T/$name.exr")" = $units ] && [ "$(counter workers_joined "$T/$name.exr")" = 16 ]; then
    ok "$name: 16 fake workers, every one of $units tiles done and acknowledged"; else bad "$name: 16 fake workers, every one of $units tiles done and acknowledged"; fi
  rej=0
  for c in results_invalid results_stale results_not_ours results_nonfinite rejected_decode rejected_envelope \
    rejected_unknown_peer rejected_unexpected rejected_wrong_job rejected_blob_req tiles_reissued evicted_silent \
    evicted_stalled $AUTHC; do
    v=$(counter $c "$T/$name.exr")
    [ "$v" = 0 ] || { echo "  $c = $v"; rej=1; }
  done
  dup=$(counter results_duplicate "$T/$name.exr") cp=$(counter straggler_copies "$T/$name.exr")
  if [ $rej = 0 ] && [ -n "$dup" ] && [ "$dup" -le "$cp" ]; then
    ok "$name: nothing rejected, duplicates ($dup) only from straggler copies ($cp)"; else bad "$name: nothing rejected, duplicates ($dup) only from straggler copies ($cp)"; fi
  bc=$(counter blob_bytes_bcast "$T/$name.exr")
  if [ -n "$bc" ] && [ "$bc" -gt 0 ] && [ "$(counter blob_bytes_p2p "$T/$name.exr")" = 0 ]; then
    ok "$name: the fake workers took the scene's blobs from the broadcast ($bc bytes sent)"; else bad "$name: the fake workers took the scene's blobs from the broadcast"; fi
  if $X cmp "$T/ref.exr" "$T/$name.exr" >"$T/log" 2>&1; then
    ok "$name: the output holds every tile, bit-identical to the pixels sent"; else bad "$name: the output holds every tile, bit-identical to the pixels sent"; fi
}

KEYARGS= AUTHC=auth_rejects
load ipc "ipc://$T/m.sock" --bcast-mbps 1000
load inloop "ipc://$T/m2.sock" --check-threads 0 --no-journal --bcast-mbps 1000

# A checker pool slower than the workers (one thread decoding every unit and folding every
# tile's passes, 64 fake workers answering at once: the smoke at 256x256 in 64 passes,
# 4096 units): past MASTER_POOL_BACKLOG (256) RESULTs a thread, a worker's credit waits for
# its RESULT's check, so the pool never holds more than 256 + the workers' 64 x 2 credits
# (a credit given back on arrival let it pile up 2400 of them here, 42 000 at 1024x1024).
mkdir -p "$T/sm"
cp scenes/smoke/* "$T/sm/"
sed -i 's/"width": 128, "height": 128/"width": 256, "height": 256/' "$T/sm/smoke.json"
timeout 120 $M "$T/sm/smoke.json" -o "$T/slow.exr" --spp 64 --photons 20000 --tile 32 --workers 0 \
  --bind "ipc://$T/slow.sock" --check-threads 1 --no-journal >"$T/m.log" 2>&1 &
mp=$!
echo $mp >>"$T/pids"
timeout 120 $L "ipc://$T/slow.sock" -n 64 --no-fetch >"$T/log" 2>&1 && lr=0 || lr=1
wait $mp && mr=0 || mr=1
rip=$(counter results_in_pool_max "$T/slow.exr")
echo "loadpeers: a slow checker pool: at most $rip RESULTs in it"
if [ $lr = 0 ] && [ $mr = 0 ] && [ "$(counter tiles_done "$T/slow.exr")" = 4096 ] && [ -n "$rip" ] && [ "$rip" -le 384 ]; then
  ok "a slow checker pool holds at most 256 + the workers' credits of RESULTs ($rip of 384), every unit done"
else tail -3 "$T/m.log" "$T/log"; bad "a slow checker pool holds at most 256 + the workers' credits of RESULTs (${rip:-none} of 384; rc $lr $mr)"; fi

# A frame range: one job per frame; loadpeers counts every frame's units.
timeout 120 $M scenes/cornell/cornell.json -o "$T/fr.exr" --spp 1 --tile 32 --workers 0 --frames 1:3 --no-journal \
  --bind "ipc://$T/fr.sock" >"$T/m.log" 2>&1 &
mp=$!
echo $mp >>"$T/pids"
timeout 120 $L "ipc://$T/fr.sock" -n 4 --image "$T/ref.exr" >"$T/log" 2>&1 && lr=0 || lr=1
wait $mp && mr=0 || mr=1
if [ $lr = 0 ] && [ $mr = 0 ] && grep -q " acked 768 acked_twice [0-9]* unacked 0 peers 4 " "$T/log" &&
  for f in 1 2 3; do $X cmp "$T/ref.exr" "$T/fr.000$f.exr" >/dev/null 2>&1 || exit 1; done; then
  ok "frames 1:3: every one of 3 x 256 units acknowledged, each frame the pixels sent"
else bad "frames 1:3: every one of 3 x 256 units acknowledged ($(grep granted "$T/log")), each frame the pixels sent"; fi

# A JOB that the worker's queue refuses: frame 1's last RESULT comes after a flood of
# BLOB_REQs and a 2 s pause in reading (--flood-at-end; 1-message receive queue), so the
# master's queue for it is full when frame 2's JOB goes out. The master sends that JOB
# again until it is queued; frame 2 renders. (Not "unacked 0": an ACK that finds the
# queue full is dropped, as is a BLOB_DATA: blob_reqs_dropped.)
timeout 120 $M scenes/cornell/cornell.json -o "$T/jr.exr" --spp 1 --tile 32 --workers 0 --frames 1:2 --no-journal \
  --bind "ipc://$T/jr.sock" >"$T/m.log" 2>&1 &
mp=$!
echo $mp >>"$T/pids"
timeout 120 $L "ipc://$T/jr.sock" -n 1 --image "$T/ref.exr" --tiny-queue --flood-at-end 3000 2000 >"$T/log" 2>&1
wait $mp && mr=0 || mr=1
cat "$T/m.log" >>"$T/log"
dropped=$(counter blob_reqs_dropped "$T/jr.exr")
if [ $mr = 0 ] && grep -q "the JOB could not be queued; sending it again" "$T/log" && [ "${dropped:-0}" -gt 0 ] &&
  grep -q "^loadpeers: granted 512 results 512 " "$T/log" && [ "$(counter tiles_done "$T/jr.exr")" = 512 ] &&
  for f in 1 2; do $X cmp "$T/ref.exr" "$T/jr.000$f.exr" >/dev/null 2>&1 || exit 1; done; then
  ok "a JOB its worker's full queue refused is sent again: frame 2 rendered, its pixels those sent ($dropped BLOB_DATA dropped)"
else bad "a JOB its worker's full queue refused is sent again ($(grep granted "$T/log"), blob_reqs_dropped ${dropped:-?})"; fi

$M --keygen "$T/master.key" >/dev/null && $M --keygen "$T/w.key" >/dev/null
cp "$T/w.key.pub" "$T/allow"
KEYARGS="--key $T/w.key $T/master.key.pub --strangers" AUTHC= # the strangers are refused: counted below
load curve "tcp://127.0.0.1:$(port)" --curve-secret "$T/master.key" --allow "$T/allow" --bcast-mbps 1000
ar=$(counter auth_rejects "$T/curve.exr") hf=$(counter handshake_failures "$T/curve.exr")
if grep -q "^loadpeers: strangers received 0$" "$T/curve.llog" && grep -q "^loadpeers: chunks bcast [1-9]" "$T/curve.llog" &&
  [ "${ar:-0}" -ge 1 ] && [ "${hf:-0}" -ge 1 ]; then
  ok "curve: the broadcast reached the allowed fake workers, not a subscriber without CurveZMQ or with a key not allowed (refused: $ar by ZAP, $hf handshakes)"
else bad "curve: the broadcast reached the allowed fake workers only ($(grep strangers "$T/curve.llog"), auth_rejects ${ar:-?}, handshake_failures ${hf:-?})"; fi

# Blob delivery to 16 fake workers (--hold-ready: none renders before all have the blobs).
mkdir -p "$T/bc"
python3 scripts/gen_mesh.py 250 "$T/bc/big" >/dev/null
rm -f "$T/bc/big.obj" "$T/bc/big.ascii.ply" "$T/bc/big.be.ply"
cp scenes/tiny/tiny.json scenes/tiny/tiny.obj scenes/tiny/tiny.mtl scenes/tiny/lamp.obj "$T/bc/"
python3 -c 'import json, sys
d = json.load(open(sys.argv[1])); d["objects"].append({"type": "ply", "file": "big.ply", "transform": {"translate": [-3, 0, 2]}})
json.dump(d, open(sys.argv[1], "w"), indent=1)' "$T/bc/tiny.json"
S=$(cat "$T/bc"/* | wc -c) # one copy of every blob
# deliver NAME MASTER_OPTIONS -- LOADPEERS_OPTIONS: sets P2P, BC (bytes the master sent)
deliver() {
  name=$1
  shift
  mo=
  while [ "$1" != -- ]; do mo="$mo $1"; shift; done
  shift
  timeout 120 $M "$T/bc/tiny.json" -o "$T/$name.exr" --workers 0 --bind "ipc://$T/$name.sock" --no-journal \
    --worker-timeout-ms 60000 $mo >"$T/m.log" 2>&1 &
  mp=$!
  echo $mp >>"$T/pids"
  timeout 120 $L "ipc://$T/$name.sock" -n 16 --hold-ready "$@" >"$T/log" 2>&1 && lr=0 || lr=1
  wait $mp && mr=0 || mr=1
  cat "$T/m.log" >>"$T/log"
  P2P=$(counter blob_bytes_p2p "$T/$name.exr") BC=$(counter blob_bytes_bcast "$T/$name.exr")
  if [ $lr = 0 ] && [ $mr = 0 ] && grep -q "^loadpeers: fetch 16 " "$T/log" && grep -q " unacked 0 peers 16" "$T/log"; then
    ok "$name: 16 fake workers have every blob (hashes checked) and the frame is done"; else bad "$name: 16 fake workers have every blob and the frame is done"; fi
}
deliver p2p --bcast-mbps 0 --
if [ "$P2P" = $((16 * S)) ] && [ "$BC" = 0 ]; then
  ok "point to point: the master sent 16 copies ($P2P bytes)"; else bad "point to point: the master sent 16 copies of $S bytes (p2p $P2P, broadcast $BC)"; fi
deliver bcast --bcast-mbps 1000 --
if [ -n "$P2P" ] && [ -n "$BC" ] && [ "$BC" -ge "$S" ] && [ $((P2P + BC)) -le $((3 * S)) ] &&
  grep -q "^loadpeers: chunks bcast [1-9][0-9]* p2p [0-9]* bad 0 " "$T/log"; then
  ok "broadcast: the master sent $((P2P + BC)) bytes for 16 workers, at most 3 copies of $S"; else bad "broadcast: the master sent at most 3 copies of $S bytes (p2p $P2P, broadcast $BC)"; fi
deliver faulty --bcast-mbps 1000 -- --corrupt-bcast 3 --drop-bcast 5
bad_chunks=$(awk '/^loadpeers: chunks/ {print $8}' "$T/log") p2p_chunks=$(awk '/^loadpeers: chunks/ {print $6}' "$T/log")
if [ "${bad_chunks:-0}" -gt 0 ] && [ "${p2p_chunks:-0}" -gt 0 ] && [ -n "$P2P" ] && [ "$P2P" -gt 0 ]; then
  ok "broadcast chunks corrupted ($bad_chunks refused by their hash) or dropped: fetched point to point ($p2p_chunks chunks)"; else bad "corrupted or dropped broadcast chunks fetched point to point (bad ${bad_chunks:-?}, p2p ${p2p_chunks:-?}, master p2p ${P2P:-?})"; fi
# --- one fake worker with 2048 credits (a worker of 1024 threads): more TILEs at once than
# the master's socket queues for it (ZMQ_SNDHWM 1000). A TILE that cannot be queued is
# taken back and sent later, not lost to a holder that never got it: every unit is done ---
sed 's/"width": 32, "height": 24/"width": 512, "height": 512/' scenes/tiny/tiny.json >"$T/big.json"
cp scenes/tiny/*.obj scenes/tiny/*.mtl "$T/"
# (generous timeouts: one process answering 2048 TILEs at once may miss a heartbeat on a
# loaded machine, and an eviction would end the run with no worker)
timeout 300 $M "$T/big.json" -o "$T/credits.exr" --spp 1 --tile 8 --workers 0 --bind "ipc://$T/c.sock" \
  --worker-timeout-ms 60000 --stall-ms 60000 >"$T/m.log" 2>&1 &
mp=$!
echo $mp >>"$T/pids"
timeout 300 $L "ipc://$T/c.sock" -n 1 --credits 2048 --timeout-ms 240000 >"$T/log" 2>&1
wait $mp && mr=0 || mr=1
cat "$T/m.log" >>"$T/log"
# (not "unacked 0": an ACK that finds the queue full is dropped, which only costs the
# worker memory until the next frame)
if [ $mr = 0 ] && grep -q "granted 4096 results 4096 " "$T/log" && [ "$(counter tiles_done "$T/credits.exr")" = 4096 ]; then
  ok "a worker with 2048 credits: TILEs that do not fit its queue go later, every one of 4096 tiles done"
else bad "a worker with 2048 credits: TILEs that do not fit its queue go later, every one of 4096 tiles done"; fi

# --- a fake worker that reads slowly (its queue takes 1 message, a 2 s pause after READY)
# with 1200 credits on a media scene of 2 passes: the master's queue for it is full when
# photon map 1 is published. Its MAP is kept and sent later, before any TILE of pass 1
# (a worker drops a TILE whose map was never announced) ---
sed 's/"width": 160, "height": 120/"width": 512, "height": 512/' scenes/fog_spot/fog_spot.json >"$T/fog.json"
cp scenes/fog_spot/room.obj "$T/"
timeout 300 $M "$T/fog.json" -o "$T/maps.exr" --spp 2 --passes 2 --tile 8 --workers 0 --no-journal \
  --worker-timeout-ms 60000 --stall-ms 60000 --bind "ipc://$T/f.sock" >"$T/m.log" 2>&1 &
mp=$!
echo $mp >>"$T/pids"
timeout 300 $L "ipc://$T/f.sock" -n 1 --credits 1200 --pause-ms 2000 --tiny-queue --no-fetch --timeout-ms 240000 >"$T/log" 2>&1
wait $mp && mr=0 || mr=1
cat "$T/m.log" >>"$T/log"
if [ $mr = 0 ] && grep -q "^loadpeers: tiles_before_map 0$" "$T/log" && [ "$(counter tiles_done "$T/maps.exr")" = 8192 ]; then
  ok "a slow reader with 1200 credits: the MAP that did not fit its queue went later, before its pass's TILEs"
else bad "a slow reader with 1200 credits: the MAP that did not fit its queue went later, before its pass's TILEs ($(grep tiles_before_map "$T/log"))"; fi

finish
