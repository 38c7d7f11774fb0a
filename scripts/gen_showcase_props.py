#!/usr/bin/env python3
"""Writes the geometric props of scenes/showcase into OUT_DIR: the floor as one quad
(floor.obj: x in [-12, 12], z in [-6, 30], y = 0, facing +y, texture coordinates in
metres, u = x and v = z, for the scene's checker texture of 0.5 m tiles, filtered with ray
differentials) and a beach ball of radius 1 at the origin as two OBJ meshes of
alternating gores (ball_red.obj, ball_white.obj, smooth normals, outward winding; geometry,
so that it spins with its keyframes' motion blur). Deterministic.
Usage: gen_showcase_props.py OUT_DIR"""
import math
import os
import sys


def write_floor(path):
    with open(path, "w") as f:
        f.write("# the floor, uv in metres: scripts/gen_showcase_props.py\nvn 0 1 0\n")
        for x, z in ((-12, -6), (-12, 30), (12, 30), (12, -6)):
            f.write("v %g 0 %g\nvt %g %g\n" % (x, z, x, z))
        f.write("f 1/1/1 2/2/1 3/3/1 4/4/1\n")


def write_gores(path, first, gores, rings, segs, what):
    """Gores first, first + 2, ... of `gores` around +y, each `segs` quads wide."""
    with open(path, "w") as f:
        f.write("# beach ball, %s gores: scripts/gen_showcase_props.py\n" % what)
        nv = 0
        faces = []
        for g in range(first, gores, 2):
            base = nv
            for r in range(rings + 1):
                th = math.pi * r / rings
                for s in range(segs + 1):
                    ph = 2 * math.pi * (g + s / segs) / gores
                    p = (math.sin(th) * math.cos(ph), math.cos(th), math.sin(th) * math.sin(ph))
                    f.write("v %.6f %.6f %.6f\nvn %.6f %.6f %.6f\n" % (p + p))
                    nv += 1
            for r in range(rings):
                for s in range(segs):
                    a = base + r * (segs + 1) + s + 1
                    b, c, d = a + 1, a + segs + 2, a + segs + 1
                    # outward: counter-clockwise seen from outside (phi grows toward +z)
                    if r == 0:
                        faces.append((a, c, d))
                    elif r == rings - 1:
                        faces.append((a, b, d))
                    else:
                        faces.append((a, b, c, d))
        for fc in faces:
            f.write("f " + " ".join("%d//%d" % (i, i) for i in fc) + "\n")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    write_floor(os.path.join(out, "floor.obj"))
    write_gores(os.path.join(out, "ball_red.obj"), 0, 8, 24, 6, "red")
    write_gores(os.path.join(out, "ball_white.obj"), 1, 8, 24, 6, "white")


if __name__ == "__main__":
    main()
