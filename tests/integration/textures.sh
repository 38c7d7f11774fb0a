#!/bin/sh
# Textured scenes end to end: the image files travel to workers as blobs (a tcp worker
# started in another folder renders the same pixels), renders are bit-identical for 1 vs 3
# workers and any tile size, no NaN, a changed texture changes the image, a missing or
# damaged image is an error naming the scene's file:line:col and the image, and a textured
# floor scaled by 3e7 or 1e10 filters as the original does.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/textures.sh
. "$(dirname "$0")/lib.sh"
lib_init tex
ROOT=$(pwd)
M=$ROOT/$BUILD/master
W=$ROOT/$BUILD/worker
X=$ROOT/$BUILD/exrtool
S=scenes/textured/textured.json

# --- 1 vs 3 workers, other threads and tiles: identical pixels, no NaN ---
run $M $S -o "$T/a1.exr" --workers 1 --threads 1 --spp 2 && r1=0 || r1=1
nan_ok=0
grep -q "NaN/Inf samples dropped: 0" "$T/log" && nan_ok=1
run $M $S -o "$T/a3.exr" --workers 3 --threads 1 --spp 2 --tile 16 && r3=0 || r3=1
if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/a1.exr" "$T/a3.exr"; then ok "textured: 1 vs 3 workers bit-identical"; else bad "textured: 1 vs 3 workers bit-identical"; fi
if [ $nan_ok = 1 ]; then ok "textured: no NaN/Inf samples"; else bad "textured: no NaN/Inf samples"; fi
run $M $S -o "$T/a2.exr" --workers 2 --threads 2 --spp 2 --tile 64 && r=0 || r=1
if [ $r = 0 ] && $X cmp "$T/a1.exr" "$T/a2.exr"; then ok "textured: 2 workers x 2 threads, tile 64 bit-identical"; else bad "textured: 2 workers x 2 threads, tile 64 bit-identical"; fi

# --- a worker in another folder over tcp: textures reach it only as blobs ---
P=$(free_port)
timeout 60 $M $S -o "$T/r.exr" --spp 2 --workers 0 --bind "tcp://127.0.0.1:$P" --insecure >"$T/log" 2>&1 &
mpid=$!
sleep 0.3
mkdir -p "$T/elsewhere"
(cd "$T/elsewhere" && timeout 60 $W --connect "tcp://127.0.0.1:$P" --threads 2 >"$T/wlog" 2>&1)
wait $mpid && r=0 || r=1
if [ $r = 0 ] && $X cmp "$T/a1.exr" "$T/r.exr"; then ok "textured: remote worker elsewhere gives identical pixels"; else bad "textured: remote worker elsewhere gives identical pixels"; fi

# --- a changed image is another blob and changes the picture ---
cp -r scenes/textured "$T/copy"
mkdir -p "$T/gen" && $BUILD/maketex "$T/gen" >/dev/null 2>&1
cp "$T/gen/bricks.jpg" "$T/copy/checker.png" 2>/dev/null  # other bytes under the same name
run $M "$T/copy/textured.json" -o "$T/c.exr" --workers 1 --spp 2 && r=0 || r=1
if [ $r = 0 ] && ! $X cmp "$T/a1.exr" "$T/c.exr" >/dev/null 2>&1; then ok "textured: another image changes the pixels"; else bad "textured: another image changes the pixels"; fi

# --- errors: a missing image, a damaged one (scene key and MTL map_Kd) ---
cp -r scenes/textured "$T/bad"
rm "$T/bad/globe.png"
if ! run $M "$T/bad/textured.json" -o "$T/x.exr" && grep -qE "textured.json:[0-9]+:[0-9]+: cannot load image: .*globe.png" "$T/log" &&
  [ ! -e "$T/x.exr" ]; then ok "missing image: file:line:col and the image named"; else bad "missing image: file:line:col and the image named"; fi
cp scenes/textured/globe.png "$T/bad/globe.png"
head -c 100 scenes/textured/tiles.exr >"$T/bad/tiles.exr"
if ! run $M "$T/bad/textured.json" -o "$T/x.exr" && grep -qE "tiles.mtl:[0-9]+:[0-9]+: map_Kd: .*tiles.exr" "$T/log"; then
  ok "damaged EXR behind MTL map_Kd: mtl:line:col and the image named"; else bad "damaged EXR behind MTL map_Kd: mtl:line:col and the image named"; fi
{ printf '#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 16 +X 16\n\002\002\000\020\377\001'; head -c 100 /dev/zero; } >"$T/bad/sky.hdr"
cp scenes/textured/tiles.exr "$T/bad/tiles.exr"
if ! run $M "$T/bad/textured.json" -o "$T/x.exr" && grep -q "sky.hdr: scanline 0: run past the end of a scanline" "$T/log"; then
  ok "damaged HDR: named with the reason"; else bad "damaged HDR: named with the reason"; fi


# --- textures through media: every kind (albedo, bump, MTL map_Kd) under a fog ---
# A fog of density ~0 under the media integrator (VPT) gives the surface integrator's image:
# the same mean within noise and the same structure, far closer than the untextured scene;
# a thin fog renders bit-identically for 1 vs 3 workers with VPT and with the beam (photons
# traced over textured surfaces).
cp -r scenes/textured "$T/tf"
python3 - "$T/tf" <<'PY'
import copy, json, sys
d = sys.argv[1]
s = json.load(open(d + "/textured.json"))
s["render"].update({"width": 160, "height": 90, "spp": 16})
json.dump(s, open(d + "/plain.json", "w"))
z = copy.deepcopy(s)
z["media"] = {"fog": {"sigma_a": [1e-7, 1e-7, 1e-7], "sigma_s": [1e-7, 1e-7, 1e-7], "g": 0}}
z["volume"] = {"method": "vpt", "fog": "fog", "photons": 4000}
json.dump(z, open(d + "/fog0.json", "w"))
n = copy.deepcopy(z)
for m in n["materials"].values():
    for k in [k for k in m if k.endswith("_texture") or k == "bump_scale"]:
        del m[k]
