#!/bin/sh
# Builds every tests/fuzz/fuzz_*.c as a libFuzzer target (clang, ASan + UBSan) and runs
# each for FUZZ_SECONDS (default 30) on a seed corpus made from the files in scenes/
# (and tests/fuzz/<target>.dict when present; fuzz_nvdb also gets build/make_nvdb's files).
# FUZZ_ONLY=fuzz_nvdb (a space-separated list of names) runs only those targets.
# Prints one summary line per target; exits non-zero if any target fails to build or
# finds a crash (crash inputs are kept in $BUILD/fuzz/<target>/). Run from anywhere.
set -u
cd "$(dirname "$0")/../.." || exit 2
FUZZ_SECONDS=${FUZZ_SECONDS:-30}
BUILD=${BUILD:-build}
CC_FUZZ=${CC_FUZZ:-clang}
OUT="$BUILD/fuzz"
mkdir -p "$OUT"
LIBS="-lembree3 -lOpenEXRCore-3_1 -ldeflate -lzmq -ljansson -lsodium -lpng -lstb -lm -pthread"
CFLAGS_FUZZ="-g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined -std=c11 -D_GNU_SOURCE -Icommon"

seed_dir="$OUT/seed"
rm -rf "$seed_dir"
mkdir -p "$seed_dir"
n=0
for f in $(find scenes -type f \( -name '*.json' -o -name '*.obj' -o -name '*.ply' -o -name '*.mtl' -o -name '*.png' -o -name '*.jpg' -o -name '*.hdr' -o -name '*.exr' \) 2>/dev/null); do
    n=$((n + 1))
    cp "$f" "$seed_dir/seed_${n}_$(basename "$f")"
done

# NanoVDB seeds for fuzz_nvdb, written by NanoVDB's own writer (the Makefile builds make_nvdb);
# the small files only (a few hundred KiB each), so that one input stays fast.
nvdb_seeds="$OUT/nvdb-seed"
rm -rf "$nvdb_seeds"
mkdir -p "$nvdb_seeds"
if [ -x "$BUILD/make_nvdb" ] && "$BUILD/make_nvdb" "$nvdb_seeds" >/dev/null 2>&1; then
    "$BUILD/make_nvdb" --from-grid scenes/smoke/smoke.grid "$nvdb_seeds/smoke.nvdb" >/dev/null 2>&1
    find "$nvdb_seeds" -name '*.nvdb' -size +1000k -exec rm -f {} +
else
    echo "fuzz: warning: $BUILD/make_nvdb missing, fuzz_nvdb starts without NanoVDB seeds"
fi

failed=0
total=0
for src in tests/fuzz/fuzz_*.c; do
    [ -e "$src" ] || continue
    name=$(basename "$src" .c)
    if [ -n "${FUZZ_ONLY:-}" ]; then
        case " $FUZZ_ONLY " in *" $name "*) ;; *) continue ;; esac
    fi
    total=$((total + 1))
    dir="$OUT/$name"
    mkdir -p "$dir/corpus"
    cp "$seed_dir"/* "$dir/corpus/" 2>/dev/null
    [ "$name" = fuzz_nvdb ] && cp "$nvdb_seeds"/*.nvdb "$dir/corpus/" 2>/dev/null
    extra=""
    case $name in fuzz_smoke_*) extra="smoke/settings.c" ;; esac  # the simulator's own sources
    if ! $CC_FUZZ $CFLAGS_FUZZ "$src" $extra common/*/*.c -o "$dir/$name" $LIBS >"$dir/build.log" 2>&1; then
        echo "fuzz: $name: BUILD FAILED (see $dir/build.log)"
        failed=$((failed + 1))
        continue
    fi
    dict=""
    [ -f "tests/fuzz/$name.dict" ] && dict="-dict=$(pwd)/tests/fuzz/$name.dict"
    (cd "$dir" && ./"$name" -max_total_time="$FUZZ_SECONDS" -timeout=10 -rss_limit_mb=2048 $dict \
        -artifact_prefix=./ -print_final_stats=1 corpus >run.log 2>&1)
    rc=$?
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$dir/run.log" | grep -o '[0-9]*$')
    cov=$(grep -o 'cov: [0-9]*' "$dir/run.log" | tail -n 1 | grep -o '[0-9]*')
    if [ $rc -ne 0 ]; then
        crash=$(ls "$dir"/crash-* "$dir"/leak-* "$dir"/timeout-* "$dir"/oom-* 2>/dev/null | head -n 1)
        echo "fuzz: $name: FAILED (rc $rc) after ${execs:-?} runs; input: ${crash:-none}; log: $dir/run.log"
        failed=$((failed + 1))
    else
        echo "fuzz: $name: ok, ${execs:-?} runs in ${FUZZ_SECONDS}s, coverage ${cov:-?}"
    fi
done
echo "fuzz: $total targets, $((total - failed)) passed, $failed failed"
[ $failed -eq 0 ]
