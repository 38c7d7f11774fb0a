#!/bin/sh
# AOVs and pixel filters end to end, on an analytic scene: a camera at the origin looking
# down -z at the plane z = -5 (below y = 0, normal +z, albedo 0.25 0.5 0.75), sky above.
# Checks the EXR's channels and id name tables (exrheader, from openexr; iinfo and oiiotool,
# from OpenImageIO, as compositors read them), the AOVs' values against the geometry, Z = +inf and ids -1 on the sky, the same AOVs for any
# worker count, tile size and passes, and the options' errors.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/aovs.sh
. "$(dirname "$0")/lib.sh"
lib_init aovs
S=tests/integration/aovs/aovs.json

# within NAME "MEAN MIN MAX INF NAN" LO HI [INF]: min >= LO, max <= HI, no NaN, INF infinities
within() {
  if echo "$2" | awk -v lo="$3" -v hi="$4" -v inf="${5:-0}" '{ exit !(NF == 5 && $2 >= lo && $3 <= hi && $4 == inf && $5 == 0) }'; then
    ok "$1: $2"
  else
    bad "$1: got '$2', want values in [$3, $4], $5 infinities"
  fi
}

run $M $S -o "$T/a.exr" --workers 1 --threads 1 && ok "renders with every AOV" || bad "renders with every AOV"
exrheader "$T/a.exr" >"$T/hdr" 2>&1
# Z, P and the ids FLOAT; N and albedo HALF (as OIDN and compositors take them).
n=0
for c in Z P.X P.Y P.Z id.object id.material; do
  grep -q "^    $c, 32-bit floating-point" "$T/hdr" && n=$((n + 1))
done
for c in N.X N.Y N.Z albedo.R albedo.G albedo.B; do
  grep -q "^    $c, 16-bit floating-point" "$T/hdr" && n=$((n + 1))
done
if [ $n = 12 ]; then ok "exrheader lists the 12 AOV channels (N, albedo half)"; else BAD_LOGS=hdr bad "exrheader lists the 12 AOV channels, N and albedo half ($n found)"; fi
if grep -q 'id.object/0 (type string): "plane.obj"' "$T/hdr" && grep -q 'id.material/1 (type string): "plane"' "$T/hdr"; then
  ok "id name tables in the header"
else
  BAD_LOGS=hdr bad "id name tables in the header"
fi

# Rows 20..32 see only the plane: the farthest ray there leaves at most
# atan(tan(10 deg) * sqrt(1 + 1)) off axis, so Z <= 5 / cos <= 5.16.
R="0 20 33 13"
within "Z on the plane" "$($X chstat "$T/a.exr" Z $R)" 5 5.16
within "N.X" "$($X chstat "$T/a.exr" N.X $R)" 0 0
within "N.Z = 1" "$($X chstat "$T/a.exr" N.Z $R)" 1 1
within "albedo.R" "$($X chstat "$T/a.exr" albedo.R $R)" 0.25 0.25
within "albedo.G" "$($X chstat "$T/a.exr" albedo.G $R)" 0.5 0.5
within "albedo.B" "$($X chstat "$T/a.exr" albedo.B $R)" 0.75 0.75
within "P.Z = -5" "$($X chstat "$T/a.exr" P.Z $R)" -5.0001 -4.9999
within "P.Y below 0" "$($X chstat "$T/a.exr" P.Y $R)" -0.9 -0.1
within "id.object 0" "$($X chstat "$T/a.exr" id.object $R)" 0 0
within "id.material 1" "$($X chstat "$T/a.exr" id.material $R)" 1 1
# Rows 0..15 see only the sky.
R="0 0 33 16"
within "Z = +inf on the sky" "$($X chstat "$T/a.exr" Z $R)" 0 0 528
within "id.object -1 on the sky" "$($X chstat "$T/a.exr" id.object $R)" -1 -1
within "N 0 on the sky" "$($X chstat "$T/a.exr" N.Z $R)" 0 0

