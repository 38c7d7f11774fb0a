#!/bin/sh
# Meshes end to end: one grid written by scripts/gen_mesh.py as OBJ and as PLY (binary
# little- and big-endian, ascii; triangles and quads) renders the same pixels from each;
# a damaged PLY is refused naming the scene's object, the file and the element; an OBJ
# as exporters write it (an undefined material, "./" and backslash paths) renders with
# a warning. Ends with "integration: N passed, N failed".
# Usage: BUILD=build sh tests/integration/meshes.sh
. "$(dirname "$0")/lib.sh"
lib_init meshes
D=tests/integration/meshes

scene() { # scene NAME TYPE FILE: $T/NAME.json rendering FILE (in $T) as TYPE
  sed "s|MESH_TYPE|$2|; s|MESH_FILE|$3|" $D/grid.json >"$T/$1.json"
}
python3 scripts/gen_mesh.py 12 "$T/tri" && python3 scripts/gen_mesh.py 12 "$T/quad" --quads \
  && ok "gen_mesh.py writes the grid" || bad "gen_mesh.py writes the grid"
scene obj obj tri.obj
run $M "$T/obj.json" -o "$T/obj.exr" --workers 1 && ok "OBJ grid renders" || bad "OBJ grid renders"
for f in tri.ply tri.be.ply tri.ascii.ply quad.ply quad.be.ply quad.ascii.ply; do
  scene p ply $f
  if run $M "$T/p.json" -o "$T/p.exr" --workers 2 --threads 1 && $X cmp "$T/obj.exr" "$T/p.exr" >/dev/null; then
    ok "PLY $f: the OBJ's pixels"
  else
    bad "PLY $f: the OBJ's pixels"
  fi
done

# Truncated binary PLYs: a vertex count that cannot fit is refused before anything is
# allocated; a file cut among its faces names the face and the property.
head -c 3000 "$T/tri.ply" >"$T/cut.ply"
scene cut ply cut.ply
if run $M "$T/cut.json" -o "$T/x.exr"; then bad "truncated PLY accepted"; else
  grep -q "cut.ply:4: element vertex: 169 of them cannot fit in the [0-9]* bytes left" "$T/log" \
    && ok "PLY too short for its vertices refused" || bad "PLY too short for its vertices: message"; fi
head -c 8000 "$T/tri.ply" >"$T/cut.ply"
if run $M "$T/cut.json" -o "$T/x.exr"; then bad "truncated PLY accepted"; else
  grep -q "cut.ply: element face [0-9]*, property vertex_indices: the file ends early" "$T/log" \
    && ok "PLY cut among its faces refused naming element and property" || bad "PLY cut among its faces: message"; fi

# An OBJ as exported in the wild.
mkdir -p "$T/wild/tex"
cp scenes/textured/checker.png "$T/wild/tex/c.png" 2>/dev/null || $BUILD/maketex "$T/wild/tex" >/dev/null 2>&1
[ -f "$T/wild/tex/c.png" ] || cp "$(ls "$T"/wild/tex/*.png | head -1)" "$T/wild/tex/c.png"
printf 'newmtl paint\nKd 0.5 0.5 0.5\nmap_Kd .\\tex\\c.png\n' >"$T/wild/box.mtl"
{ printf 'mtllib ./box.mtl\n'; sed -n 's/^v /v /p; s/^vt /vt /p' "$T/tri.obj"; printf 'usemtl paint\n';
  grep '^f ' "$T/tri.obj" | head -100 | sed 's|/[0-9]*/[0-9]*||g; s|$||'; printf 'usemtl Default\n';
  grep '^f ' "$T/tri.obj" | tail -n +101 | sed 's|/[0-9]*/[0-9]*||g'; } >"$T/wild/box.obj"
sed "s|MESH_TYPE|obj|; s|MESH_FILE|box.obj|; s|, \"material\": \"clay\"||" $D/grid.json >"$T/wild/wild.json"
if run $M "$T/wild/wild.json" -o "$T/w.exr" --workers 1; then
  grep -q 'box.obj:[0-9]*:8: unknown material "Default"' "$T/log" && ok "wild OBJ renders; undefined material warned with file:line" \
    || bad "wild OBJ: no warning naming the undefined material"
else
  bad "wild OBJ (./box.mtl, .\\tex\\c.png, usemtl Default) refused"
fi
finish
