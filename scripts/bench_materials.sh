#!/bin/sh
# Benchmark: rough materials and the environment light on scenes/materials (rough gold,
# brushed metal, frosted glass, glossy plastic, a plastic floor with a roughness texture).
# Two comparisons, each as relRMSE against a converged reference of the default variant
# (another seed, REF_SPP spp, cached in bench-out/) at the same CPU time:
#   - GGX sampling: visible normals (Heitz 2018, the default) against the classic D cos
#     (every material's "sample_visible": false), under the scene's sky without its sun
#     (so that BSDF sampling, not light sampling, carries the reflections);
#   - the environment light: importance sampling by the map (the default) against uniform
#     sphere sampling ("sampling": "uniform"), under the scene's sky with its sun (2
#     degrees' radius, most of the sky's power).
# Equal time: at a fixed spp a variant's error e and CPU time t give e sqrt(t) (error falls
# as 1/sqrt(time)); the ratio of those is the error ratio at equal time. Writes
# bench-out/materials.txt. Usage: BUILD=build sh scripts/bench_materials.sh
# (env: REF_SPP, SPP, W, H, SEEDS)
set -eu
. scripts/lib.sh
REF_SPP=${REF_SPP:-2048}
SPP=${SPP:-"16 64"}
SEEDS=${SEEDS:-"11 12"}
W=${W:-128}
H=${H:-96}
bench_init bmat bc time
cp scenes/materials/* "$T/"
python3 scripts/gen_sky_hdr.py "$T/nosun.hdr" 128 64 35 60 0 1
variant() { # variant NAME VISIBLE ENV_SAMPLING SKY
  python3 - "$T/materials.json" "$T/$1.json" "$2" "$3" "$W" "$H" "$4" <<'PY'
import json, sys
src, dst, vis, env, w, h, sky = sys.argv[1:8]
s = json.load(open(src))
s["render"].update({"width": int(w), "height": int(h), "sampler": "independent"})
for m in s["materials"].values():
    if m["type"] in ("conductor", "dielectric", "plastic", "mirror"):
        m["sample_visible"] = vis == "1"
for l in s["lights"]:
    if l["type"] == "environment":
        l["sampling"] = env
        l["file"] = sky
json.dump(s, open(dst, "w"), indent=1)
PY
}
variant vndf 1 importance nosun.hdr
variant dcos 0 importance nosun.hdr
variant importance 1 importance sky.hdr
variant uniform 1 uniform sky.hdr

for r in vndf importance; do
  ref="$OUT/materials-ref-$r-${W}x$H-$REF_SPP-$(ref_key "$T/$r.json" "$T/sky.hdr" "$T/nosun.hdr").exr"
  if [ ! -f "$ref" ]; then
    echo "materials: rendering the $r reference ($REF_SPP spp, once)"
    logged "$BUILD/master" "$T/$r.json" -o "$ref" --workers 1 --threads "$CORES" --spp "$REF_SPP" --seed 999
  fi
  eval "REF_$r=\$ref"
done

: >"$T/rows"
for v in vndf dcos importance uniform; do
  case $v in vndf | dcos) REF=$REF_vndf ;; *) REF=$REF_importance ;; esac
  for spp in $SPP; do
    e2=0; secs=0; n=0
    for seed in $SEEDS; do
      t=$(cpu_secs "$BUILD/master" "$T/$v.json" -o "$T/img.exr" --workers 1 --threads "$CORES" --spp "$spp" --seed "$seed")
      e=$("$BUILD/exrtool" relrmse "$T/img.exr" "$REF")
      e2=$(echo "$e2 + $e * $e" | bc -l); secs=$(echo "$secs + $t" | bc -l); n=$((n + 1))
    done
    echo "$v $spp $(echo "sqrt($e2 / $n)" | bc -l) $(echo "$secs / $n" | bc -l)" >>"$T/rows"
  done
done

{
  printf 'scenes/materials at %sx%s, %s cores, independent sampler, relRMSE against a %s-spp reference, rms over seeds %s\n' \
    "$W" "$H" "$CORES" "$REF_SPP" "$SEEDS"
  printf '%-8s %6s %10s %8s %10s\n' variant spp relrmse cpu_s 'e*sqrt(t)'
  awk '{printf "%-8s %6d %10.5f %8.3f %10.5f\n", $1, $2, $3, $4, $3 * sqrt($4)}' "$T/rows"
  awk '{k[$1 " " $2] = $3 * sqrt($4); s[$2] = 1}
    END { for (p in s) {
      printf "at %s spp: D cos / VNDF error at equal time %.3f (no sun); uniform / importance environment %.3f (sun)\n",
        p, k["dcos " p] / k["vndf " p], k["uniform " p] / k["importance " p] } }' "$T/rows" | sort -n -k2
} | tee "$OUT/materials.txt"