# The same file as compositors read it, through OpenImageIO (oiiotool, iinfo): the channel
# names they expect, and the values on the analytic plane. Pixel (16, 26) sees the plane
# at x in 5 t [2c/33 - 1, 2(c+1)/33 - 1] (c = 16) and y likewise (r = 26, downward), with
# t = tan(10 deg): its nearest hit Z lies between 5 sqrt(1 + x^2 + y^2) at the pixel's
# nearest and farthest corners, its mean P.X and P.Y between the pixel's edges.
if command -v oiiotool >/dev/null && command -v iinfo >/dev/null; then
  iinfo -v "$T/a.exr" >"$T/iinfo" 2>&1
  # (a render in passes, the default for an even spp, also has the per-pixel "samples" count)
  want="R, G, B, A, Z, samples, N.X, N.Y, N.Z, P.X, P.Y, P.Z, albedo.R, albedo.G, albedo.B, id.material, id.object, variance.R, variance.G, variance.B"
  want="R (float), G (float), B (float), A (float), Z (float), samples (float), N.X (half), N.Y (half), N.Z (half), P.X (float), P.Y (float), P.Z (float), albedo.R (half), albedo.G (half), albedo.B (half), id.material (float), id.object (float), variance.R (float), variance.G (float), variance.B (float)"
  if grep -q "33 x   33, 20 channel, float/float/float/float/float/float/half/half/half/float/float/float/half/half/half/float/float/float/float/float openexr" "$T/iinfo" && grep -qF "channel list: $want" "$T/iinfo" \
    && grep -q 'id.object/0: "plane.obj"' "$T/iinfo" && grep -q 'id.material/1: "plane"' "$T/iinfo"; then
    ok "iinfo: 20 channels named Z, samples, N.X/Y/Z, P.X/Y/Z, albedo.R/G/B, id.*, N and albedo half; id name tables"
  else
    BAD_LOGS=iinfo bad "iinfo: channel names and id name tables"
  fi
  # oistats RECT CHANNELS: the Min, Max, InfCount and FiniteCount lines of oiiotool --printstats
  oistats() { oiiotool "$T/a.exr" --ch "$2" --cut "$1" --printstats 2>&1 | awk '/Stats (Min|Max|InfCount|FiniteCount):/ { sub(/^ *Stats /, ""); sub(/ \(float\)/, ""); print }'; }
  st=$(oistats 33x13+0+20 N.X,N.Y,N.Z,albedo.R,albedo.G,albedo.B,P.Z,id.object,id.material)
  if [ "$(echo "$st" | sed -n 1p)" = "Min: 0.000000 0.000000 1.000000 0.250000 0.500000 0.750000 -5.000000 0.000000 1.000000" ] \
    && [ "$(echo "$st" | sed -n 2p)" = "Max: 0.000000 0.000000 1.000000 0.250000 0.500000 0.750000 -5.000000 0.000000 1.000000" ]; then
    ok "oiiotool: on the plane N = (0, 0, 1), albedo = (0.25, 0.5, 0.75), P.Z = -5, ids 0 and 1"
  else
    echo "$st" >"$T/st"; BAD_LOGS=st bad "oiiotool: N, albedo, P.Z and ids on the plane"
  fi
  st=$(oistats 1x1+16+26 Z,P.X,P.Y | sed -n 1p)
  if echo "$st" | awk -v c=16 -v r=26 'BEGIN { t = sin(10 * atan2(0, -1) / 180) / cos(10 * atan2(0, -1) / 180) }
      { x0 = 5 * t * (2 * c / 33 - 1); x1 = 5 * t * (2 * (c + 1) / 33 - 1)
        y0 = -5 * t * (2 * r / 33 - 1); y1 = -5 * t * (2 * (r + 1) / 33 - 1)
        ax = x0 * x0 > x1 * x1 ? x0 : x1
        zlo = sqrt(25 + (x0 * x1 < 0 ? 0 : x0 * x0) + y0 * y0); zhi = sqrt(25 + ax * ax + y1 * y1)
        exit !($2 >= zlo - 1e-5 && $2 <= zhi + 1e-5 && $3 >= x0 - 1e-5 && $3 <= x1 + 1e-5 && $4 <= y0 + 1e-5 && $4 >= y1 - 1e-5) }'; then
    ok "oiiotool: pixel (16, 26): Z, P.X, P.Y within the pixel's analytic bounds ($st)"
  else
    bad "oiiotool: pixel (16, 26): Z, P.X, P.Y outside the analytic bounds ($st)"
  fi
  st=$(oistats 33x16+0+0 Z,id.object,id.material)
  if echo "$st" | grep -q "^InfCount: 528 0 0 *$" && echo "$st" | grep -q "^FiniteCount: 0 528 528 *$" \
    && echo "$st" | grep -q "^Max: [0-9.]* -1.000000 -1.000000$"; then
    ok "oiiotool: on the sky Z = inf, ids -1"
  else
    echo "$st" >"$T/st"; BAD_LOGS=st bad "oiiotool: Z and ids on the sky"
  fi
