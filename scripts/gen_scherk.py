#!/usr/bin/env python3
"""Writes a Scherk-Collins toroid (after Carlo Sequin's Scherk-Collins sculpture generator)
as a closed, consistently wound OBJ with smooth normals: a Scherk tower of saddles, twisted
along its axis and bent into a ring, thickened into a slab of constant thickness whose wings
are cut (with rounded edges) by a tube around the ring. scenes/showcase uses it as glass.

The surface is the zero set of F = (sinh(rho)/rho)^b Im((u + i v)^b) - sin(N phi / 2) in the
ring's frame: phi the angle around the ring (axis +y), (u, v) the point's offset from the
ring's core circle in the cross-section (radial, up), turned by the twist, times N / (2 R)
so that saddles are as wide as they are far apart. b = 2 is Scherk's second surface (four
wings per saddle), b = 3 a ring of monkey saddles. The solid is
max(|F| / |grad F| - thickness / 2, rho - tube), a smooth max, polygonised by marching
tetrahedra on a Freudenthal (Kuhn) split of a cubic grid, which is conforming, so the mesh
is closed by construction; the script still checks, and exits with an error, unless every
edge is shared by exactly two triangles that traverse it in opposite directions and the
signed volume is positive (outward normals). Python 3, standard library only.

Usage: gen_scherk.py OUT.obj [--saddles N] [--branches B] [--twist TURNS] [--radius R]
       [--tube T] [--thickness W] [--cell H]
(defaults, those of scenes/showcase: 8 saddles, 2 branches, 0.5 turns, radius 1, tube
0.42, thickness 0.11, cell 0.028: 212468 triangles, genus 9, about a minute). The ring closes only when 2 B TURNS is an integer of
the same parity as N; other combinations are refused."""
import argparse
import math
import sys


def field_fn(a):
    k = a.saddles / (2.0 * a.radius)
    b = a.branches
    twist = 2.0 * math.pi * a.twist

    def f(x, y, z):
        phi = math.atan2(z, x)
        u = math.hypot(x, z) - a.radius
        v = y
        rho_w = math.hypot(u, v)
        # The twist turns the cross-section by twist * phi / (2 pi) along the ring.
        c, s = math.cos(-twist * phi / (2 * math.pi)), math.sin(-twist * phi / (2 * math.pi))
        uu, vv = k * (c * u - s * v), k * (s * u + c * v)
        r = k * rho_w
        g = math.sinh(r) / r if r > 1e-9 else 1.0
        im = complex(uu, vv) ** b
        return (g ** b) * im.imag - math.sin(a.saddles * phi / 2.0), rho_w

    return f


def smax(p, q, w):
    h = max(w - abs(p - q), 0.0) / w
    return max(p, q) + h * h * w * 0.25


def build(a):
    h = a.cell
    ext_xz = a.radius + a.tube + 3 * h
    ext_y = a.tube + 3 * h
    nx = int(math.ceil(2 * ext_xz / h)) + 1
    ny = int(math.ceil(2 * ext_y / h)) + 1
    nz = nx
    x0, y0, z0 = -ext_xz, -ext_y, -ext_xz
    f = field_fn(a)
    n = nx * ny * nz
    F = [0.0] * n
    RHO = [0.0] * n
    for k in range(nz):
        z = z0 + k * h
        for j in range(ny):
            y = y0 + j * h
            base = (k * ny + j) * nx
            for i in range(nx):
                F[base + i], RHO[base + i] = f(x0 + i * h, y, z)
    sx, sy, sz = 1, nx, nx * ny
    half_t = 0.5 * a.thickness
    soft = 0.5 * a.thickness
    D = [1.0] * n
    tiny = 1e-7 * h
    for k in range(1, nz - 1):
        for j in range(1, ny - 1):
            base = (k * ny + j) * nx
            for i in range(1, nx - 1):
                idx = base + i
                cyl = RHO[idx] - a.tube
                if cyl > 2 * h:
                    D[idx] = cyl
                    continue
                gx = F[idx + sx] - F[idx - sx]
                gy = F[idx + sy] - F[idx - sy]
                gz = F[idx + sz] - F[idx - sz]
                gl = math.sqrt(gx * gx + gy * gy + gz * gz) / (2 * h)
                slab = abs(F[idx]) / gl - half_t if gl > 1e-12 else 1.0
                d = smax(slab, cyl, soft)
                if abs(d) < tiny:
                    d = tiny if d >= 0 else -tiny
                D[idx] = d
    return D, (nx, ny, nz), (x0, y0, z0)


