#!/usr/bin/env python3
"""Converts the Stanford bunny of the npm package `bunny` (1.0.1, licence "Public Domain";
its index.js holds `exports.positions=[[x,y,z],...]` and `exports.cells=[[a,b,c],...]`: the
Stanford 3D Scanning Repository's bunny, decimated to 1839 vertices and 3674 triangles, open
at the base as the scan is) into an OBJ with smooth (area-weighted) vertex normals, scaled
to HEIGHT with its lowest point at y = 0 and centred in x and z. Every index is checked
against the vertex count and every number for finiteness before use.
Usage: gen_bunny.py INDEX_JS OUT.obj [HEIGHT]   (`make showcase-bunny` fetches INDEX_JS with
npm pack and rewrites scenes/showcase/bunny.obj)"""
import json
import math
import re
import sys


def parse(text):
    arrays = {}
    for name in ("positions", "cells"):
        m = re.search(r"exports\.%s\s*=\s*(\[[-0-9.eE,\[\]\s]*\])" % name, text)
        if not m:
            sys.exit("gen_bunny: no exports.%s array in the input" % name)
        arrays[name] = json.loads(m.group(1))
    pos, cells = arrays["positions"], arrays["cells"]
    for i, p in enumerate(pos):
        if len(p) != 3 or not all(isinstance(c, (int, float)) and math.isfinite(c) for c in p):
            sys.exit("gen_bunny: position %d is not 3 finite numbers" % i)
    for i, c in enumerate(cells):
        if len(c) != 3 or not all(isinstance(k, int) and 0 <= k < len(pos) for k in c):
            sys.exit("gen_bunny: cell %d is not 3 indices below %d" % (i, len(pos)))
    return pos, cells


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    with open(sys.argv[1], encoding="ascii") as f:
        pos, cells = parse(f.read())
    height = float(sys.argv[3]) if len(sys.argv) == 4 else 1.0
    lo = [min(p[c] for p in pos) for c in range(3)]
    hi = [max(p[c] for p in pos) for c in range(3)]
    s = height / (hi[1] - lo[1])
    ctr = [(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2]
    v = [[(p[c] - ctr[c]) * s for c in range(3)] for p in pos]
    n = [[0.0, 0.0, 0.0] for _ in v]
    for a, b, c in cells:
        e1 = [v[b][k] - v[a][k] for k in range(3)]
        e2 = [v[c][k] - v[a][k] for k in range(3)]
        fn = (e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0])
        for i in (a, b, c):
            for k in range(3):
                n[i][k] += fn[k]
    with open(sys.argv[2], "w") as out:
        out.write("# Stanford bunny (Stanford 3D Scanning Repository) via npm bunny 1.0.1, "
                  "Public Domain; scripts/gen_bunny.py, height %g\n" % height)
        out.write("".join("v %.6f %.6f %.6f\n" % tuple(p) for p in v))
        for q in n:
            ln = math.sqrt(sum(c * c for c in q)) or 1.0
            out.write("vn %.5f %.5f %.5f\n" % (q[0] / ln, q[1] / ln, q[2] / ln))
        out.write("".join("f %d//%d %d//%d %d//%d\n" % (a + 1, a + 1, b + 1, b + 1, c + 1, c + 1)
                          for a, b, c in cells))
    print("gen_bunny: %s: %d vertices, %d triangles" % (sys.argv[2], len(v), len(cells)))


if __name__ == "__main__":
    main()
