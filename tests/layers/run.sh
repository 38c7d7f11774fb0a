#!/bin/sh
# The layering check (scripts/check_layers.py) on this tree, and on copies of it with a
# planted upward include, a sideways include between master and worker, an include of a
# missing file, includes across smoke/ (the simulator) and a circle: each must be caught, naming the file and line or the modules.
# Run by `make test`; ends with one line `layers: N passed, N failed`.
set -u
T=$(mktemp -d /tmp/brume-layers.XXXXXX)
trap 'rm -rf "$T"' EXIT
pass=0 fail=0
ok() { pass=$((pass + 1)); echo "ok: $1"; }
bad() { fail=$((fail + 1)); echo "FAIL: $1"; }

if python3 scripts/check_layers.py >"$T/out" 2>&1; then ok "this tree: $(tail -1 "$T/out")"
else cat "$T/out"; bad "this tree has layering problems"; fi

# plant NAME FILE LINE EXPECTED: a copy of the tree with LINE appended to FILE must fail,
# with EXPECTED in the report.
plant() {
  rm -rf "$T/tree"; mkdir -p "$T/tree"
  cp -r common master worker smoke "$T/tree/"
  printf '%s\n' "$3" >>"$T/tree/$2"
  if python3 scripts/check_layers.py --root "$T/tree" >"$T/out" 2>&1; then
    bad "$1: not caught"
  elif grep -q "$4" "$T/out"; then
    ok "$1: $(grep -m1 "$4" "$T/out")"
  else
    cat "$T/out"; bad "$1: caught, but the report lacks '$4'"
  fi
}
plant "upward include" common/base/log.h '#include "render/tile.h"' \
  'common/base/log.h:[0-9]*: include "render/tile.h" runs upward'
plant "image above scene" common/image/mip.c '#include "scene/scene.h"' \
  'common/image/mip.c:[0-9]*: include "scene/scene.h" runs upward'
plant "master includes worker" master/launch.c '#include "../worker/worker.h"' \
  'master/launch.c:[0-9]*: include "../worker/worker.h" runs sideways'
plant "missing header" common/wire/net.c '#include "wire/nowhere.h"' \
  'common/wire/net.c:[0-9]*: include "wire/nowhere.h" names no file'
plant "smoke includes render" smoke/fluid.c '#include "render/integrator.h"' \
  'smoke/fluid.c:[0-9]*: include "render/integrator.h" runs outside'
plant "scene includes smoke" common/scene/grid.c '#include "smoke/fluid.h"' \
  'common/scene/grid.c:[0-9]*: include "smoke/fluid.h" runs outside'
# The circle needs an arrow back: cli.h -> rng.h closes cli -> rng -> cli.
rm -rf "$T/tree"; mkdir -p "$T/tree"; cp -r common master worker "$T/tree/"
printf '#include "base/rng.h"\n' >>"$T/tree/common/base/cli.h"
printf '#include "base/cli.h"\n' >>"$T/tree/common/base/rng.h"
if python3 scripts/check_layers.py --root "$T/tree" >"$T/out" 2>&1; then bad "circle cli <-> rng: not caught"
elif grep -q "circle between modules: common/base/cli -> common/base/rng -> common/base/cli" "$T/out"; then
  ok "circle cli <-> rng: $(grep -m1 circle "$T/out")"
else cat "$T/out"; bad "circle cli <-> rng: report lacks the circle"; fi

echo "layers: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
