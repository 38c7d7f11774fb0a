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
if ! command -v "$CC_FUZZ" >/dev/null 2>&1; then
  echo "fuzz: FAILED: $CC_FUZZ not found (scripts/install-deps.sh installs clang)"
  exit 1
fi
SRC="tests/fuzz/fuzz_proto.c common/wire/proto.c common/base/log.c"
BIN="$OUT/fuzz_proto"
# rebuilt only when a source changed
if [ ! -x "$BIN" ] || [ -n "$(find $SRC common/wire/proto.h common/base/log.h -newer "$BIN" 2>/dev/null)" ]; then
  if ! $CC_FUZZ -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined -std=c11 -D_GNU_SOURCE \
      -Icommon $SRC -o "$BIN" -lm -pthread >"$OUT/build.log" 2>&1; then
    echo "fuzz: FAILED: fuzz_proto does not build (see $OUT/build.log)"; tail -5 "$OUT/build.log"; exit 1
  fi
fi
rm -rf "$OUT/corpus"
mkdir -p "$OUT/corpus"
if ! ${CC:-cc} -std=c11 -D_GNU_SOURCE -Icommon tests/fuzz/proto_seeds.c common/wire/proto.c common/base/log.c -o "$OUT/proto_seeds" -lm -pthread >"$OUT/seeds.log" 2>&1 ||
  ! "$OUT/proto_seeds" "$OUT/corpus"; then
  echo "fuzz: FAILED: cannot make the seed corpus (see $OUT/seeds.log)"; exit 1
fi
(cd "$OUT" && ./fuzz_proto -max_total_time="$SECONDS_TO_RUN" -timeout=10 -rss_limit_mb=2048 -artifact_prefix=./ \
  -print_final_stats=1 corpus >run.log 2>&1)
rc=$?
execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$OUT/run.log" | grep -o '[0-9]*$')
cov=$(grep -o 'cov: [0-9]*' "$OUT/run.log" | tail -n 1 | grep -o '[0-9]*')
if [ $rc -ne 0 ]; then
  echo "fuzz: fuzz_proto FAILED (rc $rc) after ${execs:-?} runs; input: $(ls "$OUT"/crash-* "$OUT"/leak-* "$OUT"/timeout-* 2>/dev/null | head -1); log: $OUT/run.log"
  tail -20 "$OUT/run.log"
  exit 1
fi
echo "fuzz: fuzz_proto (protocol decoder, ASan + UBSan): ${execs:-?} inputs in ${SECONDS_TO_RUN} s, coverage ${cov:-?}, no crash"

# --- the PLY reader ---
PLY_SRC="tests/fuzz/fuzz_mesh_ply.c common/scene/mesh_ply.c common/scene/mesh_obj.c common/scene/scene.c
  common/scene/texture.c common/scene/motion.c common/scene/medium.c common/image/image_load.c common/image/imgio.c
  common/image/hdr.c common/image/mip.c common/base/asset.c common/base/log.c"
BIN="$OUT/fuzz_mesh_ply"
if [ ! -x "$BIN" ] || [ -n "$(find $PLY_SRC common/scene/*.h common/image/*.h common/base/*.h -newer "$BIN" 2>/dev/null)" ]; then
  if ! $CC_FUZZ -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined -std=c11 -D_GNU_SOURCE \
      -Icommon $PLY_SRC -o "$BIN" -lOpenEXRCore-3_1 -lpng -lstb -lm -pthread >"$OUT/build-ply.log" 2>&1; then
    echo "fuzz: FAILED: fuzz_mesh_ply does not build (see $OUT/build-ply.log)"; tail -5 "$OUT/build-ply.log"; exit 1
  fi
fi
rm -rf "$OUT/ply-corpus"
mkdir -p "$OUT/ply-corpus"
if ! python3 scripts/gen_mesh.py 2 "$OUT/ply-corpus/tri" || ! python3 scripts/gen_mesh.py 2 "$OUT/ply-corpus/quad" --quads; then
  echo "fuzz: FAILED: cannot make the PLY seeds"; exit 1
fi
rm -f "$OUT"/ply-corpus/*.obj
DICT="$(pwd)/tests/fuzz/fuzz_mesh_ply.dict"
(cd "$OUT" && ./fuzz_mesh_ply -max_total_time="$SECONDS_TO_RUN" -timeout=10 -rss_limit_mb=2048 -dict="$DICT" \
  -artifact_prefix=./ -print_final_stats=1 ply-corpus >run-ply.log 2>&1)
rc=$?
execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$OUT/run-ply.log" | grep -o '[0-9]*$')
cov=$(grep -o 'cov: [0-9]*' "$OUT/run-ply.log" | tail -n 1 | grep -o '[0-9]*')
if [ $rc -ne 0 ]; then
  echo "fuzz: fuzz_mesh_ply FAILED (rc $rc) after ${execs:-?} runs; input: $(ls "$OUT"/crash-* "$OUT"/leak-* "$OUT"/timeout-* 2>/dev/null | head -1); log: $OUT/run-ply.log"
  tail -20 "$OUT/run-ply.log"
  exit 1
fi
echo "fuzz: fuzz_mesh_ply (PLY reader, ASan + UBSan): ${execs:-?} inputs in ${SECONDS_TO_RUN} s, coverage ${cov:-?}, no crash"
