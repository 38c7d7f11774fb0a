#!/bin/sh
# Frame farms: --frames A:B[:STEP] over the keyframed motion scene. The range writes
# exactly the requested numbered files, each bit-identical to rendering that frame alone
# (one job per frame, --frames F:F); '#' runs in the name take the frame number; a master
# killed along the way (after a worker was killed too) and restarted skips the frames it
# finished, resumes the half-done one from its journal and ends with the same files.
# Ends with "integration: N passed, N failed". Usage: BUILD=build TRIALS=4 sh tests/integration/frames.sh
. "$(dirname "$0")/lib.sh"
lib_init frames
FRAME_TRIALS=${FRAME_TRIALS:-4}
rnd() { echo $(( $(od -An -N2 -tu2 /dev/urandom) % $1 )); }
SCENE=scenes/motion/motion.json
ARGS="--spp 512 --tile 8"

# Each frame alone: one job per frame, the farm manager's unit.
mkdir -p "$T/ref"
r=0
for f in 0 1 2; do
  timeout 60 $M $SCENE -o "$T/ref/f.exr" --frames $f:$f --workers 1 $ARGS >"$T/log" 2>&1 || r=1
done
if [ $r = 0 ] && [ "$(ls "$T/ref" | tr '\n' ' ')" = "f.0000.exr f.0000.exr.stats.json f.0001.exr f.0001.exr.stats.json f.0002.exr f.0002.exr.stats.json " ] &&
  [ "$(counter frames_done "$T/ref/f.0001.exr")" = 1 ] &&
  ! $X cmp "$T/ref/f.0000.exr" "$T/ref/f.0001.exr" >/dev/null 2>&1 &&
  ! $X cmp "$T/ref/f.0001.exr" "$T/ref/f.0002.exr" >/dev/null 2>&1; then
  ok "one job per frame (--frames F:F) writes f.000F.exr and its own f.000F.exr.stats.json; frames differ"
else bad "one job per frame (--frames F:F) writes f.000F.exr and its own f.000F.exr.stats.json; frames differ"; fi

# The range in one job: workers keep the scene between frames.
mkdir -p "$T/range"
timeout 60 $M $SCENE -o "$T/range/f.exr" --frames 0:2 --workers 2 --threads 1 $ARGS >"$T/log" 2>&1 && r=0 || r=1
same=0
for f in 0000 0001 0002; do $X cmp "$T/ref/f.$f.exr" "$T/range/f.$f.exr" >/dev/null && same=$((same + 1)); done
if [ $r = 0 ] && [ $same = 3 ] && [ "$(ls "$T/range" | grep -v "\.stats\.json$" | tr '\n' ' ')" = "f.0000.exr f.0001.exr f.0002.exr " ] &&
  [ -s "$T/range/f.exr.stats.json" ] && [ "$(counter frames_done "$T/range/f.exr")" = 3 ] && [ "$(grep -c 'scene kept' "$T/log")" = 4 ]; then
  ok "--frames 0:2: exactly 3 files, each identical to its frame alone; workers kept the scene"
else bad "--frames 0:2: exactly 3 files, each identical to its frame alone; workers kept the scene"; fi

# Run again: everything is done already.
timeout 60 $M $SCENE -o "$T/range/f.exr" --frames 0:2 --workers 2 --threads 1 $ARGS >"$T/log" 2>&1 && r=0 || r=1
if [ $r = 0 ] && [ "$(counter frames_skipped "$T/range/f.exr")" = 3 ] && [ "$(counter tiles_assigned "$T/range/f.exr")" = 0 ] &&
  [ "$(grep -c 'already rendered with this scene and settings; skipped' "$T/log")" = 3 ]; then
  ok "finished frames are skipped, and the master says so"; else bad "finished frames are skipped, and the master says so"; fi