else
  bad "oiiotool / iinfo not installed (openimageio-tools; make deps)"
fi

# A second object, a quad at z = -3 in front of the sky with the other material: its
# pixels (columns 12..20, rows 5..11 lie inside it) hold object 1 and material 0.
sed 's|{"type": "obj", "file": "plane.obj", "material": "plane"}|&, {"type": "obj", "file": "quad.obj", "material": "other"}|' $S >"$T/two.json"
cp tests/integration/aovs/plane.obj "$T/"
printf 'v -0.2 0.1 -3\nv 0.2 0.1 -3\nv 0.2 0.4 -3\nv -0.2 0.4 -3\nf 1 2 3 4\n' >"$T/quad.obj"
run $M "$T/two.json" -o "$T/two.exr" --workers 1 && ok "renders two objects" || bad "renders two objects"
R="12 5 9 7"
within "id.object 1 on the second object" "$($X chstat "$T/two.exr" id.object $R)" 1 1
within "id.material 0 on the second object" "$($X chstat "$T/two.exr" id.material $R)" 0 0
within "Z = 3 on the second object" "$($X chstat "$T/two.exr" Z $R)" 3 3.05
within "id.object 0 below" "$($X chstat "$T/two.exr" id.object 0 20 33 13)" 0 0
exrheader "$T/two.exr" >"$T/hdr" 2>&1
grep -q 'id.object/1 (type string): "quad.obj"' "$T/hdr" && ok "id name table names the second object" \
  || BAD_LOGS=hdr bad "id name table names the second object"

# The same AOVs for any worker count, thread count, tile size and passes.
sums() { for c in Z N.Z albedo.G P.X P.Y id.object id.material; do $X chsum "$1" $c; done; }
run $M $S -o "$T/p1.exr" --workers 1 --threads 2 --passes 2 && r1=0 || r1=1
run $M $S -o "$T/p2.exr" --workers 2 --threads 1 --passes 2 --tile 8 && r2=0 || r2=1
if [ $r1 = 0 ] && [ $r2 = 0 ] && [ "$(sums "$T/p1.exr")" = "$(sums "$T/p2.exr")" ] && $X cmp "$T/p1.exr" "$T/p2.exr"; then
  ok "passes: AOVs identical for 1 and 2 workers, tiles 16 and 8"
else
  bad "passes: AOVs identical for 1 and 2 workers, tiles 16 and 8"
fi
within "passes: albedo.G folded" "$($X chstat "$T/p1.exr" albedo.G 0 20 33 13)" 0.5 0.5

# Only what is asked for: --aovs overrides the scene; a scene without render.aovs pays nothing.
run $M $S -o "$T/z.exr" --workers 1 --aovs Z,albedo && r=0 || r=1
exrheader "$T/z.exr" >"$T/hdr" 2>&1
if [ $r = 0 ] && grep -q "^    Z, " "$T/hdr" && grep -q "^    albedo.R, " "$T/hdr" && ! grep -q "^    N.X, " "$T/hdr" && ! grep -q "id.object" "$T/hdr"; then
  ok "--aovs Z,albedo writes those only"
else
  BAD_LOGS="log hdr" bad "--aovs Z,albedo writes those only"
fi
sed 's/"aovs": \[[^]]*\]/"aovs": []/' $S >"$T/none.json" && cp tests/integration/aovs/plane.obj "$T/"
run $M "$T/none.json" -o "$T/n.exr" --workers 1 && r=0 || r=1
exrheader "$T/n.exr" >"$T/hdr" 2>&1
if [ $r = 0 ] && ! grep -q "^    Z, " "$T/hdr" && $X cmp "$T/a.exr" "$T/n.exr"; then
  ok "no AOVs: beauty alone, the same pixels"
else
  BAD_LOGS="log hdr" bad "no AOVs: beauty alone, the same pixels"
