#!/bin/sh
# Benchmark: texture filtering, error against samples and against time. Renders the
# textured scene (scenes/textured: a checkered floor to the horizon, a textured globe in a
# mirror, a brick box through a glass slab), and its floor alone, with every texture set to
# nearest, bilinear, trilinear and EWA at 1..64 spp, and measures RMSE against a converged
# reference (the
# point-sampled textures, i.e. nearest, at REF_SPP spp with another seed: the pixel's box
# integral). Also the cost of one lookup per filter (build/texbench) and the spp each
# filter needs to reach EWA's 1-spp error. Writes bench-out/textures.txt and
# bench-out/textures.png. Called by `make bench`.
# Usage: BUILD=build sh scripts/bench_textures.sh   (env: REF_SPP, W, H, FLOOR_SCALE)
set -eu
. scripts/lib.sh
REF_SPP=${REF_SPP:-1024}
W=${W:-256}
H=${H:-144}
FLOOR_SCALE=${FLOOR_SCALE:-400}
bench_init btex gnuplot-nox bc
# Two scenes: "full" is the textured scene at the bench resolution with a finer floor
# checker (so the floor is minified almost everywhere, as a floor seen to the horizon is),
# the MTL-textured box left out (an MTL map has no filter key: it is always EWA); "floor"
# is its floor alone under its light, direct light only (max_depth 1): texture error
# without the noise of glass, edges and indirect light. One variant per filter.
cp -r scenes/textured "$T/scene"
python3 - "$T/scene" "$W" "$H" "$FLOOR_SCALE" <<'PY'
import json, sys
d = json.load(open("scenes/textured/textured.json"))
out, w, h, fs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
d["render"].update(width=w, height=h)
d["textures"]["checks"]["scale"] = [fs, fs]
d["objects"] = [o for o in d["objects"] if "tiles_box" not in o.get("file", "")]
floor = json.loads(json.dumps(d))
floor["objects"] = [o for o in d["objects"] if o.get("name") == "floor"]
floor["render"]["max_depth"] = 1
for f in ["nearest", "bilinear", "trilinear", "ewa"]:
    for name, sc in (("full", d), ("floor", floor)):
        for t in sc["textures"].values():
            t["filter"] = f
        json.dump(sc, open("%s/bench-%s-%s.json" % (out, name, f), "w"), indent=1)
# "flat": the full scene with every texture replaced by a mid grey albedo. Its error is
# what edges, glass and indirect light leave at a given spp: a floor no filter goes below.
flat = json.loads(json.dumps(d))
flat.pop("textures")
for m in flat["materials"].values():
    for k in ("albedo_texture", "bump_texture", "normal_texture", "bump_scale"):
        m.pop(k, None)
    if m["type"] == "diffuse":
        m["albedo"] = [0.5, 0.5, 0.5]
json.dump(flat, open("%s/bench-flat-none.json" % out, "w"), indent=1)
PY

: >"$T/rows"
render() { # scene.json spp seed out.exr
  rm -f "$4"
  logged "$BUILD/master" "$1" -o "$4" --workers 1 --threads "$CORES" --spp "$2" --seed "$3"
}
reference() { # name scene.json: sets REF, rendering it once per scene and binary
  REF="$OUT/textured-$1-ref-${W}x$H-$REF_SPP-$(ref_key "$2").exr"
  if [ ! -f "$REF" ]; then
    echo "textures: rendering the $1 reference ($REF_SPP spp, once)"
    render "$2" "$REF_SPP" 999 "$REF"
  fi
}
for sc in full floor; do
  reference "$sc" "$T/scene/bench-$sc-nearest.json"
  for f in nearest bilinear trilinear ewa; do
    for spp in 1 2 4 8 16 32 64; do
      render "$T/scene/bench-$sc-$f.json" "$spp" 7 "$T/img.exr"
      r=$("$BUILD/exrtool" rmse "$T/img.exr" "$REF")
      w=$(render_secs)
      echo "$sc $f $spp $r $w" >>"$T/rows"
    done
  done
