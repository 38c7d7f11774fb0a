#!/bin/sh
# The master's capacity (docs/cluster.md, "How many workers one master keeps busy"):
# 1. Worker time per tile: scenes/cornell (512x512, SPP spp, 32 px tiles) with 1 worker x 1
#    thread, CPU s of master and worker / tiles.
# 2. Master time per tile: build/loadpeers, N fake workers answering every TILE at once
#    with a real tile chunk (the render of step 1), against a master on a 2048x2048 copy of
#    the scene; tiles of 16, 32 and 64 px; ipc without keys, tcp with CurveZMQ, each with
#    and without the journal. The master's CPU per tile over the tile phase (from /proc):
#    the whole process and its main thread (the loop, the serial part). Workers kept busy
#    = worker time per tile (scaled by pixels from 32 px) / the loop's time per tile.
#    Then the headline case (32 px, tcp + CurveZMQ, journal) again with BIG_N fake
#    workers: the loop's cost at the number of workers the target names.
# 3. Blob delivery: a binary PLY of about 45 MB (scripts/gen_mesh.py 880) in a scene, to
#    1, 4, 16 and 64 fake workers (--hold-ready: nobody renders before every peer has it),
#    point to point (--bcast-mbps 0) and by the broadcast (--bcast-mbps 1000), one after the
#    other for each N: time until the last has it (every chunk and the blob's hash
#    checked), bytes the master sent on each path (its counters) and its CPU s.
# 4. Scaling: master + 2 workers x 1 thread against master + 1 worker x 2 threads, Cornell
#    at SCALE_SPP spp, REPS runs each, alternating, wall and CPU time (medians); efficiency
#    = the second's time / the first's.
# 5. A model of the speed-up at 16, 64, 256 and 1024 workers from 1-3 (see the doc).
# (2b, between 2 and 3: the master's memory on the smoke in 64 passes against MEM_N fake
# workers; MEM_N=0 skips it.)
# Environment: SPP (64), N (fake workers, 16), BIG_N (1024; 0 skips it), SCALE_SPP (16), REPS (3), BCAST_NS
# ("1 4 16 64"), MESH_N (880), MEM_N (64), MEM_SIZE (1024); WT_US and LOOP_US (both: skip
# parts 1-2, use these);
# DELIVERY_ONLY=1: part 3 alone. Output: bench-out/bench_master.txt.
# Usage: BUILD=build sh scripts/bench_master.sh
set -eu
. scripts/lib.sh
bench_init master
SPP=${SPP:-64}
N=${N:-16}
BIG_N=${BIG_N:-1024}
SCALE_SPP=${SCALE_SPP:-16}
REPS=${REPS:-3}
BCAST_NS=${BCAST_NS:-"1 4 16 64"}
MESH_N=${MESH_N:-880}
R="$OUT/bench_master.txt"
L=$BUILD/loadpeers
: >"$R"
say() { echo "$*" | tee -a "$R"; }

# 1. the worker's time per tile (WT_US and LOOP_US given: parts 1 and 2 are skipped, the
# rest uses them)
if [ -z "${DELIVERY_ONLY:-}" ] && { [ -z "${WT_US:-}" ] || [ -z "${LOOP_US:-}" ]; }; then
cpu=$(cpu_secs $BUILD/master scenes/cornell/cornell.json -o "$T/ref.exr" --workers 1 --threads 1 --spp "$SPP" --tile 32)
tiles=$(( (512 / 32) * (512 / 32) ))
wt_us=$(echo "$cpu * 1000000 / $tiles" | bc -l)
say "worker: scenes/cornell 512x512, $SPP spp, 32 px tiles, 1 worker x 1 thread: $cpu CPU s for $tiles tiles = $(printf %.0f "$wt_us") us per tile"

