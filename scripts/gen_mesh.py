#!/usr/bin/env python3
"""Writes one grid mesh (a height field of 2 * N * N triangles over the unit square, with
normals and uvs) in the formats the renderer reads, for tests, fuzz seeds and the PLY
benchmark (docs/benchmarks.md):
    gen_mesh.py N OUT_BASE [--quads]
writes OUT_BASE.obj (v, vt, vn and f v/vt/vn), OUT_BASE.ply (binary little-endian),
OUT_BASE.be.ply (binary big-endian) and OUT_BASE.ascii.ply, the same vertices and
faces in each (triangles, or with --quads N * N quads)."""
import math
import struct
import sys


def f32(x):
    """x rounded to float, so that the OBJ's decimals and the PLY's floats are one value."""
    return struct.unpack("f", struct.pack("f", x))[0]


def grid(n):
    verts = []
    for j in range(n + 1):
        for i in range(n + 1):
            x, y = i / n, j / n
            z = 0.1 * math.sin(6.0 * x) * math.cos(5.0 * y)
            dzdx = 0.6 * math.cos(6.0 * x) * math.cos(5.0 * y)
            dzdy = -0.5 * math.sin(6.0 * x) * math.sin(5.0 * y)
            ln = math.sqrt(dzdx * dzdx + dzdy * dzdy + 1.0)
            verts.append(tuple(f32(c) for c in (x, y, z, -dzdx / ln, -dzdy / ln, 1.0 / ln, x, y)))
    return verts


def faces(n, quads):
    out = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            b, c, d = a + 1, a + n + 2, a + n + 1
            if quads:
                out.append((a, b, c, d))
            else:
                out.append((a, b, c))
                out.append((a, c, d))
    return out


def ply_header(fmt, nv, nf):
    return ("ply\nformat %s 1.0\ncomment scripts/gen_mesh.py\nelement vertex %d\n"
            "property float x\nproperty float y\nproperty float z\n"
            "property float nx\nproperty float ny\nproperty float nz\n"
            "property float u\nproperty float v\n"
            "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % (fmt, nv, nf)).encode()


def write_binary(path, verts, fs, endian):
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    vs = struct.Struct(endian + "8f")
    with open(path, "wb") as f:
        f.write(ply_header(fmt, len(verts), len(fs)))
        f.write(b"".join(vs.pack(*v) for v in verts))
        f.write(b"".join(struct.pack(endian + "B%di" % len(q), len(q), *q) for q in fs))


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    n, base = int(sys.argv[1]), sys.argv[2]
    quads = "--quads" in sys.argv[3:]
    verts, fs = grid(n), faces(n, quads)
    with open(base + ".obj", "w") as f:
        f.write("# scripts/gen_mesh.py\n")
        f.writelines("v %.9g %.9g %.9g\n" % v[:3] for v in verts)
        f.writelines("vt %.9g %.9g\n" % v[6:8] for v in verts)
        f.writelines("vn %.9g %.9g %.9g\n" % v[3:6] for v in verts)
        f.writelines("f " + " ".join("%d/%d/%d" % (k + 1, k + 1, k + 1) for k in q) + "\n" for q in fs)
    write_binary(base + ".ply", verts, fs, "<")
    write_binary(base + ".be.ply", verts, fs, ">")
    with open(base + ".ascii.ply", "wb") as f:
        f.write(ply_header("ascii", len(verts), len(fs)))
        f.write("".join("%.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g\n" % v for v in verts).encode())
        f.write("".join("%d %s\n" % (len(q), " ".join(map(str, q))) for q in fs).encode())


if __name__ == "__main__":
    main()
