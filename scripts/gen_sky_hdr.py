#!/usr/bin/env python3
"""Writes an analytic sky as a lat-long Radiance .hdr (flat RGBE scanlines), the
environment light of scenes/materials: a zenith-to-horizon gradient, a darker ground below
the horizon, and a small bright sun disc. Deterministic: the same arguments give the same
bytes. Row 0 is +y (up); column u is the azimuth phi = 2 pi u with direction
(sin(theta) cos(phi), cos(theta), sin(theta) sin(phi)), as envmap.h reads it.
Usage: python3 scripts/gen_sky_hdr.py OUT.hdr [WIDTH HEIGHT SUN_ELEVATION_DEG SUN_AZIMUTH_DEG
SUN_RADIUS_DEG SUN_RADIANCE]  (defaults 128 64 35 60 2 4000)"""
import math
import struct
import sys


def rgbe(r, g, b):
    v = max(r, g, b)
    if v < 1e-32:
        return b"\0\0\0\0"
    m, e = math.frexp(v)
    s = m * 256.0 / v
    return struct.pack("BBBB", int(r * s), int(g * s), int(b * s), e + 128)


def main():
    a = sys.argv[1:]
    if not a:
        sys.exit(__doc__)
    out = a[0]
    w, h = (int(a[1]), int(a[2])) if len(a) > 2 else (128, 64)
    el, az, rad, sun = (float(x) for x in a[3:7]) if len(a) > 6 else (35.0, 60.0, 2.0, 4000.0)
    if not (8 <= w <= 32767 and 1 <= h <= 32767):
        sys.exit("width must be in [8, 32767], height in [1, 32767]")
    sd = (math.cos(math.radians(el)) * math.cos(math.radians(az)), math.sin(math.radians(el)),
          math.cos(math.radians(el)) * math.sin(math.radians(az)))
    cos_sun = math.cos(math.radians(rad))
    rows = []
    for y in range(h):
        th = math.pi * (y + 0.5) / h
        row = []
        for x in range(w):
            ph = 2 * math.pi * (x + 0.5) / w
            d = (math.sin(th) * math.cos(ph), math.cos(th), math.sin(th) * math.sin(ph))
            if d[1] >= 0:
                t = d[1] ** 0.5  # horizon (0) to zenith (1)
                c = (0.9 - 0.6 * t, 1.0 - 0.4 * t, 1.1 - 0.1 * t)
            else:
                c = (0.25, 0.22, 0.18)
            if d[0] * sd[0] + d[1] * sd[1] + d[2] * sd[2] >= cos_sun:
                c = (sun, sun * 0.95, sun * 0.85)
            row.append(rgbe(*c))
        rows.append(b"".join(row))
    head = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (h, w)
    with open(out, "wb") as f:
        f.write(head + b"".join(rows))


if __name__ == "__main__":
    main()
