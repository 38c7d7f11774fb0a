#!/bin/sh
# Camera rays in Embree packets (common/render/packet.c) change no pixel: every scene in
# scenes/ (its main JSON: the one named as its folder), shrunk to 24 x 16 with 8-pixel
# tiles and 21 spp (packets of 16, then 5: the 16- and 8-wide kernels, masked lanes),
# renders bit-identical (R, G, B, A, and the sums of the variance and AOV channels) and
# counts the same samples and rays (OUT.stats.json) with packets and with single rays
# (BRUME_PACKETS=0), all AOVs on. Scenes with spheres or
# motion trace single camera rays (accel.h packets_exact), so the scenes below also run
# with their spheres removed and their motion frozen, where packets do the work; spp 3
# adds the 4-wide kernel. smoke_anim is left out: its grids are the simulator's output.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/packets.sh
. "$(dirname "$0")/lib.sh"
lib_init packets
ROOT=$(pwd)
M=$ROOT/$BUILD/master
X=$ROOT/$BUILD/exrtool
CHANNELS="variance.R variance.G variance.B Z N.X N.Y N.Z P.X P.Y P.Z albedo.R albedo.G albedo.B id.object id.material"

# stat KEY OUT: a top-level figure of OUT.stats.json (samples, rays).
stat() { python3 -c 'import json, sys; print(json.load(open(sys.argv[1] + ".stats.json"))[sys.argv[2]])' "$2" "$1" 2>/dev/null; }

# same NAME JSON SPP: the render with packets and the one without are bit-identical and
# count the same samples and rays (the rays per sample that scripts/bench.sh reports).
same() {
  # shellcheck disable=SC2086 # $3: the spp and further options
  run $M "$2" -o "$T/p.exr" --workers 1 --threads 2 --spp $3 --aovs all && r1=0 || r1=1
  cp "$T/log" "$T/log.p"
  BRUME_PACKETS=0 run $M "$2" -o "$T/s.exr" --workers 1 --threads 2 --spp $3 --aovs all && r0=0 || r0=1
  d=0
  for c in $CHANNELS; do
    [ "$($X chsum "$T/p.exr" "$c")" = "$($X chsum "$T/s.exr" "$c")" ] || { echo "channel $c differs" >>"$T/cmp"; d=1; }
  done
  for k in samples rays; do
    [ -n "$(stat $k "$T/p.exr")" ] && [ "$(stat $k "$T/p.exr")" = "$(stat $k "$T/s.exr")" ] ||
      { echo "$k: $(stat $k "$T/p.exr") with packets, $(stat $k "$T/s.exr") without" >>"$T/cmp"; d=1; }
  done
  if [ $r1 = 0 ] && [ $r0 = 0 ] && [ $d = 0 ] && $X cmp "$T/p.exr" "$T/s.exr" >>"$T/cmp" 2>&1; then
    ok "packets: $1 bit-identical, same samples and rays, with and without packets"
  else
    BAD_LOGS="log.p log cmp" bad "packets: $1 bit-identical, same samples and rays, with and without packets"
  fi
  rm -f "$T/cmp"
}

# shrink DIR NAME [triangles]: a 24 x 16 copy of the scene in $T/s; with "triangles", no
# spheres and no motion (shutter closed).
shrink() {
  rm -rf "$T/s"
  cp -r "$1" "$T/s"
  python3 - "$T/s/$2.json" "${3:-}" <<'PY'
import json, sys
p = sys.argv[1]
s = json.load(open(p))
s["render"].update({"width": 24, "height": 16, "tile_size": 8})
if sys.argv[2] == "triangles":
    s["objects"] = [o for o in s["objects"] if o.get("type") != "sphere"]
    s["camera"]["shutter_close"] = s["camera"].get("shutter_open", 0)
json.dump(s, open(p, "w"), indent=1)
PY
}

for dir in scenes/*/; do
  name=$(basename "$dir")
  # Scenes with one grid per frame ("####": smoke_anim, showcase) need the simulator's
  # output first; their own tests render them.
  [ -f "$dir/$name.json" ] && ! grep -q '####' "$dir/$name.json" || continue
  shrink "$dir" "$name"
  same "$name" "$T/s/$name.json" 21
done
for name in tiny textured dof_motion; do
  shrink "scenes/$name" "$name" triangles
  same "$name without spheres or motion" "$T/s/$name.json" 21
  same "$name without spheres or motion, 3 spp" "$T/s/$name.json" 3
done
# Passes (the adaptive renderer's units): packets over each pass's samples.
shrink scenes/cornell cornell
same "cornell in 4 passes" "$T/s/cornell.json" "40 --passes 4"
finish
