#!/bin/sh
# Benchmark: our time per sample against Embree's own `pathtracer` tutorial on Embree's
# cornell_box.obj, with the tutorial's camera and point light (cornell_box.ecs), the same
# resolution, samples per pixel and path length, measured in the same run. Fixed costs
# (process start, parsing, BVH build) are removed by timing two sample counts and taking
# the slope. Both use independent random samples per dimension (the tutorial's sampler;
# ours is chosen with "sampler": "independent"), so a sample costs the same work. Prints a table, writes bench-out/bench.txt and bench-out/bench.png.
# Usage: BUILD=build sh scripts/bench.sh   (env: W, H, SPP_LO, SPP_HI, DEPTH, REPS, THREADS
# (the tutorial's threads, ours per worker or workers; default: the cores), TIME ("wall", or
# "cpu": user + system seconds of every process of a run, steadier on a loaded machine), ISA
# (our --embree-isa in the compared rows; default: the kernels Embree picks by itself on this
# CPU, which the tutorial runs, so that both trace with the same kernels; when that is not
# avx2, a row at our default, avx2, is added))
set -eu
. scripts/lib.sh
W=${W:-256}
H=${H:-256}
SPP_LO=${SPP_LO:-4}
SPP_HI=${SPP_HI:-36}
DEPTH=${DEPTH:-8}
REPS=${REPS:-3}
THREADS=${THREADS:-$CORES}
TIME=${TIME:-wall}
# The kernels Embree picks for itself here (its best instruction set), which the tutorial runs.
f=$(grep -m1 '^flags' /proc/cpuinfo)
has() { for x in "$@"; do echo " $f " | grep -q " $x " || return 1; done; }
if has avx512f avx512cd avx512dq avx512bw avx512vl; then TUT_ISA=avx512
elif has avx2 fma bmi1 bmi2; then TUT_ISA=avx2
else TUT_ISA=sse4.2; fi
ISA=${ISA:-$TUT_ISA}
if [ "$TIME" = cpu ]; then tsecs=cpu_secs; else tsecs=wall_secs; fi
MODELS=/usr/share/doc/embree3/models
bench_init bench embree-tools gnuplot-nox bc
cp "$MODELS/cornell_box.obj" "$MODELS/cornell_box.mtl" "$T/"
# The camera and light of cornell_box.ecs:
#   -pointlight 213 300 227 100000 100000 100000 ; -vp 278 273 -800 -vi 278 273 0 -vu 0 1 0 -fov 37
cat >"$T/embree_cornell.json" <<JSON
{
  "version": 1,
  "camera": {"position": [278, 273, -800], "look_at": [278, 273, 0], "up": [0, 1, 0], "fov_y": 37},
  "render": {"width": $W, "height": $H, "spp": $SPP_LO, "max_depth": $DEPTH, "seed": 1, "tile_size": 32,
             "sampler": "independent"},
  "objects": [{"type": "obj", "file": "cornell_box.obj"}],
  "lights": [{"type": "point", "position": [213, 300, 227], "intensity": [100000, 100000, 100000]}]
}
JSON

# ours TIMER WORKERS THREADS SPP, theirs TIMER SPP: one run under TIMER (wall_secs, cpu_secs or
# logged).
ours() { $1 "$BUILD/master" "$T/embree_cornell.json" -o "$T/ours.exr" --workers "$2" --threads "$3" --spp "$4" \
  --embree-isa "${5:-$ISA}"; }
theirs() { $1 pathtracer -c "$MODELS/cornell_box.ecs" -i "$T/cornell_box.obj" --size "$W" "$H" --spp "$2" \
  --max-path-length "$DEPTH" --threads "$THREADS" -o "$T/theirs.ppm"; }

: >"$T/times"
for r in $(seq "$REPS"); do
  for spp in "$SPP_LO" "$SPP_HI"; do
    echo "theirs $spp $(theirs $tsecs "$spp")" >>"$T/times"
    echo "ours1 $spp $(ours $tsecs 1 "$THREADS" "$spp")" >>"$T/times"
    # THREADS workers x 1 thread: another configuration only with more than one thread.
    [ "$THREADS" -gt 1 ] && echo "ours2 $spp $(ours $tsecs "$THREADS" 1 "$spp")" >>"$T/times"
    # Our default kernels, where they are not the compared ones.
    [ "$ISA" != avx2 ] && echo "oursd $spp $(ours $tsecs 1 "$THREADS" "$spp" avx2)" >>"$T/times"
  done