fi
if run $M $S -o "$T/x.exr" --aovs Z,depth; then bad "--aovs with an unknown name accepted"; else
  grep -q "aovs" "$T/log" && ok "--aovs with an unknown name refused" || bad "--aovs error message"; fi
sed 's/"Z", "N"/"Z", "normal"/' $S >"$T/badaov.json"
if run $M "$T/badaov.json" -o "$T/x.exr"; then bad "render.aovs with an unknown name accepted"; else
  grep -q 'badaov.json:[0-9]*:[0-9]*: unknown AOV "normal"' "$T/log" && ok "render.aovs: unknown name, file:line:col" || bad "render.aovs error message"; fi

# Textured albedo in media scenes: the plane with uvs and a checker albedo (squares of 0.5
# x 0.25, colours (0.2, 0.4, 0.6) and (0.8, 0.6, 0.3)), with and without a fog of density
# ~0 (VPT). The media integrator shades its AOV hit as the path tracer shades its first hit
# (same camera differentials, same filtered lookup), so the albedo AOV is the same to the
# bit, and it holds both colours of the checker (as half: 0.19995 and 0.79980).
printf 'v -100 -100 -5\nv 100 -100 -5\nv 100 0 -5\nv -100 0 -5\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n' >"$T/plane_uv.obj"
python3 - $S "$T" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["textures"] = {"checks": {"type": "checker", "scale": [400, 400], "color0": [0.2, 0.4, 0.6], "color1": [0.8, 0.6, 0.3]}}
s["materials"]["plane"] = {"type": "diffuse", "albedo_texture": "checks"}
s["objects"] = [{"type": "obj", "file": "plane_uv.obj", "material": "plane"}]
json.dump(s, open(sys.argv[2] + "/tex.json", "w"))
s["media"] = {"fog": {"sigma_a": [1e-7, 1e-7, 1e-7], "sigma_s": [1e-7, 1e-7, 1e-7], "g": 0}}
s["volume"] = {"method": "vpt", "fog": "fog", "photons": 4000}
json.dump(s, open(sys.argv[2] + "/texfog.json", "w"))
PY
run $M "$T/tex.json" -o "$T/tex.exr" --workers 1 && r1=0 || r1=1
run $M "$T/texfog.json" -o "$T/texfog.exr" --workers 1 && r2=0 || r2=1
albs() { for c in albedo.R albedo.G albedo.B N.Z; do echo "$c $($X chsum "$1" $c) $($X chstat "$1" $c 0 20 33 13)"; done; }
if [ $r1 = 0 ] && [ $r2 = 0 ] && [ "$(albs "$T/tex.exr")" = "$(albs "$T/texfog.exr")" ]; then
  ok "media scene: textured albedo AOV identical to the scene without fog"
else
  albs "$T/tex.exr" >"$T/alb"; albs "$T/texfog.exr" >>"$T/alb"; BAD_LOGS=alb bad "media scene: textured albedo AOV identical to the scene without fog"
fi
$X chstat "$T/texfog.exr" albedo.R 0 20 33 13 | awk '{ exit !($2 < 0.2002 && $3 > 0.7997) }' \
  && ok "media scene: albedo.R reaches 0.2 and 0.8 (the texture, not the material's constant)" \
  || bad "media scene: albedo.R reaches 0.2 and 0.8 (the texture, not the material's constant)"

# Pixel filters: a Gaussian changes the pixels, the same for any worker count and tile size.
run $M $S -o "$T/g1.exr" --workers 1 --filter gaussian:1.5 && r1=0 || r1=1
run $M $S -o "$T/g2.exr" --workers 2 --threads 2 --tile 8 --filter gaussian:1.5 && r2=0 || r2=1
if [ $r1 = 0 ] && [ $r2 = 0 ] && $X cmp "$T/g1.exr" "$T/g2.exr" && ! $X cmp "$T/a.exr" "$T/g1.exr" >/dev/null 2>&1; then
  ok "gaussian filter: deterministic, differs from box"
else
  bad "gaussian filter: deterministic, differs from box"
fi
if run $M $S -o "$T/x.exr" --filter gaussian:0; then bad "--filter gaussian:0 accepted"; else ok "--filter gaussian:0 refused"; fi
finish