# Freudenthal split of the unit cube: one tetrahedron per axis order, 000 -> 111.
def cube_tets():
    tets = []
    for order in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        c = [0, 0, 0]
        t = [tuple(c)]
        for ax in order:
            c[ax] = 1
            t.append(tuple(c))
        tets.append(t)
    return tets


def polygonise(D, dims, origin, h):
    nx, ny, nz = dims
    x0, y0, z0 = origin
    sx, sy, sz = 1, nx, nx * ny
    tets = cube_tets()
    offs = [(dx * sx + dy * sy + dz * sz) for dx in (0, 1) for dy in (0, 1) for dz in (0, 1)]
    corner_of = {(dx, dy, dz): (dx * sx + dy * sy + dz * sz)
                 for dx in (0, 1) for dy in (0, 1) for dz in (0, 1)}
    tet_offs = [[corner_of[c] for c in t] for t in tets]
    verts, normals, tris = [], [], []
    vid = {}

    def pos(idx):
        i = idx % nx
        j = (idx // nx) % ny
        k = idx // (nx * ny)
        return (x0 + i * h, y0 + j * h, z0 + k * h)

    def grad(idx):
        return (D[idx + sx] - D[idx - sx], D[idx + sy] - D[idx - sy], D[idx + sz] - D[idx - sz])

    def edge_vertex(p, q):
        key = (p, q) if p < q else (q, p)
        v = vid.get(key)
        if v is not None:
            return v
        dp, dq = D[p], D[q]
        t = dp / (dp - dq)
        a, b = pos(p), pos(q)
        ga, gb = grad(p), grad(q)
        verts.append(tuple(a[c] + t * (b[c] - a[c]) for c in range(3)))
        g = [ga[c] + t * (gb[c] - ga[c]) for c in range(3)]
        gl = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) or 1.0
        normals.append((g[0] / gl, g[1] / gl, g[2] / gl))
        v = len(verts) - 1
        vid[key] = v
        return v

    def emit(tri, inside_c, outside_c):
        va, vb, vc = (verts[t] for t in tri)
        e1 = [vb[c] - va[c] for c in range(3)]
        e2 = [vc[c] - va[c] for c in range(3)]
        nrm = (e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
               e1[0] * e2[1] - e1[1] * e2[0])
        out = [outside_c[c] - inside_c[c] for c in range(3)]
        if nrm[0] * out[0] + nrm[1] * out[1] + nrm[2] * out[2] < 0:
            tri = (tri[0], tri[2], tri[1])
        tris.append(tri)

    for k in range(1, nz - 2):
        for j in range(1, ny - 2):
            base = (k * ny + j) * nx
            for i in range(1, nx - 2):
                c0 = base + i
                neg = 0
                for o in offs:
                    if D[c0 + o] < 0:
                        neg += 1
                if neg == 0 or neg == 8:
                    continue
                for to in tet_offs:
                    idx = [c0 + o for o in to]
                    ins = [p for p in idx if D[p] < 0]
                    if not ins or len(ins) == 4:
                        continue
                    outs = [p for p in idx if D[p] >= 0]
                    pi = [pos(p) for p in ins]
                    po = [pos(p) for p in outs]
                    ci = tuple(sum(p[c] for p in pi) / len(pi) for c in range(3))
                    co = tuple(sum(p[c] for p in po) / len(po) for c in range(3))
                    if len(ins) == 1 or len(outs) == 1:
                        lone, rest = (ins[0], outs) if len(ins) == 1 else (outs[0], ins)
                        emit(tuple(edge_vertex(lone, r) for r in rest), ci, co)
                    else:
                        a, b = ins
                        c, d = outs
                        ac, ad = edge_vertex(a, c), edge_vertex(a, d)
                        bd, bc = edge_vertex(b, d), edge_vertex(b, c)
                        emit((ac, ad, bd), ci, co)
                        emit((ac, bd, bc), ci, co)
    return verts, normals, tris