done
med() { awk -v k="$1" -v s="$2" '$1==k && $2==s {print $3}' "$T/times" | median; }
samples=$(echo "($SPP_HI - $SPP_LO) * $W * $H" | bc)
per_sample() { echo "($(med "$1" "$SPP_HI") - $(med "$1" "$SPP_LO")) / $samples * 1000000000" | bc -l; }
t_theirs=$(per_sample theirs)
t_ours1=$(per_sample ours1)
[ "$THREADS" -gt 1 ] && t_ours2=$(per_sample ours2)
[ "$ISA" != avx2 ] && t_oursd=$(per_sample oursd)
# Rays per sample of our renderer on this scene, used to estimate theirs (not reported by
# the tutorial): the exact counts of OUT.stats.json (the summary line's rates are rounded).
ours logged 1 "$THREADS" "$SPP_HI"
rays_per_sample=$(python3 -c 'import json, sys
s = json.load(open(sys.argv[1]))
print("%.6f" % (s["rays"] / s["samples"]))' "$T/ours.exr.stats.json")
ours_mrays=$(echo "$rays_per_sample * 1000 / $t_ours1" | bc -l)
theirs_mrays=$(echo "$rays_per_sample * 1000 / $t_theirs" | bc -l)
{
  printf 'Embree cornell_box.obj + point light, %sx%s, path length %s, spp %s vs %s, %s cores, %s threads, %s time, median of %s\n' \
    "$W" "$H" "$DEPTH" "$SPP_LO" "$SPP_HI" "$CORES" "$THREADS" "$TIME" "$REPS"
  printf "Embree kernels: the tutorial's own choice here, %s; ours %s (--embree-isa)\n" "$TUT_ISA" "$ISA"
  printf '%-34s %14s %10s %12s\n' "renderer" "ns/sample" "ratio" "Mrays/s"
  printf '%-34s %14.1f %10.3f %12.2f (est.)\n' "embree pathtracer ($THREADS threads)" "$t_theirs" 1 "$theirs_mrays"
  printf '%-34s %14.1f %10.3f %12.2f\n' "brume, 1 worker x $THREADS threads" "$t_ours1" "$(echo "$t_ours1 / $t_theirs" | bc -l)" "$ours_mrays"
  [ "$THREADS" -gt 1 ] &&
    printf '%-34s %14.1f %10.3f %12.2f\n' "brume, $THREADS workers x 1 thread" "$t_ours2" "$(echo "$t_ours2 / $t_theirs" | bc -l)" "$(echo "$rays_per_sample * 1000 / $t_ours2" | bc -l)"
  [ "$ISA" != avx2 ] &&
    printf '%-34s %14.1f %10.3f %12.2f\n' "brume, 1x$THREADS, default avx2" "$t_oursd" "$(echo "$t_oursd / $t_theirs" | bc -l)" "$(echo "$rays_per_sample * 1000 / $t_oursd" | bc -l)"
  printf 'ratio = our time per sample / Embree pathtracer time per sample (target <= 0.8)\n'
  printf 'rays per sample (ours, counted): %.3f; Embree Mrays/s estimated from it\n' "$rays_per_sample"
} | tee "$OUT/bench.txt"
awk '{print $1, $2, $3}' "$T/times" >"$OUT/bench-times.dat"
plot "$OUT/bench.png" <<GP
set terminal png size 800,500
set output "$OUT/bench.png"
set title "Time per sample against Embree's pathtracer (lower is better)"
set style data histograms
set style fill solid 0.8
set ylabel "ns per sample"
set yrange [0:*]
plot "-" using 2:xtic(1) title "ns/sample"
"embree" $t_theirs
"brume-1x$THREADS" $t_ours1
$([ "$THREADS" -gt 1 ] && echo "\"brume-${THREADS}x1\" $t_ours2")
$([ "$ISA" != avx2 ] && echo "\"brume-1x$THREADS-avx2\" $t_oursd")
e
GP
