#!/bin/sh
# Two libFuzzer targets, briefly, for `make test`, each built with clang
# (-fsanitize=fuzzer,address,undefined) from the sources it needs only and run for
# FUZZ_CI_SECONDS (default 5):
# - the protocol decoder, seeded with one valid message of every type
#   (tests/fuzz/proto_seeds.c); it checks that every rejection has a reason and that
#   whatever decodes re-encodes to the same bytes;
# - the PLY reader (fuzz_mesh_ply), seeded with grids from scripts/gen_mesh.py in every
#   format, with its dictionary.
# A crash fails the test; its input is kept in $BUILD/fuzz-ci/. `make fuzz` runs every
# target longer. Ends with "fuzz: ..." lines.
set -u
cd "$(dirname "$0")/../.." || exit 2
BUILD=${BUILD:-build}
SECONDS_TO_RUN=${FUZZ_CI_SECONDS:-5}
CC_FUZZ=${CC_FUZZ:-clang}
OUT="$BUILD/fuzz-ci"
mkdir -p "$OUT"

# fuzz_build TARGET SOURCES HEADERS LIBS: $OUT/TARGET from the sources it needs only,
# rebuilt when one of them or of the headers changed.
fuzz_build() {
  bin="$OUT/$1"
  if [ ! -x "$bin" ] || [ -n "$(find $2 $3 -newer "$bin" 2>/dev/null)" ]; then
    if ! $CC_FUZZ -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined -std=c11 -D_GNU_SOURCE \
        -Icommon $2 -o "$bin" $4 -lm -pthread >"$OUT/build-$1.log" 2>&1; then
      echo "fuzz: FAILED: $1 does not build (see $OUT/build-$1.log)"; tail -5 "$OUT/build-$1.log"; exit 1
    fi
  fi
}

# fuzz_run TARGET WHAT CORPUS LOG [ARGS]: runs $OUT/TARGET on $OUT/CORPUS for SECONDS_TO_RUN,
# prints its summary line; a crash ends the script with status 1.
fuzz_run() {
  t=$1 what=$2 corpus=$3 log=$4
  shift 4
  (cd "$OUT" && ./"$t" -max_total_time="$SECONDS_TO_RUN" -timeout=10 -rss_limit_mb=2048 "$@" -artifact_prefix=./ \
    -print_final_stats=1 "$corpus" >"$log" 2>&1)
  rc=$?
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$OUT/$log" | grep -o '[0-9]*$')
  cov=$(grep -o 'cov: [0-9]*' "$OUT/$log" | tail -n 1 | grep -o '[0-9]*')
  if [ $rc -ne 0 ]; then
    echo "fuzz: $t FAILED (rc $rc) after ${execs:-?} runs; input: $(ls "$OUT"/crash-* "$OUT"/leak-* "$OUT"/timeout-* 2>/dev/null | head -1); log: $OUT/$log"
    tail -20 "$OUT/$log"
    exit 1
  fi
  echo "fuzz: $t ($what, ASan + UBSan): ${execs:-?} inputs in ${SECONDS_TO_RUN} s, coverage ${cov:-?}, no crash"
}
if ! command -v "$CC_FUZZ" >/dev/null 2>&1; then
  echo "fuzz: FAILED: $CC_FUZZ not found (scripts/install-deps.sh installs clang)"
  exit 1
fi
fuzz_build fuzz_proto "tests/fuzz/fuzz_proto.c common/wire/proto.c common/base/log.c" \
  "common/wire/proto.h common/base/log.h" ""
rm -rf "$OUT/corpus"
mkdir -p "$OUT/corpus"
if ! ${CC:-cc} -std=c11 -D_GNU_SOURCE -Icommon tests/fuzz/proto_seeds.c common/wire/proto.c common/base/log.c -o "$OUT/proto_seeds" -lm -pthread >"$OUT/seeds.log" 2>&1 ||
  ! "$OUT/proto_seeds" "$OUT/corpus"; then
  echo "fuzz: FAILED: cannot make the seed corpus (see $OUT/seeds.log)"; exit 1
fi
fuzz_run fuzz_proto "protocol decoder" corpus run.log

# --- the PLY reader ---
fuzz_build fuzz_mesh_ply "tests/fuzz/fuzz_mesh_ply.c common/scene/mesh_ply.c common/scene/mesh_obj.c
  common/scene/scene.c common/scene/envmap.c common/scene/texture.c common/scene/motion.c common/scene/medium.c common/image/image_load.c
  common/image/imgio.c common/image/hdr.c common/image/mip.c common/base/asset.c common/base/log.c" \
  "common/scene/*.h common/image/*.h common/base/*.h" "-lOpenEXRCore-3_1 -ldeflate -lpng -lstb"
rm -rf "$OUT/ply-corpus"
mkdir -p "$OUT/ply-corpus"
if ! python3 scripts/gen_mesh.py 2 "$OUT/ply-corpus/tri" || ! python3 scripts/gen_mesh.py 2 "$OUT/ply-corpus/quad" --quads; then
  echo "fuzz: FAILED: cannot make the PLY seeds"; exit 1
fi
rm -f "$OUT"/ply-corpus/*.obj
fuzz_run fuzz_mesh_ply "PLY reader" ply-corpus run-ply.log -dict="$(pwd)/tests/fuzz/fuzz_mesh_ply.dict"