# 2. the master's time per tile
mkdir -p "$T/big"
cp scenes/cornell/cornell.obj scenes/cornell/cornell.mtl "$T/big/"
python3 -c 'import json, sys
d = json.load(open("scenes/cornell/cornell.json")); d["render"]["width"] = d["render"]["height"] = 2048
json.dump(d, open(sys.argv[1], "w"), indent=1)' "$T/big/cornell.json"
$BUILD/master --keygen "$T/master.key" >/dev/null
$BUILD/master --keygen "$T/w.key" >/dev/null
cp "$T/w.key.pub" "$T/allow"
# load TILE TRANSPORT JOURNAL [WORKERS]: one master + loadpeers run (WORKERS fake workers,
# default N); prints "tiles/s process_us loop_us"
load() {
  rm -f "$T/o.exr"*
  case $2 in
    ipc) ep="ipc://$T/m.sock" mopts= lopts= ;;
    curve) ep="tcp://127.0.0.1:$(free_port)" mopts="--curve-secret $T/master.key --allow $T/allow"
      lopts="--key $T/w.key $T/master.key.pub" ;;
  esac
  jopt=
  [ "$3" = on ] || jopt=--no-journal
  $BUILD/master "$T/big/cornell.json" -o "$T/o.exr" --tile "$1" --workers 0 --bind "$ep" $mopts $jopt >"$T/mlog" 2>&1 &
  mp=$!
  $L "$ep" -n "${4:-$N}" --no-fetch --image "$T/ref.exr" --master-pid $mp $lopts >"$T/llog" 2>&1 || { cat "$T/llog" "$T/mlog" >&2; exit 1; }
  wait $mp || { cat "$T/mlog" >&2; exit 1; }
  awk '/tiles_per_s/ {r = $3} /master_cpu_us_per_tile/ {p = $3; l = $5} END {print r, p, l}' "$T/llog"
}
say ""
say "master: build/loadpeers with $N fake workers, a 2048x2048 frame, chunks of the render above; CPU per tile from /proc"
say "tile px | transport | journal | tiles/s (wall) | master process us/tile | loop us/tile | workers kept busy"
for tile in 16 32 64; do
  for tr in ipc curve; do
    for j in on off; do
      set -- $(load $tile $tr $j)
      busy=$(echo "$wt_us * ($tile * $tile) / (32 * 32) / $3" | bc -l)
      say "$tile | $tr | $j | $1 | $2 | $3 | $(printf %.0f "$busy")"
      [ "$tile $tr $j" = "32 curve on" ] && loop32=$3 && busy32=$busy
    done
  done
done
say "headline (32 px, tcp + CurveZMQ, journal): the loop takes $loop32 us per tile: one master keeps $(printf %.0f "$busy32") workers busy (target 1000)"
if [ "$BIG_N" -gt 0 ]; then
  set -- $(load 32 curve on "$BIG_N")
  busybig=$(echo "$wt_us / $3" | bc -l)
  say "the same with $BIG_N fake workers: $1 tiles/s, the loop $3 us per tile: $(printf %.0f "$busybig") workers kept busy"
  # the model below takes the loop's larger cost of the two
  loop32=$(echo "$loop32 $3" | awk '{print ($2 > $1) ? $2 : $1}')
fi
elif [ -z "${DELIVERY_ONLY:-}" ]; then
  wt_us=$WT_US loop32=$LOOP_US
  say "given: worker $wt_us us per 32 px tile, the master's loop $loop32 us per tile"
fi