json.dump(n, open(d + "/notex.json", "w"))
z["media"]["fog"] = {"sigma_a": [0.01, 0.01, 0.01], "sigma_s": [0.06, 0.06, 0.06], "g": 0.3}
z["render"]["spp"] = 2
json.dump(z, open(d + "/fog.json", "w"))
PY
r=0
for s in plain fog0 notex; do run $M "$T/tf/$s.json" -o "$T/m_$s.exr" --workers 1 --threads 2 || r=1; done
if [ $r = 0 ] && python3 - "$($X semean "$T/m_plain.exr")" "$($X semean "$T/m_fog0.exr")" \
  "$($X relrmse "$T/m_fog0.exr" "$T/m_plain.exr")" "$($X relrmse "$T/m_notex.exr" "$T/m_plain.exr")" <<'PY'
import math, sys
(a, sa), (b, sb) = (map(float, x.split()) for x in sys.argv[1:3])
e_tex, e_notex = float(sys.argv[3]), float(sys.argv[4])
print("  means %.6f %.6f (se %.2g %.2g); relRMSE to the surface integrator %.3f, untextured %.3f" % (a, b, sa, sb, e_tex, e_notex))
sys.exit(0 if abs(a - b) <= 4 * math.hypot(sa, sb) and e_tex < 0.5 * e_notex else 1)
PY
then ok "textures under a fog of density ~0: the surface integrator's image (mean within 4 se, structure)"
else bad "textures under a fog of density ~0: the surface integrator's image (mean within 4 se, structure)"; fi
for m in vpt beam; do
  run $M "$T/tf/fog.json" -o "$T/f1_$m.exr" --media-method $m --workers 1 --threads 1 && r1=0 || r1=1
  grep -q "NaN/Inf samples dropped: 0" "$T/log" || r1=1
  run $M "$T/tf/fog.json" -o "$T/f3_$m.exr" --media-method $m --workers 3 --threads 1 --tile 16 && r3=0 || r3=1
  if [ $r1 = 0 ] && [ $r3 = 0 ] && $X cmp "$T/f1_$m.exr" "$T/f3_$m.exr"; then ok "textured fog ($m): 1 vs 3 workers bit-identical, no NaN"
  else bad "textured fog ($m): 1 vs 3 workers bit-identical, no NaN"; fi
done

# --- the checker floor alone (direct light), scaled by 3e7 and 1e10 and 1e-10: the same
# footprints, so the image of the original, far below its own noise (a floor edge of 1.2e10
# once overflowed the squared length of its raw cross product in the footprint transfer,
# and derivatives were capped at 1e8: shifted, blurred checks) ---
floor_scene() {
  python3 - "$1" "$2" <<'PY'
import json, os, shutil, sys
dst, f = sys.argv[1], float(sys.argv[2])
os.makedirs(dst, exist_ok=True)
shutil.copy('scenes/textured/checker.png', dst)
open(os.path.join(dst, 'floor.obj'), 'w').write(''.join('v %.17g 0 %.17g\n' % (x * f, z * f) for x, z in ((-200, -200), (-200, 200), (200, 200), (200, -200))) + 'vt 0 0\nvt 0 1\nvt 1 1\nvt 1 0\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n')
s = {"version": 1, "camera": {"position": [0, 1.2 * f, -6 * f], "look_at": [0, 0.8 * f, 0], "fov_y": 45},
     "render": {"width": 48, "height": 27, "spp": 4, "max_depth": 1, "seed": 1, "tile_size": 16},
     "textures": {"checks": {"type": "image", "file": "checker.png", "scale": [100, 100], "filter": "ewa", "max_anisotropy": 16}},
     "materials": {"floor": {"type": "diffuse", "albedo_texture": "checks"}},
     "objects": [{"type": "obj", "file": "floor.obj", "material": "floor"}],
     "lights": [{"type": "point", "position": [-2 * f, 6 * f, -5 * f], "intensity": [70 * f * f] * 3}]}
json.dump(s, open(os.path.join(dst, 'floor.json'), 'w'))
PY
}
floor_scene "$T/fl1" 1
run $M "$T/fl1/floor.json" -o "$T/fl1.exr" --no-journal && r=0 || r=1
noise=$($X errest "$T/fl1.exr" 2>/dev/null)
for f in 3e7 1e10 1e-10; do
  floor_scene "$T/fl$f" $f
  run $M "$T/fl$f/floor.json" -o "$T/fl$f.exr" --no-journal && r2=0 || r2=1
  rel=$($X relrmse "$T/fl$f.exr" "$T/fl1.exr" 2>/dev/null)
  if [ $r = 0 ] && [ $r2 = 0 ] && python3 -c 'import sys; sys.exit(not (float(sys.argv[1]) < 0.1 * float(sys.argv[2])))' "$rel" "$noise"; then
    ok "textured floor scaled by $f: relRMSE $rel against the original, noise $noise"
  else bad "textured floor scaled by $f: relRMSE ${rel:-?} against the original, noise ${noise:-?}"; fi
done

finish
