#!/usr/bin/env python3
"""Writes a smoke-cloud density grid in Brume's dense grid format (common/scene/medium.h:
"BRGRID01", uint32 nx ny nz little-endian, then nx*ny*nz float32, x fastest).
The cloud is a few overlapping soft blobs rising in a plume, eroded by fractal value
noise: deterministic (its own integer hash), so the bytes are the same everywhere.
Usage: python3 scripts/make_smoke_grid.py OUT.grid [N]"""
import math
import struct
import sys


def hash3(x, y, z, seed):
    h = (x * 73856093) ^ (y * 19349663) ^ (z * 83492791) ^ (seed * 2654435761)
    h &= 0xFFFFFFFF
    h ^= h >> 16
    h = (h * 0x7FEB352D) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 0x846CA68B) & 0xFFFFFFFF
    h ^= h >> 16
    return h / 4294967296.0


def value_noise(x, y, z, seed):
    xi, yi, zi = math.floor(x), math.floor(y), math.floor(z)
    fx, fy, fz = x - xi, y - yi, z - zi
    sx, sy, sz = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy), fz * fz * (3 - 2 * fz)
    acc = 0.0
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = (sx if dx else 1 - sx) * (sy if dy else 1 - sy) * (sz if dz else 1 - sz)
                acc += w * hash3(xi + dx, yi + dy, zi + dz, seed)
    return acc


def fbm(x, y, z):
    s, a, f = 0.0, 0.5, 1.0
    for octave in range(4):
        s += a * value_noise(x * f, y * f, z * f, octave)
        a *= 0.5
        f *= 2.0
    return s


def main():
    out = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 40
    blobs = [(0.5, 0.25, 0.5, 0.22), (0.45, 0.45, 0.52, 0.2), (0.55, 0.62, 0.47, 0.18),
             (0.62, 0.78, 0.55, 0.14), (0.38, 0.35, 0.4, 0.15)]
    vals = []
    for k in range(n):
        for j in range(n):
            for i in range(n):
                x, y, z = (i + 0.5) / n, (j + 0.5) / n, (k + 0.5) / n
                d = 0.0
                for (cx, cy, cz, r) in blobs:
                    q = ((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (r * r)
                    d += math.exp(-2.0 * q)
                d *= 0.4 + 1.2 * fbm(x * 6, y * 6, z * 6)
                d = max(0.0, d - 0.15)
                vals.append(d)
    with open(out, "wb") as f:
        f.write(b"BRGRID01")
        f.write(struct.pack("<III", n, n, n))
        f.write(struct.pack("<%df" % len(vals), *vals))


if __name__ == "__main__":
    main()
