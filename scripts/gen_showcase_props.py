#!/usr/bin/env python3
"""Writes the geometric props of scenes/showcase into OUT_DIR: a tiled floor as two OBJ
meshes (tiles_light.obj, tiles_dark.obj: alternating squares of TILE metres over x in
[-12, 12], z in [-6, 30], y = 0, facing +y) and a beach ball of radius 1 at the origin as
two OBJ meshes of alternating gores (ball_red.obj, ball_white.obj, smooth normals, outward
winding). Geometry rather than textures because the renderer refuses textures in a scene
with participating media (common/scene/scene.c, scene_validate). Deterministic.
Usage: gen_showcase_props.py OUT_DIR [TILE]   (default tile 0.5)"""
import math
import os
import sys


def tiles(tile):
    light, dark = [], []
    nx, nz = int(round(24 / tile)), int(round(36 / tile))
    for k in range(nz):
        for i in range(nx):
            x0, z0 = -12 + i * tile, -6 + k * tile
            quad = [(x0, z0), (x0, z0 + tile), (x0 + tile, z0 + tile), (x0 + tile, z0)]
            (light if (i + k) % 2 == 0 else dark).append(quad)
    return light, dark


def write_tiles(path, quads, what):
    with open(path, "w") as f:
        f.write("# %s floor tiles: scripts/gen_showcase_props.py\nvn 0 1 0\n" % what)
        for q in quads:
            f.write("".join("v %g 0 %g\n" % p for p in q))
        for n in range(len(quads)):
            b = 4 * n + 1
            f.write("f %d//1 %d//1 %d//1 %d//1\n" % (b, b + 1, b + 2, b + 3))


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
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    out = sys.argv[1]
    tile = float(sys.argv[2]) if len(sys.argv) == 3 else 0.5
    if not 0.05 <= tile <= 6:
        sys.exit("gen_showcase_props: tile must be in [0.05, 6] metres")
    light, dark = tiles(tile)
    write_tiles(os.path.join(out, "tiles_light.obj"), light, "light")
    write_tiles(os.path.join(out, "tiles_dark.obj"), dark, "dark")
    write_gores(os.path.join(out, "ball_red.obj"), 0, 8, 24, 6, "red")
    write_gores(os.path.join(out, "ball_white.obj"), 1, 8, 24, 6, "white")


if __name__ == "__main__":
    main()