def check(verts, tris):
    """Exits unless the mesh is closed, consistently wound and outward facing."""
    directed = {}
    for t in tris:
        if len(set(t)) != 3:
            sys.exit("gen_scherk: degenerate triangle %s" % (t,))
        for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            if e in directed:
                sys.exit("gen_scherk: edge %s traversed twice in the same direction: "
                         "not consistently wound (or not manifold)" % (e,))
            directed[e] = True
    for (p, q) in directed:
        if (q, p) not in directed:
            sys.exit("gen_scherk: edge (%d, %d) belongs to one triangle only: not watertight"
                     % (p, q))
    vol = 0.0
    for t in tris:
        a, b, c = (verts[i] for i in t)
        vol += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
    vol /= 6.0
    if not vol > 0:
        sys.exit("gen_scherk: signed volume %g is not positive: normals point inwards" % vol)
    return len(directed) // 2, vol


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--saddles", type=int, default=8, help="saddles around the ring (>= 1)")
    p.add_argument("--branches", type=int, default=2,
                   help="saddle order: 2 = Scherk's saddles (4 wings), 3 = monkey saddles")
    p.add_argument("--twist", type=float, default=0.5, help="turns of the cross-section per revolution")
    p.add_argument("--radius", type=float, default=1.0, help="radius of the ring's core circle")
    p.add_argument("--tube", type=float, default=0.42, help="radius at which the wings are cut")
    p.add_argument("--thickness", type=float, default=0.11, help="thickness of the slab")
    p.add_argument("--cell", type=float, default=0.028, help="grid cell of the polygoniser")
    a = p.parse_args()
    if a.saddles < 1 or a.branches < 1 or a.branches > 8:
        sys.exit("gen_scherk: --saddles must be >= 1 and --branches in [1, 8]")
    if not (0 < a.tube < a.radius and 0 < a.thickness < a.tube and 0 < a.cell < a.thickness):
        sys.exit("gen_scherk: need 0 < tube < radius, 0 < thickness < tube, 0 < cell < thickness")
    m = 2 * a.branches * a.twist
    if abs(m - round(m)) > 1e-9 or (int(round(m)) - a.saddles) % 2 != 0:
        sys.exit("gen_scherk: the ring does not close: 2 * branches * twist (%g) must be an "
                 "integer of the same parity as saddles (%d)" % (m, a.saddles))
    D, dims, origin = build(a)
    verts, normals, tris = polygonise(D, dims, origin, a.cell)
    if not tris:
        sys.exit("gen_scherk: empty mesh (cell too coarse for the thickness?)")
    edges, vol = check(verts, tris)
    chi = len(verts) - edges + len(tris)
    with open(a.out, "w") as out:
        out.write("# Scherk-Collins toroid: gen_scherk.py --saddles %d --branches %d --twist %g "
                  "--radius %g --tube %g --thickness %g --cell %g\n"
                  % (a.saddles, a.branches, a.twist, a.radius, a.tube, a.thickness, a.cell))
        out.write("# %d vertices, %d triangles, closed and outward wound, volume %.6f, "
                  "Euler characteristic %d\n" % (len(verts), len(tris), vol, chi))
        out.write("".join("v %.6f %.6f %.6f\n" % v for v in verts))
        out.write("".join("vn %.5f %.5f %.5f\n" % v for v in normals))
        out.write("".join("f %d//%d %d//%d %d//%d\n" % (t[0] + 1, t[0] + 1, t[1] + 1, t[1] + 1,
                                                          t[2] + 1, t[2] + 1) for t in tris))
    print("gen_scherk: %s: %d vertices, %d triangles, watertight, consistently wound, "
          "volume %.4f, genus %d" % (a.out, len(verts), len(tris), vol, (2 - chi) // 2))


if __name__ == "__main__":
    main()
