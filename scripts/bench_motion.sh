#!/bin/sh
# Benchmark: the cost of motion blur. Renders scenes/motion (a spinning cube, a deforming
# pyramid, a flying sphere) with its shutter open, and the same scene with motion removed
# (shutter closed: every object frozen at shutter open, no Embree time steps, no time
# dimension), in the same run. Time per sample is the slope between two sample counts, so
# process start, parsing and BVH builds drop out; median of REPS. Prints the ratio of
# throughputs (moving / still). Usage: BUILD=build sh scripts/bench_motion.sh (env: W, H, SPP_LO, SPP_HI, REPS)
set -eu
. scripts/lib.sh
W=${W:-320}
H=${H:-240}
SPP_LO=${SPP_LO:-4}
SPP_HI=${SPP_HI:-36}
REPS=${REPS:-5}
bench_init bench-motion time
cp scenes/motion/*.obj scenes/motion/*.png scenes/motion/motion.json "$T/"
# The still variant: shutter_close = shutter_open.
sed 's/"shutter_close": [0-9.]*/"shutter_close": 0/' scenes/motion/motion.json >"$T/still.json"
grep -q '"shutter_close": 0}' "$T/still.json" || { echo "bench_motion: cannot make the still variant" >&2; exit 1; }

# CPU seconds (master and worker) of one render; the slope below removes the fixed costs.
cpu() { cpu_secs "$BUILD/master" "$1" -o "$T/out.exr" --workers 1 --spp "$2"; }
# Nanoseconds per sample: slope between SPP_LO and SPP_HI, median over REPS.
ns_per_sample() {
  i=0
  while [ $i -lt "$REPS" ]; do
    lo=$(cpu "$1" "$SPP_LO")
    hi=$(cpu "$1" "$SPP_HI")
    awk -v lo="$lo" -v hi="$hi" -v n=$(( (SPP_HI - SPP_LO) * W * H )) 'BEGIN {printf "%.2f\n", (hi - lo) * 1e9 / n}'
    i=$((i + 1))
  done | median
}
for f in motion still; do
  sed -i "s/\"width\": [0-9]*, \"height\": [0-9]*/\"width\": $W, \"height\": $H/" "$T/$f.json"
done
moving=$(ns_per_sample "$T/motion.json")
still=$(ns_per_sample "$T/still.json")
echo "motion blur cost, scenes/motion at ${W}x${H}, CPU time, slope ${SPP_LO}..${SPP_HI} spp, median of $REPS, $CORES cores"
printf '%-34s %12s %12s\n' "variant" "ns/sample" "throughput"
printf '%-34s %12s %12s\n' "still (shutter closed, no steps)" "$still" "1.000"
printf '%-34s %12s %12s\n' "moving (shutter 0..0.5)" "$moving" "$(awk -v a="$still" -v b="$moving" 'BEGIN {printf "%.3f", a / b}')"
echo "throughput of the moving scene / the still scene: $(awk -v a="$still" -v b="$moving" 'BEGIN {printf "%.3f", a / b}')"