# '#' runs and a step; other settings make a frame count as not done.
mkdir -p "$T/hash"
timeout 60 $M $SCENE -o "$T/hash/shot_######_v1.exr" --frames 0:2:2 --workers 1 $ARGS >"$T/log" 2>&1 && r=0 || r=1
$X cmp "$T/ref/f.0000.exr" "$T/hash/shot_000000_v1.exr" >/dev/null && $X cmp "$T/ref/f.0002.exr" "$T/hash/shot_000002_v1.exr" >/dev/null || r=1
timeout 60 $M $SCENE -o "$T/hash/shot_######_v1.exr" --frames 0:2:2 --workers 1 --spp 4 --tile 8 >"$T/log2" 2>&1 || r=1
if [ $r = 0 ] && [ "$(ls "$T/hash" | grep -v "\.stats\.json$" | tr '\n' ' ')" = "shot_000000_v1.exr shot_000002_v1.exr " ] &&
  [ "$(counter frames_skipped "$T/hash/shot_######_v1.exr")" = 0 ] && [ "$(counter frames_done "$T/hash/shot_######_v1.exr")" = 2 ] &&
  ! $X cmp "$T/ref/f.0002.exr" "$T/hash/shot_000002_v1.exr" >/dev/null 2>&1; then
  ok "'######' takes the zero-padded frame, STEP 2; other settings re-render"; else bad "'######' takes the zero-padded frame, STEP 2; other settings re-render"; fi

# Settings the command line sets beside the scene file count too: a frame rendered to one
# target error is not done for another, and is for the same.
mkdir -p "$T/adapt"
r=0
timeout 60 $M $SCENE -o "$T/adapt/f.exr" --frames 0:0 --workers 1 $ARGS --target-error 0.9 >"$T/log" 2>&1 || r=1
timeout 60 $M $SCENE -o "$T/adapt/f.exr" --frames 0:0 --workers 1 $ARGS --target-error 0.5 >"$T/log" 2>&1 || r=1
redone=$(counter frames_done "$T/adapt/f.0000.exr")
timeout 60 $M $SCENE -o "$T/adapt/f.exr" --frames 0:0 --workers 1 $ARGS --target-error 0.5 >"$T/log" 2>&1 || r=1
if [ $r = 0 ] && [ "$redone" = 1 ] && [ "$(counter frames_skipped "$T/adapt/f.0000.exr")" = 1 ]; then
  ok "a frame rendered to --target-error 0.9 is rendered again for 0.5, then skipped"
else bad "a frame rendered to --target-error 0.9 is rendered again for 0.5, then skipped (done $redone)"; fi

# A worker and then the master killed along the way; restarted until done.
good=0
journaled=0
skipped=0
i=0
while [ $i -lt "$FRAME_TRIALS" ]; do
  i=$((i + 1))
  d="$T/kill$i"
  mkdir -p "$d"
  $M $SCENE -o "$d/f.exr" --frames 0:2 --workers 2 --threads 1 $ARGS >"$T/klog" 2>&1 &
  mpid=$!
  echo $mpid >"$T/pids"
  sleep "0.$(( $(rnd 6) + 1 ))"
  w=$(pgrep -P $mpid | head -1)
  [ -n "$w" ] && kill -9 "$w"
  sleep "0.$(( $(rnd 9) + 1 ))"
  kill -9 $mpid 2>/dev/null
  wait $mpid 2>/dev/null
  before=$(ls "$d" | grep -c '^f\.[0-9]*\.exr$')
  timeout 60 $M $SCENE -o "$d/f.exr" --frames 0:2 --workers 2 --threads 1 $ARGS >"$T/log" 2>&1 && r=0 || r=1
  same=0
  for f in 0000 0001 0002; do $X cmp "$T/ref/f.$f.exr" "$d/f.$f.exr" >/dev/null 2>&1 && same=$((same + 1)); done
  if [ $r = 0 ] && [ $same = 3 ] && [ "$(ls "$d" | grep -v "\.stats\.json$" | tr '\n' ' ')" = "f.0000.exr f.0001.exr f.0002.exr " ] &&
    [ "$(counter frames_skipped "$d/f.exr")" = "$before" ] && [ "$(counter frames_done "$d/f.exr")" = $((3 - before)) ]; then
    good=$((good + 1)); journaled=$((journaled + $(counter tiles_from_journal "$d/f.exr"))); skipped=$((skipped + before))
  else
    echo "trial $i: rc $r, $same identical, $before done before the restart, files: $(ls "$d" | tr '\n' ' ')"
    cat "$T/klog" >>"$T/log"
  fi
done
echo "frames: master killed mid-range: $good of $FRAME_TRIALS trials exact; $skipped frames skipped, $journaled tiles from journals"
if [ $good = "$FRAME_TRIALS" ]; then ok "range with a worker and the master killed: exactly the requested frames, identical"
else bad "range with a worker and the master killed: exactly the requested frames, identical"; fi

# --preview with a range: one PNG per frame, named like the EXRs.
mkdir -p "$T/pv"
timeout 60 $M $SCENE -o "$T/pv/f.exr" --frames 1:2 --workers 1 --spp 1 --preview "$T/pv/p.png" >"$T/log" 2>&1 && r=0 || r=1
if [ $r = 0 ] && [ -s "$T/pv/p.0001.png" ] && [ -s "$T/pv/p.0002.png" ] && ! cmp -s "$T/pv/p.0001.png" "$T/pv/p.0002.png" &&
  [ ! -e "$T/pv/p.png" ]; then
  ok "--preview with --frames: one PNG per frame"; else bad "--preview with --frames: one PNG per frame"; fi

finish