done
reference flat "$T/scene/bench-flat-none.json"
: >"$T/flat"
for spp in 1 16; do
  render "$T/scene/bench-flat-none.json" "$spp" 7 "$T/img.exr"
  echo "$spp $("$BUILD/exrtool" rmse "$T/img.exr" "$REF")" >>"$T/flat"
done
"$BUILD/texbench" 2000000 >"$T/lookup"

{
  printf 'Textured scene scenes/textured (%sx%s, floor checker scale %s), %s cores, RMSE vs a %s-spp point-sampled reference\n' \
    "$W" "$H" "$FLOOR_SCALE" "$CORES" "$REF_SPP"
  printf '"full": the whole scene (mirror, glass, max_depth 5); "floor": the floor alone, direct light only\n'
  printf 'Texture lookups are centred on the sample'"'"'s pixel cell (1 spp: the pixel) and EWA'"'"'s Gaussian has the box'"'"'s variance\n'
  printf '%-6s %-10s %5s %12s %10s\n' scene filter spp rmse seconds
  awk '{printf "%-6s %-10s %5d %12.6f %10.4f\n", $1, $2, $3, $4, $5}' "$T/rows"
  awk '{printf "untextured full scene (grey albedo): RMSE %.6f at %d spp, what edges, glass and indirect light leave\n", $2, $1}' "$T/flat"
  echo "cost of one lookup (1024^2 RGB8 texture, minor axis 0.25..4 texels, anisotropy 1..30, max 16):"
  awk '{printf "  %-10s %8.1f ns\n", $1, $2}' "$T/lookup"
  # Per scene: spp each filter needs to reach EWA's 1-spp RMSE (log-log interpolation
  # between measured spp; ">64" when never reached), then the headline comparison.
  for sc in full floor; do
    awk -v sc="$sc" '
      $1 == sc { r[$2, $3] = $4; t[$2, $3] = $5 }
      END {
        target = r["ewa", 1];
        printf "%s: spp needed to reach RMSE %.6f (EWA at 1 spp):", sc, target;
        split("nearest bilinear trilinear ewa", fs, " ");
        for (k = 1; k <= 4; k++) {
          f = fs[k]; need = ">64"; prev = 0;
          for (s = 1; s <= 64; s *= 2) {
            if (r[f, s] <= target) {
              if (s == 1) need = "1";
              else { a = log(r[f, prev]); b = log(r[f, s]);
                     need = sprintf("%.1f", exp(log(prev) + (log(target) - a) / (b - a) * (log(s) - log(prev)))); }
              break;
            }
            prev = s;
          }
          printf " %s %s", f, need;
        }
        printf "\n%s: EWA at 1 spp: RMSE %.6f in %.4f s; nearest at 16 spp: RMSE %.6f in %.4f s -> EWA %s (RMSE ratio %.2f, time ratio %.2f); EWA/nearest at 1 spp: RMSE ratio %.2f\n",
          sc, r["ewa", 1], t["ewa", 1], r["nearest", 16], t["nearest", 16],
          (r["ewa", 1] < r["nearest", 16]) ? "beats it" : "does not beat it",
          r["ewa", 1] / r["nearest", 16], t["ewa", 1] / t["nearest", 16], r["ewa", 1] / r["nearest", 1];
      }' "$T/rows"
  done
} | tee "$OUT/textures.txt"

for sc in full floor; do
  for f in nearest bilinear trilinear ewa; do
    awk -v sc="$sc" -v f="$f" '$1 == sc && $2 == f {print $3, $4, $5}' "$T/rows" >"$OUT/textures-$sc-$f.dat"
  done
done
plot "$OUT/textures.png" <<GP
set terminal png size 1000,800
set output "$OUT/textures.png"
set multiplot layout 2,2 title "Textured scene: RMSE against a converged reference (log-log), per texture filter"
set logscale xy
set grid
set ylabel "RMSE"
do for [sc in "full floor"] {
  set xlabel "samples per pixel (".sc.")"
  plot for [f in "nearest bilinear trilinear ewa"] "$OUT/textures-".sc."-".f.".dat" using 1:2 with linespoints title f
  set xlabel "render seconds (".sc.")"
  plot for [f in "nearest bilinear trilinear ewa"] "$OUT/textures-".sc."-".f.".dat" using 3:2 with linespoints title f
}
unset multiplot
GP