# 2b. the master's memory on a frame of many passes (docs/cluster.md, "The master's
# memory"): the smoke at MEM_SIZE^2 in 64 photon-map passes against MEM_N fake workers
# answering at once (ipc, no journal): peak resident memory of the master, the most
# RESULTs its checker pool held, wall time.
if [ -z "${DELIVERY_ONLY:-}" ] && [ "${MEM_N:-64}" -gt 0 ]; then
  MEM_N=${MEM_N:-64}
  MEM_SIZE=${MEM_SIZE:-1024}
  mkdir -p "$T/sm"
  cp scenes/smoke/* "$T/sm/"
  python3 -c 'import json, sys
d = json.load(open(sys.argv[1])); d["render"]["width"] = d["render"]["height"] = int(sys.argv[2])
json.dump(d, open(sys.argv[1], "w"), indent=1)' "$T/sm/smoke.json" "$MEM_SIZE"
  rm -f "$T/m.exr"*
  /usr/bin/time -f "%M %e" -o "$T/mt" $BUILD/master "$T/sm/smoke.json" -o "$T/m.exr" --spp 64 --photons 20000 --tile 32 \
    --workers 0 --bind "ipc://$T/mem.sock" --no-journal --worker-timeout-ms 120000 >"$T/mlog" 2>&1 &
  mp=$!
  $L "ipc://$T/mem.sock" -n "$MEM_N" --no-fetch >"$T/llog" 2>&1 || { cat "$T/llog" "$T/mlog" >&2; exit 1; }
  wait $mp
  units=$(python3 -c 'import json, sys; s = json.load(open(sys.argv[1])); print(s["tiles"] * s["passes"])' "$T/m.exr.stats.json")
  pool=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["counters"]["results_in_pool_max"])' "$T/m.exr.stats.json")
  say ""
  say "memory: the smoke at ${MEM_SIZE}x${MEM_SIZE} in 64 passes ($units units), $MEM_N fake workers, ipc, no journal"
  say "master peak resident MB | most RESULTs in the checker pool | wall s | bytes a pixel"
  awk -v p="$pool" -v px="$((MEM_SIZE * MEM_SIZE))" '{ printf "%.0f | %s | %s | %.0f\n", $1 / 1024, p, $2, $1 * 1024 / px }' "$T/mt" | tee -a "$R"
fi

# 3. blob delivery, point to point and by the broadcast
mkdir -p "$T/bc"
python3 scripts/gen_mesh.py "$MESH_N" "$T/bc/big" >/dev/null
rm -f "$T/bc/big.obj" "$T/bc/big.ascii.ply" "$T/bc/big.be.ply"
cp scenes/tiny/tiny.json scenes/tiny/tiny.obj scenes/tiny/tiny.mtl scenes/tiny/lamp.obj "$T/bc/"
python3 -c 'import json, sys
d = json.load(open(sys.argv[1])); d["objects"].append({"type": "ply", "file": "big.ply", "transform": {"translate": [-3, 0, 2]}})
json.dump(d, open(sys.argv[1], "w"), indent=1)' "$T/bc/tiny.json"
bytes=$(stat -c %s "$T/bc/big.ply")
scene_bytes=$(cat "$T/bc"/* | wc -c)
say ""
say "blob delivery over ipc: a $bytes-byte PLY and the small scene files ($scene_bytes bytes in all) to N fake workers"
say "workers | path | last has it (s) | bytes the master sent (point to point + broadcast) | copies | master CPU s | time / one worker's (same path)"
one_p2p= one_bc=
for n in $BCAST_NS; do
  for path in p2p bcast; do
    rm -f "$T/o.exr"*
    [ $path = p2p ] && mb=0 || mb=1000
    # a long heartbeat timeout: on a loaded machine 64 fetches at once can delay a fake
    # worker's heartbeats past the default 10 s
    /usr/bin/time -f "%U %S" -o "$T/mt" $BUILD/master "$T/bc/tiny.json" -o "$T/o.exr" --workers 0 \
      --bind "ipc://$T/b.sock" --no-journal --worker-timeout-ms 120000 --bcast-mbps $mb >"$T/mlog" 2>&1 &
    mp=$!
    $L "ipc://$T/b.sock" -n "$n" --hold-ready >"$T/llog" 2>&1 || { cat "$T/llog" "$T/mlog" >&2; exit 1; }
    wait $mp
    secs=$(awk '/^loadpeers: fetch/ {print $9 / 1000}' "$T/llog")
    p2p=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["counters"]["blob_bytes_p2p"])' "$T/o.exr.stats.json")
    bc=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["counters"]["blob_bytes_bcast"])' "$T/o.exr.stats.json")
    mcpu=$(awk '{printf "%.2f", $1 + $2}' "$T/mt")
    if [ $path = p2p ]; then
      [ -n "$one_p2p" ] || one_p2p=$secs
      one=$one_p2p
      [ "$n" = 1 ] && bc1=$secs
    else
      [ -n "$one_bc" ] || one_bc=$secs
      one=$one_bc
    fi
    say "$n | $path | $secs | $p2p + $bc | $(awk -v b=$((p2p + bc)) -v s="$scene_bytes" 'BEGIN { printf "%.2f", b / s }') | $mcpu | $(awk -v t="$secs" -v o="$one" 'BEGIN { if (o > 0) printf "%.2f", t / o; else print "-" }')"
  done
done
[ -z "${DELIVERY_ONLY:-}" ] || { echo "bench_master: $R"; exit 0; }

# 4. scaling on this machine: wall and CPU s of each run (time -f "%e %U %S")
: >"$T/two_workers"
: >"$T/one_worker"
for i in $(seq "$REPS"); do
  logged /usr/bin/time -f "%e %U %S" -o "$T/t" $BUILD/master scenes/cornell/cornell.json -o "$T/s2.exr" --workers 2 --threads 1 --spp "$SCALE_SPP"
  cat "$T/t" >>"$T/two_workers"
  logged /usr/bin/time -f "%e %U %S" -o "$T/t" $BUILD/master scenes/cornell/cornell.json -o "$T/s1.exr" --workers 1 --threads 2 --spp "$SCALE_SPP"
  cat "$T/t" >>"$T/one_worker"
done
w2=$(awk '{print $1}' "$T/two_workers" | median) c2=$(awk '{print $2 + $3}' "$T/two_workers" | median)
w1=$(awk '{print $1}' "$T/one_worker" | median) c1=$(awk '{print $2 + $3}' "$T/one_worker" | median)
say ""
say "scaling: scenes/cornell at $SCALE_SPP spp, median of $REPS alternating runs (the machine has $CORES cores, shared with other work: wall time is noisy, CPU time less so)"
say "master + 2 workers x 1 thread: wall $w2 s, CPU $c2 s"
say "master + 1 worker x 2 threads: wall $w1 s, CPU $c1 s"
say "efficiency (1 worker x 2 threads / 2 workers x 1 thread): wall $(echo "$w1 / $w2" | bc -l | xargs printf %.3f), CPU $(echo "$c1 / $c2" | bc -l | xargs printf %.3f) (target 0.95)"

# 5. the model: a frame of F tiles (32 px, this scene's cost) on W workers: the blob goes
# out first (point to point: W times the one-worker delivery; broadcast: the 1-worker time),
# then the tiles: the workers render F/W tiles each while the master's loop serves one
# tile per loop_us; the frame takes the larger of the two, plus one tile's tail.
say ""
F=16384
say "model: a 4096x4096 frame ($F tiles of 32 px at this scene's $(printf %.0f "$wt_us") us per tile), the loop's $loop32 us per tile (the larger of the headline runs), the blob's ${bc1:-?} s to one worker"
say "workers | speed-up (blob point to point) | efficiency | speed-up (blob once: broadcast) | efficiency"
for w in 16 64 256 1024; do
  awk -v w="$w" -v F="$F" -v t="$wt_us" -v m="$loop32" -v b="${bc1:-0}" 'BEGIN {
    t1 = b + F * t * 1e-6
    tiles = (F / w > F * m / t) ? F / w * t : F * m
    tp = w * b + tiles * 1e-6 + t * 1e-6; tb = b + tiles * 1e-6 + t * 1e-6
    printf "%d | %.0f | %.2f | %.0f | %.2f\n", w, t1 / tp, t1 / tp / w, t1 / tb, t1 / tb / w }' | tee -a "$R"
done
echo "bench_master: $R"
