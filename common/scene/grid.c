/* Density grids and tracking through them (see grid.h). Lookups and tracking are pure
 * functions of (grid, ray, key): no state, so any thread may call them. The shadow cache
 * is filled once by tr_cache_init (threads over z slices, same values for any count). */
#include "scene/grid.h"
#include "base/bytes.h"
#include "base/cdf.h"
#include "base/log.h"
#include "scene/motion.h"
#include "base/rng.h"
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

/* Trilinear weights and the scale round: majorants are inflated by 2^-16, many times that. */
#define MAJ_INFLATE (1.0f + 0x1p-16f)

int grid_parse(const uint8_t *data, size_t size, struct density_grid *out, char *err, size_t errlen)
{
    memset(out, 0, sizeof *out);
    if (size < 20 || memcmp(data, GRID_MAGIC, 8) != 0) {
        str_fmt(err, errlen, "not a density grid (expected the \"%s\" header)", GRID_MAGIC);
        return -1;
    }
    uint32_t nx = bytes_get_u32(data + 8), ny = bytes_get_u32(data + 12), nz = bytes_get_u32(data + 16);
    /* In two steps, each of at most 64 bits: nx * ny * nz in one could wrap around to a
     * small count (2^22 x 2^22 x 2^20 is 0 modulo 2^64). */
    if (nx < 1 || ny < 1 || nz < 1 || (uint64_t)nx * ny > GRID_MAX_VOXELS ||
        (uint64_t)nx * ny * nz > GRID_MAX_VOXELS) {
        str_fmt(err, errlen, "grid size %ux%ux%u out of range (1.. and at most %u voxels)", nx, ny, nz, GRID_MAX_VOXELS);
        return -1;
    }
    uint64_t n = (uint64_t)nx * ny * nz;
    if (size != 20 + 4 * n) {
        str_fmt(err, errlen, "grid of %ux%ux%u needs %llu bytes, the file has %zu", nx, ny, nz,
                (unsigned long long)(20 + 4 * n), size);
        return -1;
    }
    float *v = mem_alloc(sizeof(float) * n);
    for (uint64_t i = 0; i < n; i++) {
        uint32_t u = bytes_get_u32(data + 20 + 4 * i);
        memcpy(&v[i], &u, 4);
        if (!isfinite(v[i]) || v[i] < 0.0f) {
            free(v);
            str_fmt(err, errlen, "voxel %llu: density must be finite and >= 0", (unsigned long long)i);
            return -1;
        }
    }
    out->nx = nx, out->ny = ny, out->nz = nz;
    out->data = v;
    out->scale = 1.0f;
    out->grid_to_world = out->world_to_grid = xform_identity();
    return 0;
}

/* Majorant cells sit on the lattice of voxel centres (u = q n - 0.5): cell c of an axis
 * covers u in [(c - 1) B, c B) and every lookup there reads only voxels (c - 1) B .. c B
 * (clipped to the grid: lookups clamp to its edge), so their maximum bounds it exactly. */
static void maj_window(uint32_t c, uint32_t n, uint32_t *lo, uint32_t *hi)
{
    int64_t a = ((int64_t)c - 1) * GRID_MAJ_BLOCK, b = (int64_t)c * GRID_MAJ_BLOCK;
    *lo = a < 0 ? 0u : (a > (int64_t)n - 1 ? n - 1 : (uint32_t)a);
    *hi = b > (int64_t)n - 1 ? n - 1 : (uint32_t)b;
}

/* The majorant cells (grid.h): maxima over each cell's window, axis by axis. They live in
 * data's allocation, after the voxels, so whoever frees data frees them. */
static void grid_build_majorants(struct density_grid *g)
{
    uint32_t n[3] = {g->nx, g->ny, g->nz}, m[3];
    for (int k = 0; k < 3; k++)
        m[k] = (n[k] + GRID_MAJ_BLOCK - 1) / GRID_MAJ_BLOCK + 1;
    size_t nv = (size_t)n[0] * n[1] * n[2], nc = (size_t)m[0] * m[1] * m[2];
    g->data = mem_realloc(g->data, sizeof(float) * (nv + nc));
    g->majorant = g->data + nv;
    memcpy(g->maj_n, m, sizeof m);
    float *a = mem_alloc(sizeof(float) * m[0] * n[1] * n[2]), *b = mem_alloc(sizeof(float) * m[0] * m[1] * n[2]);
    uint32_t lo, hi;
    for (uint32_t z = 0; z < n[2]; z++)
        for (uint32_t y = 0; y < n[1]; y++)
            for (uint32_t cx = 0; cx < m[0]; cx++) {
                const float *row = g->data + ((size_t)z * n[1] + y) * n[0];
                float mx = 0.0f;
                maj_window(cx, n[0], &lo, &hi);
                for (uint32_t x = lo; x <= hi; x++)
                    mx = fmaxf(mx, row[x]);
                a[((size_t)z * n[1] + y) * m[0] + cx] = mx;
            }
    for (uint32_t z = 0; z < n[2]; z++)
        for (uint32_t cy = 0; cy < m[1]; cy++)
            for (uint32_t cx = 0; cx < m[0]; cx++) {
                float mx = 0.0f;
                maj_window(cy, n[1], &lo, &hi);
                for (uint32_t y = lo; y <= hi; y++)
                    mx = fmaxf(mx, a[((size_t)z * n[1] + y) * m[0] + cx]);
                b[((size_t)z * m[1] + cy) * m[0] + cx] = mx;
            }
    for (uint32_t cz = 0; cz < m[2]; cz++)
        for (uint32_t cy = 0; cy < m[1]; cy++)
            for (uint32_t cx = 0; cx < m[0]; cx++) {
                float mx = 0.0f;
                maj_window(cz, n[2], &lo, &hi);
                for (uint32_t z = lo; z <= hi; z++)
                    mx = fmaxf(mx, b[((size_t)z * m[1] + cy) * m[0] + cx]);
                g->majorant[((size_t)cz * m[1] + cy) * m[0] + cx] = mx * g->scale * MAJ_INFLATE;
            }
    free(a);
    free(b);
}

void grid_finish(struct density_grid *g, const struct xform *grid_to_world, float scale)
{
    g->scale = scale;
    g->grid_to_world = *grid_to_world;
    g->world_to_grid = motion_xform_inverse(grid_to_world);
    uint32_t lo[3] = {UINT32_MAX, UINT32_MAX, UINT32_MAX}, hi[3] = {0, 0, 0};
    float mx = 0.0f;
    for (uint32_t z = 0; z < g->nz; z++)
        for (uint32_t y = 0; y < g->ny; y++)
            for (uint32_t x = 0; x < g->nx; x++) {
                float v = g->data[((size_t)z * g->ny + y) * g->nx + x];
                if (!(v > 0.0f))
                    continue;
                mx = fmaxf(mx, v);
                uint32_t c[3] = {x, y, z};
                for (int k = 0; k < 3; k++) {
                    lo[k] = c[k] < lo[k] ? c[k] : lo[k];
                    hi[k] = c[k] > hi[k] ? c[k] : hi[k];
                }
            }
    g->max_density = mx * scale;
    uint32_t n[3] = {g->nx, g->ny, g->nz};
    float ol[3], oh[3];
    for (int k = 0; k < 3; k++) {
        if (lo[k] == UINT32_MAX) {
            ol[k] = 1.0f, oh[k] = 0.0f; /* empty */
            continue;
        }
        /* Trilinear support of voxels lo..hi reaches the neighbouring centres. */
        ol[k] = fmaxf(0.0f, ((float)lo[k] - 0.5f) / (float)n[k]);
        oh[k] = fminf(1.0f, ((float)hi[k] + 1.5f) / (float)n[k]);
    }
    g->occ_lo = v3(ol[0], ol[1], ol[2]);
    g->occ_hi = v3(oh[0], oh[1], oh[2]);
    float vw = INFINITY;
    for (int k = 0; k < 3; k++) {
        vec3 col = v3(grid_to_world->m[0][k], grid_to_world->m[1][k], grid_to_world->m[2][k]);
        vw = fminf(vw, v3_length(col) / (float)n[k]);
    }
    g->voxel_world = vw;
    grid_build_majorants(g);
}

/* The trilinear value at grid-space q (in [0, 1]^3; voxel centres at (i + 0.5) / n),
 * without the scale. */
static inline float grid_trilinear(const struct density_grid *g, vec3 q)
{
    float u[3] = {q.x * (float)g->nx - 0.5f, q.y * (float)g->ny - 0.5f, q.z * (float)g->nz - 0.5f};
    int32_t n[3] = {(int32_t)g->nx, (int32_t)g->ny, (int32_t)g->nz}, i0[3], i1[3];
    float f[3];
    for (int k = 0; k < 3; k++) {
        float fl = floorf(u[k]);
        f[k] = u[k] - fl;
        int32_t a = (int32_t)fl;
        i0[k] = a < 0 ? 0 : (a >= n[k] ? n[k] - 1 : a);
        i1[k] = a + 1 < 0 ? 0 : (a + 1 >= n[k] ? n[k] - 1 : a + 1);
    }
#define V(x, y, z) g->data[((size_t)(z) * g->ny + (y)) * g->nx + (x)]
    float c00 = V(i0[0], i0[1], i0[2]) * (1 - f[0]) + V(i1[0], i0[1], i0[2]) * f[0];
    float c10 = V(i0[0], i1[1], i0[2]) * (1 - f[0]) + V(i1[0], i1[1], i0[2]) * f[0];
    float c01 = V(i0[0], i0[1], i1[2]) * (1 - f[0]) + V(i1[0], i0[1], i1[2]) * f[0];
    float c11 = V(i0[0], i1[1], i1[2]) * (1 - f[0]) + V(i1[0], i1[1], i1[2]) * f[0];
#undef V
    float c0 = c00 * (1 - f[1]) + c10 * f[1], c1 = c01 * (1 - f[1]) + c11 * f[1];
    return c0 * (1 - f[2]) + c1 * f[2];
}

static inline int grid_unit_box(vec3 q)
{
    return q.x >= 0.0f && q.y >= 0.0f && q.z >= 0.0f && q.x <= 1.0f && q.y <= 1.0f && q.z <= 1.0f;
}

float grid_density(const struct density_grid *g, vec3 p)
{
    vec3 q = xform_point(&g->world_to_grid, p);
    if (!grid_unit_box(q))
        return 0.0f;
    return grid_trilinear(g, q) * g->scale;
}

/* medium_clip on the ray already in grid space (og, dg). */
static int grid_clip(const struct density_grid *g, vec3 og, vec3 dg, float tmax, float *t0, float *t1)
{
    float a = 0.0f, b = tmax;
    if (!v3_clip_box(og, dg, g->occ_lo, g->occ_hi, &a, &b) || !(a < b))
        return 0;
    *t0 = a;
    *t1 = b;
    return 1;
}

int medium_clip(const struct medium *m, vec3 o, vec3 d, float tmax, float *t0, float *t1)
{
    *t0 = 0.0f;
    *t1 = tmax;
    if (!m->grid)
        return tmax > 0.0f;
    const struct density_grid *g = m->grid;
    return grid_clip(g, xform_point(&g->world_to_grid, o), xform_vector(&g->world_to_grid, d), tmax, t0, t1);
}

float medium_march_step(const struct medium *m, float step)
{
    return m->grid ? fminf(step, 0.5f * m->grid->voxel_world) : step;
}

/* ---- local majorants along a ray ---- */

/* A 3D DDA over a lattice of cells of edge h (voxel-centre units) whose cell i of an axis
 * covers u in [(i - 1) h, i h): coarse majorant cells (h = B) and trilinear patches (h = 1,
 * patch i between the voxel centres i - 1 and i). */
struct dda {
    int32_t i[3], step[3], n[3];
    double tnext[3], tdelta[3], t, tend;
    uint32_t guard;
};

static int dda_init(struct dda *w, const double u0[3], const double du[3], double h, const uint32_t n[3], double t0,
                    double t1)
{
    w->t = t0;
    w->tend = t1;
    w->guard = n[0] + n[1] + n[2] + 4;
    for (int k = 0; k < 3; k++) {
        double p = (u0[k] + t0 * du[k]) / h + 1.0, dk = du[k] / h, fl = floor(p);
        if (!isfinite(p) || !isfinite(dk))
            return 0;
        w->n[k] = (int32_t)n[k];
        w->i[k] = fl < 0.0 ? 0 : (fl >= (double)n[k] ? (int32_t)n[k] - 1 : (int32_t)fl);
        w->step[k] = dk > 0.0 ? 1 : (dk < 0.0 ? -1 : 0);
        w->tdelta[k] = dk != 0.0 ? fabs(1.0 / dk) : INFINITY;
        w->tnext[k] = dk > 0.0 ? t0 + ((double)w->i[k] + 1.0 - p) / dk
                               : (dk < 0.0 ? t0 + ((double)w->i[k] - p) / dk : INFINITY);
    }
    return t0 < t1;
}

/* The next cell: its index and [*a, *b) of the ray. 0 at the end. */
static int dda_next(struct dda *w, double *a, double *b, int32_t idx[3])
{
    if (!(w->t < w->tend) || w->guard-- == 0)
        return 0;
    int k = w->tnext[0] < w->tnext[1] ? (w->tnext[0] < w->tnext[2] ? 0 : 2) : (w->tnext[1] < w->tnext[2] ? 1 : 2);
    *a = w->t;
    *b = d_max(w->t, d_min(w->tnext[k], w->tend));
    memcpy(idx, w->i, sizeof w->i);
    w->t = *b;
    if (w->tnext[k] < w->tend) {
        w->i[k] += w->step[k];
        w->tnext[k] += w->tdelta[k];
        if (w->i[k] < 0 || w->i[k] >= w->n[k])
            w->t = w->tend; /* left the grid */
    }
    return 1;
}

/* ---- directions toward the density ---- */

int grid_aim_init(struct grid_aim *a, const struct density_grid *g)
{
    memset(a, 0, sizeof *a);
    a->g = g;
    if (!(g->occ_lo.x < g->occ_hi.x && g->occ_lo.y < g->occ_hi.y && g->occ_lo.z < g->occ_hi.z))
        return 0;
    const uint32_t nv[3] = {g->nx, g->ny, g->nz};
    const float lo[3] = {g->occ_lo.x, g->occ_lo.y, g->occ_lo.z}, hi[3] = {g->occ_hi.x, g->occ_hi.y, g->occ_hi.z};
    for (int k = 0; k < 3; k++) {
        double cells = ceil((double)(hi[k] - lo[k]) * nv[k] / GRID_MAJ_BLOCK);
        a->n[k] = cells < 1.0 ? 1u : (cells > GRID_AIM_MAX_N ? GRID_AIM_MAX_N : (uint32_t)cells);
    }
    size_t nc = (size_t)a->n[0] * a->n[1] * a->n[2];
    double *w = mem_calloc(nc, sizeof *w);
    a->cdf = mem_alloc((nc + 1) * sizeof *a->cdf);
    const size_t nvox = (size_t)g->nx * g->ny * g->nz;
    for (size_t i = 0; i < nvox; i++) { /* each voxel's value to the cell holding its centre */
        if (!(g->data[i] > 0.0f))
            continue;
        const size_t c[3] = {i % g->nx, i / g->nx % g->ny, i / g->nx / g->ny};
        uint32_t ci[3];
        for (int k = 0; k < 3; k++) {
            double f = (((double)c[k] + 0.5) / nv[k] - lo[k]) / (hi[k] - lo[k]) * a->n[k];
            ci[k] = f < 0.0 ? 0u : (f >= a->n[k] ? a->n[k] - 1 : (uint32_t)f);
        }
        w[((size_t)ci[2] * a->n[1] + ci[1]) * a->n[0] + ci[0]] += g->data[i];
    }
    double total = 0.0;
    for (size_t i = 0; i < nc; i++)
        total += w[i];
    double run = 0.0;
    a->cdf[0] = 0.0f;
    for (size_t i = 0; i < nc; i++) {
        run += w[i];
        a->cdf[i + 1] = (float)(run / total);
    }
    free(w);
    if (!(total > 0.0)) {
        grid_aim_fini(a);
        return 0;
    }
    a->cdf[nc] = 1.0f;
    a->lo = g->occ_lo, a->hi = g->occ_hi;
    a->cell_volume = fabs(motion_xform_det(&g->grid_to_world));
    for (int k = 0; k < 3; k++)
        a->cell_volume *= (double)(hi[k] - lo[k]) / a->n[k];
    if (!(a->cell_volume > 0.0) || !isfinite(a->cell_volume)) {
        grid_aim_fini(a);
        return 0;
    }
    return 1;
}

void grid_aim_fini(struct grid_aim *a)
{
    free(a->cdf);
    a->cdf = NULL;
}

vec3 grid_aim_sample(const struct grid_aim *a, vec3 p, float u0, float u1, float u2, float u3)
{
    size_t lo = cdf_cell(a->cdf, a->n[0] * a->n[1] * a->n[2], u0);
    uint32_t c[3] = {(uint32_t)(lo % a->n[0]), (uint32_t)(lo / a->n[0] % a->n[1]), (uint32_t)(lo / a->n[0] / a->n[1])};
    const float u[3] = {u1, u2, u3}, bl[3] = {a->lo.x, a->lo.y, a->lo.z}, bh[3] = {a->hi.x, a->hi.y, a->hi.z};
    float q[3];
    for (int k = 0; k < 3; k++)
        q[k] = bl[k] + ((float)c[k] + u[k]) / (float)a->n[k] * (bh[k] - bl[k]);
    vec3 to = v3_sub(xform_point(&a->g->grid_to_world, v3(q[0], q[1], q[2])), p);
    float len = v3_length(to);
    return len > 0.0f && isfinite(len) ? v3_scale(to, 1.0f / len) : v3(0, 0, 0);
}

float grid_aim_pdf(const struct grid_aim *a, vec3 p, vec3 w)
{
    if (!(v3_dot(w, w) > 0.5f)) /* not a unit direction (grid_aim_sample's zero vector) */
        return 0.0f;
    vec3 og = xform_point(&a->g->world_to_grid, p), dg = xform_vector(&a->g->world_to_grid, w);
    float t0 = 0.0f, t1 = INFINITY;
    if (!v3_clip_box(og, dg, a->lo, a->hi, &t0, &t1) || !(t0 < t1))
        return 0.0f;
    const float o3[3] = {og.x, og.y, og.z}, d3[3] = {dg.x, dg.y, dg.z};
    const float bl[3] = {a->lo.x, a->lo.y, a->lo.z}, bh[3] = {a->hi.x, a->hi.y, a->hi.z};
    double u0[3], du[3];
    for (int k = 0; k < 3; k++) { /* lattice coordinates minus 1: the DDA's cell i covers [i - 1, i) */
        double s = a->n[k] / ((double)bh[k] - bl[k]);
        u0[k] = ((double)o3[k] - bl[k]) * s - 1.0;
        du[k] = (double)d3[k] * s;
    }
    struct dda walk;
    if (!dda_init(&walk, u0, du, 1.0, a->n, t0, t1))
        return 0.0f;
    double acc = 0.0, ta, tb;
    int32_t idx[3];
    while (dda_next(&walk, &ta, &tb, idx)) {
        size_t c = ((size_t)idx[2] * a->n[1] + (size_t)idx[1]) * a->n[0] + (size_t)idx[0];
        acc += (double)(a->cdf[c + 1] - a->cdf[c]) * (tb * tb * tb - ta * ta * ta) / 3.0;
    }
    return (float)(acc / a->cell_volume);
}

/* Pieces [a, b) of a ray, each with a majorant density. Coarse cells whose majorant
 * optical depth sigma_t,max maj (b - a) is at most MAJ_REFINE are pieces as they are;
 * denser ones are walked patch by patch (the max of the patch's 8 voxels), and a patch
 * still above MAJ_REFINE is bisected, each half bounded by the largest value of the
 * trilinear function at the corners of its box (a multilinear function's maximum over a
 * box is at a corner). So tracking takes about MAJ_REFINE tentative collisions per piece
 * however uneven the density, and a piece's bound holds exactly: lookups are clamped into
 * the piece's cell or patch, against rounding. */
#define MAJ_REFINE 4.0
#define MAJ_DEPTH 30
struct pieces {
    const struct density_grid *g;
    double u0[3], du[3];    /* u(t) = u0 + t du, voxel-centre coordinates */
    double st_max;
    struct dda coarse, fine;
    int fine_on;
    uint32_t nfine[3];
    /* the current piece */
    int patch;              /* 1: density from V over patch p; 0: lookups clamped to [clo, chi] */
    int32_t p[3];
    float V[8];             /* patch corners, scale applied, x fastest */
    double clo[3], chi[3];
    /* bisection stack of the current patch */
    double sa[MAJ_DEPTH + 2], sb[MAJ_DEPTH + 2];
    int sd[MAJ_DEPTH + 2], sp;
};

/* clip: medium_clip's answer for (o, d, tmax) when the caller has it (photon_trace's
 * split_count clips the same ray), else NULL. */
static int pieces_init(struct pieces *pc, const struct medium *m, vec3 o, vec3 d, float tmax,
                       const struct medium_clip_memo *clip)
{
    const struct density_grid *g = m->grid;
    pc->st_max = v3_max_component(m->sigma_t);
    vec3 og = xform_point(&g->world_to_grid, o), dg = xform_vector(&g->world_to_grid, d);
    float c0, c1;
    if (!(clip ? clip->hit : grid_clip(g, og, dg, tmax, &c0, &c1)) || !(pc->st_max > 0.0))
        return 0;
    if (clip)
        c0 = clip->t0, c1 = clip->t1;
    float oo[3] = {og.x, og.y, og.z}, dd[3] = {dg.x, dg.y, dg.z};
    uint32_t n[3] = {g->nx, g->ny, g->nz};
    for (int k = 0; k < 3; k++) {
        pc->u0[k] = (double)oo[k] * n[k] - 0.5;
        pc->du[k] = (double)dd[k] * n[k];
        pc->nfine[k] = n[k] + 1;
    }
    pc->g = g;
    pc->fine_on = 0;
    pc->sp = 0;
    return dda_init(&pc->coarse, pc->u0, pc->du, GRID_MAJ_BLOCK, g->maj_n, c0, c1);
}

static float lerpf(float a, float b, float f) { return a * (1.0f - f) + b * f; }

static float trilerp(const float V[8], float fx, float fy, float fz)
{
    float c0 = lerpf(lerpf(V[0], V[1], fx), lerpf(V[2], V[3], fx), fy);
    float c1 = lerpf(lerpf(V[4], V[5], fx), lerpf(V[6], V[7], fx), fy);
    return lerpf(c0, c1, fz);
}

/* Largest value of the patch's trilinear function over the box of the ray over [a, b]. */
static float patch_bound(const struct pieces *pc, double a, double b)
{
    float lo[3], hi[3];
    for (int k = 0; k < 3; k++) {
        double fa = pc->u0[k] + a * pc->du[k] - (pc->p[k] - 1), fb = pc->u0[k] + b * pc->du[k] - (pc->p[k] - 1);
        lo[k] = (float)d_min(1.0, d_max(0.0, d_min(fa, fb)));
        hi[k] = (float)d_min(1.0, d_max(0.0, d_max(fa, fb)));
    }
    float mx = 0.0f;
    for (int c = 0; c < 8; c++)
        mx = f_max(mx, trilerp(pc->V, c & 1 ? hi[0] : lo[0], c & 2 ? hi[1] : lo[1], c & 4 ? hi[2] : lo[2]));
    return mx * MAJ_INFLATE;
}

/* The next piece [*a, *b) with its majorant density *maj (> 0; cells bounded by 0 are
 * skipped). 0 at the end of the ray. */
static int pieces_next(struct pieces *pc, double *a, double *b, float *maj)
{
    const struct density_grid *g = pc->g;
    int32_t idx[3];
    for (;;) {
        if (pc->sp > 0) {
            pc->sp--;
            double pa = pc->sa[pc->sp], pb = pc->sb[pc->sp];
            int depth = pc->sd[pc->sp];
            float mj = patch_bound(pc, pa, pb);
            if (!(mj > 0.0f))
                continue;
            if (pc->st_max * mj * (pb - pa) > MAJ_REFINE && depth < MAJ_DEPTH) {
                double mid = 0.5 * (pa + pb);
                pc->sa[pc->sp] = mid, pc->sb[pc->sp] = pb, pc->sd[pc->sp++] = depth + 1;
                pc->sa[pc->sp] = pa, pc->sb[pc->sp] = mid, pc->sd[pc->sp++] = depth + 1;
                continue;
            }
            *a = pa, *b = pb, *maj = mj;
            pc->patch = 1;
            return 1;
        }
        if (pc->fine_on) {
            if (!dda_next(&pc->fine, a, b, idx)) {
                pc->fine_on = 0;
                continue;
            }
            /* Patch idx: between the voxel centres idx - 1 and idx (clamped to the grid). */
            uint32_t v0[3], v1[3], n[3] = {g->nx, g->ny, g->nz};
            for (int k = 0; k < 3; k++) {
                pc->p[k] = idx[k];
                v0[k] = idx[k] - 1 < 0 ? 0u : (uint32_t)(idx[k] - 1);
                v1[k] = (uint32_t)idx[k] > n[k] - 1 ? n[k] - 1 : (uint32_t)idx[k];
            }
            float mx = 0.0f;
            for (int c = 0; c < 8; c++) {
                uint32_t x = c & 1 ? v1[0] : v0[0], y = c & 2 ? v1[1] : v0[1], z = c & 4 ? v1[2] : v0[2];
                pc->V[c] = g->data[((size_t)z * g->ny + y) * g->nx + x] * g->scale;
                mx = f_max(mx, pc->V[c]);
            }
            if (!(mx > 0.0f))
                continue;
            pc->sa[0] = *a, pc->sb[0] = *b, pc->sd[0] = 0, pc->sp = 1;
            continue;
        }
        if (!dda_next(&pc->coarse, a, b, idx))
            return 0;
        float mj = g->majorant[((size_t)idx[2] * g->maj_n[1] + (size_t)idx[1]) * g->maj_n[0] + (size_t)idx[0]];
        if (!(mj > 0.0f))
            continue; /* empty cell: skipped */
        if (pc->st_max * mj * (*b - *a) > MAJ_REFINE) {
            pc->fine_on = dda_init(&pc->fine, pc->u0, pc->du, 1.0, pc->nfine, *a, *b);
            continue;
        }
        for (int k = 0; k < 3; k++) {
            pc->clo[k] = ((double)idx[k] - 1.0) * GRID_MAJ_BLOCK;
            pc->chi[k] = (double)idx[k] * GRID_MAJ_BLOCK;
        }
        *maj = mj;
        pc->patch = 0;
        return 1;
    }
}

/* Density at t of the current piece, its point clamped into the piece's cell or patch. */
static float pieces_density(const struct pieces *pc, double t)
{
    const struct density_grid *g = pc->g;
    if (pc->patch) {
        float f[3];
        for (int k = 0; k < 3; k++)
            f[k] = (float)d_min(1.0, d_max(0.0, pc->u0[k] + t * pc->du[k] - (pc->p[k] - 1)));
        return trilerp(pc->V, f[0], f[1], f[2]);
    }
    int32_t n[3] = {(int32_t)g->nx, (int32_t)g->ny, (int32_t)g->nz}, i0[3], i1[3];
    float f[3];
    for (int k = 0; k < 3; k++) {
        double u = d_min(pc->chi[k], d_max(pc->clo[k], pc->u0[k] + t * pc->du[k])), fl = floor(u);
        f[k] = (float)(u - fl);
        int32_t a = (int32_t)fl;
        i0[k] = a < 0 ? 0 : (a >= n[k] ? n[k] - 1 : a);
        i1[k] = a + 1 < 0 ? 0 : (a + 1 >= n[k] ? n[k] - 1 : a + 1);
    }
#define V(x, y, z) g->data[((size_t)(z) * g->ny + (y)) * g->nx + (x)]
    float c[8] = {V(i0[0], i0[1], i0[2]), V(i1[0], i0[1], i0[2]), V(i0[0], i1[1], i0[2]), V(i1[0], i1[1], i0[2]),
                  V(i0[0], i0[1], i1[2]), V(i1[0], i0[1], i1[2]), V(i0[0], i1[1], i1[2]), V(i1[0], i1[1], i1[2])};
#undef V
    return trilerp(c, f[0], f[1], f[2]) * g->scale;
}

float grid_majorant(const struct density_grid *g, vec3 p)
{
    vec3 q = xform_point(&g->world_to_grid, p);
    float qq[3] = {q.x, q.y, q.z};
    uint32_t n[3] = {g->nx, g->ny, g->nz};
    size_t idx[3];
    for (int k = 0; k < 3; k++) {
        if (!(qq[k] >= 0.0f && qq[k] <= 1.0f))
            return 0.0f;
        double c = floor(((double)qq[k] * n[k] - 0.5) / GRID_MAJ_BLOCK + 1.0);
        idx[k] = c < 0.0 ? 0 : (c >= (double)g->maj_n[k] ? g->maj_n[k] - 1 : (size_t)c);
    }
    return g->majorant[(idx[2] * g->maj_n[1] + idx[1]) * g->maj_n[0] + idx[0]];
}

static _Atomic uint64_t track_bound_hits;

uint64_t grid_track_bound_hits(void)
{
    return atomic_load_explicit(&track_bound_hits, memory_order_relaxed);
}

/* A ray reached GRID_TRACK_MAX: counted, and logged the first time and at each power of 10. */
static void track_bound_hit(const char *what)
{
    uint64_t n = atomic_fetch_add_explicit(&track_bound_hits, 1, memory_order_relaxed) + 1, p = 1;
    while (p < n && p <= UINT64_MAX / 10)
        p *= 10;
    if (p == n)
        log_warn("density grid: %llu ray(s) so far reached the bound of %u tracking steps (%s; counted as "
                 "absorbed)", (unsigned long long)n, GRID_TRACK_MAX, what);
}

vec3 medium_tr_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key, int ratio)
{
    if (!m->grid)
        return medium_transmittance(m, len);
    float c0, c1;
    if (!medium_clip(m, o, d, len, &c0, &c1))
        return v3(1, 1, 1);
    if (ratio) {
        /* Ratio tracking: tentative collisions at rate mu = sigma_t,max x the piece's
         * majorant (an exponential optical depth consumed piece by piece), each multiplying
         * the estimate by 1 - sigma_t rho / mu. */
        struct pieces pc;
        if (!pieces_init(&pc, m, o, d, len, NULL))
            return v3(1, 1, 1);
        vec3 tr = v3(1, 1, 1);
        uint32_t k = 0;
        double a, b, left = -log1p(-(double)rng_uniform(key, 0));
        float maj;
        while (pieces_next(&pc, &a, &b, &maj)) {
            double mu = pc.st_max * maj, t = a;
            for (;;) {
                if (!(t + left / mu < b)) {
                    left = d_max(0.0, left - (b - t) * mu);
                    break;
                }
                t += left / mu;
                float r = (float)(pieces_density(&pc, t) / mu);
                tr = v3_mul(tr, v3(1.0f - m->sigma_t.x * r, 1.0f - m->sigma_t.y * r, 1.0f - m->sigma_t.z * r));
                if (v3_max_component(tr) < 1e-7f)
                    return v3(0, 0, 0);
                if (++k >= GRID_TRACK_MAX) {
                    track_bound_hit("ratio tracking");
                    return v3(0, 0, 0);
                }
                left = -log1p(-(double)rng_uniform(key, k));
            }
        }
        return tr;
    }
    /* Jensen: a jittered march of the optical depth at half-voxel steps. */
    float dx = 0.5f * m->grid->voxel_world;
    if ((c1 - c0) / dx > 100000.0f)
        dx = (c1 - c0) / 100000.0f;
    float tau = 0.0f, u = rng_uniform(key, 0);
    for (uint32_t k = 0;; k++) {
        float t = c0 + ((float)k + u) * dx;
        if (!(t < c1))
            break;
        tau += grid_density(m->grid, v3_add(o, v3_scale(d, t))) * dx;
    }
    return medium_tr_tau(m, tau);
}

vec3 medium_emission_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key)
{
    if (!m->grid)
        return medium_emission_integral(m, len);
    float c0, c1;
    if (v3_is_black(m->emission) || !medium_clip(m, o, d, len, &c0, &c1))
        return v3(0, 0, 0);
    float span = c1 - c0, t = c0 + rng_uniform(key, 0) * span;
    if (!(span > 0.0f) || !isfinite(span) || !(t < c1))
        return v3(0, 0, 0);
    float rho = grid_density(m->grid, v3_add(o, v3_scale(d, t)));
    if (!(rho > 0.0f))
        return v3(0, 0, 0);
    vec3 tr = medium_tr_segment(m, o, d, t, rng_mix64(key ^ 0x454d4954ull), 1);
    return v3_scale(v3_mul(tr, m->emission), rho * span);
}

int medium_sample_flight(const struct medium *m, vec3 o, vec3 d, float tmax, vec3 chan, uint64_t key, float *t,
                         vec3 *weight)
{
    return medium_sample_flight_clip(m, o, d, tmax, NULL, chan, key, t, weight);
}

int medium_sample_flight_clip(const struct medium *m, vec3 o, vec3 d, float tmax, const struct medium_clip_memo *clip,
                              vec3 chan, uint64_t key, float *t, vec3 *weight)
{
    if (!m->grid)
        return medium_sample_distance(m, tmax, chan, rng_uniform(key, 0), rng_uniform(key, 1), t, weight);
    *t = tmax;
    *weight = v3(1, 1, 1);
    struct pieces pc;
    if (!pieces_init(&pc, m, o, d, tmax, clip))
        return 0;
    /* Weighted delta tracking against each piece's majorant mu: a tentative collision is
     * real with probability avg(sigma_t(x)) / mu; the weights keep every channel unbiased. */
    vec3 w = v3(1, 1, 1);
    uint32_t k = 0;
    double a, b, left = -log1p(-(double)rng_uniform(key, 0));
    float majd;
    while (pieces_next(&pc, &a, &b, &majd)) {
        double tt = a;
        float mu = (float)(pc.st_max * majd);
        for (;;) {
            if (!(tt + left / mu < b)) {
                left = d_max(0.0, left - (b - tt) * mu);
                break;
            }
            tt += left / mu;
            float rho = pieces_density(&pc, tt);
            vec3 st = v3_scale(m->sigma_t, rho);
            float avg = (st.x + st.y + st.z) / 3.0f, p = avg / mu;
            if (rng_uniform(key, 2 * k + 1) < p) {
                *t = (float)tt;
                *weight = v3_mul(w, v3_scale(m->sigma_s, rho / avg));
                return 1;
            }
            float q = mu - avg;
            w = v3_mul(w, v3((mu - st.x) / q, (mu - st.y) / q, (mu - st.z) / q));
            if (++k >= GRID_TRACK_MAX) {
                track_bound_hit("delta tracking");
                *weight = v3(0, 0, 0);
                return 0;
            }
            left = -log1p(-(double)rng_uniform(key, 2 * k));
        }
    }
    *weight = w;
    return 0;
}

/* ---- shadow transmittance cache (Jensen's methods in grids) ---- */

void grid_world_box(const struct density_grid *g, vec3 *lo, vec3 *hi)
{
    *lo = v3(INFINITY, INFINITY, INFINITY);
    *hi = v3(-INFINITY, -INFINITY, -INFINITY);
    if (grid_is_empty(g))
        return; /* the empty box, not the corners of the one marked empty */
    for (int k = 0; k < 8; k++) {
        vec3 q = v3(k & 1 ? g->occ_hi.x : g->occ_lo.x, k & 2 ? g->occ_hi.y : g->occ_lo.y, k & 4 ? g->occ_hi.z : g->occ_lo.z);
        vec3 w = xform_point(&g->grid_to_world, q);
        *lo = v3(fminf(lo->x, w.x), fminf(lo->y, w.y), fminf(lo->z, w.z));
        *hi = v3(fmaxf(hi->x, w.x), fmaxf(hi->y, w.y), fmaxf(hi->z, w.z));
    }
}

void media_grids_grow_box(const struct scene_media *sm, vec3 *lo, vec3 *hi)
{
    for (uint32_t i = 0; sm && i < sm->num_media; i++) {
        vec3 glo, ghi;
        if (!sm->media[i].grid || grid_is_empty(sm->media[i].grid))
            continue;
        grid_world_box(sm->media[i].grid, &glo, &ghi);
        *lo = v3(fminf(lo->x, glo.x), fminf(lo->y, glo.y), fminf(lo->z, glo.z));
        *hi = v3(fmaxf(hi->x, ghi.x), fmaxf(hi->y, ghi.y), fmaxf(hi->z, ghi.z));
    }
}

float grid_optical_depth(const struct medium *m, vec3 a, vec3 b)
{
    if (!m->grid)
        return 0.0f;
    vec3 ab = v3_sub(b, a);
    float len = v3_length(ab);
    if (!(len > 0.0f))
        return 0.0f;
    vec3 d = v3_scale(ab, 1.0f / len);
    float c0, c1;
    if (!medium_clip(m, a, d, len, &c0, &c1))
        return 0.0f;
    /* Midpoint rule at steps of at most half a voxel: deterministic, no random number. The
     * samples are taken in grid space, the ray transformed once (the shadow cache's fill
     * takes most of its time here). */
    const struct density_grid *g = m->grid;
    float span = c1 - c0, steps = ceilf(span / (0.5f * g->voxel_world));
    uint32_t n = steps < 1.0f ? 1u : (steps > 100000.0f ? 100000u : (uint32_t)steps);
    float dx = span / (float)n;
    vec3 qa = xform_point(&g->world_to_grid, a), dq = xform_vector(&g->world_to_grid, d);
    double tau = 0.0;
    for (uint32_t k = 0; k < n; k++) {
        vec3 q = v3_add(qa, v3_scale(dq, c0 + ((float)k + 0.5f) * dx));
        if (grid_unit_box(q))
            tau += grid_trilinear(g, q);
    }
    return (float)(tau * g->scale * dx);
}

struct tr_fill { struct tr_cache *c; const struct medium *m; uint32_t threads, id; };

static void *tr_cache_fill(void *arg)
{
    const struct tr_fill *f = arg;
    struct tr_cache *c = f->c;
    for (uint32_t z = f->id; z < c->n[2]; z += f->threads)
        for (uint32_t y = 0; y < c->n[1]; y++)
            for (uint32_t x = 0; x < c->n[0]; x++) {
                vec3 p = v3(c->lo.x + (float)x * c->cell.x, c->lo.y + (float)y * c->cell.y, c->lo.z + (float)z * c->cell.z);
                c->tau[((size_t)z * c->n[1] + y) * c->n[0] + x] = grid_optical_depth(f->m, p, c->light);
            }
    return NULL;
}

int tr_cache_init(struct tr_cache *c, const struct medium *m, vec3 light, uint32_t threads)
{
    memset(c, 0, sizeof *c);
    const struct density_grid *g = m->grid;
    if (!g || grid_is_empty(g))
        return 0;
    /* World box of the occupied grid box: every point where a march step can land. */
    vec3 lo, hi;
    grid_world_box(g, &lo, &hi);
    float ext[3] = {hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}, cell[3];
    if (!(g->voxel_world > 0.0f) || !isfinite(ext[0] + ext[1] + ext[2]))
        return 0;
    for (int k = 0; k < 3; k++) {
        /* One vertex per voxel, at most TR_CACHE_MAX_N per axis. */
        float nv = ceilf(ext[k] / (TR_CACHE_SPACING * g->voxel_world));
        nv = nv < 1.0f ? 1.0f : (nv > (float)(TR_CACHE_MAX_N - 1) ? (float)(TR_CACHE_MAX_N - 1) : nv);
        c->n[k] = (uint32_t)nv + 1;
        cell[k] = ext[k] > 0.0f ? ext[k] / nv : 1.0f;
    }
    c->lo = lo;
    c->hi = hi;
    c->cell = v3(cell[0], cell[1], cell[2]);
    c->inv_cell = v3(1.0f / cell[0], 1.0f / cell[1], 1.0f / cell[2]);
    c->light = light;
    c->tau = mem_alloc(sizeof *c->tau * c->n[0] * c->n[1] * c->n[2]);
    threads = threads < 1 ? 1 : (threads > 64 ? 64 : threads);
    pthread_t th[64];
    struct tr_fill f[64];
    int started[64] = {0};
    for (uint32_t i = 0; i < threads; i++)
        f[i] = (struct tr_fill){c, m, threads, i};
    for (uint32_t i = 1; i < threads; i++)
        started[i] = pthread_create(&th[i], NULL, tr_cache_fill, &f[i]) == 0;
    tr_cache_fill(&f[0]);
    for (uint32_t i = 1; i < threads; i++) {
        if (started[i])
            pthread_join(th[i], NULL);
        else
            tr_cache_fill(&f[i]); /* no thread: fill its slices here (same values) */
    }
    return 1;
}

void tr_cache_fini(struct tr_cache *c)
{
    free(c->tau);
    c->tau = NULL;
}

int tr_cache_tau_from(const struct tr_cache *c, vec3 p, float *tau)
{
    if (!c->tau || !v3_is_finite(p))
        return 0;
    if (tr_cache_tau(c, p, tau))
        return 1;
    /* The part of p + t (light - p), t in [0, 1], inside the lattice's box. */
    vec3 d = v3_sub(c->light, p);
    float t0 = 0.0f, t1 = 1.0f;
    *tau = 0.0f;
    if (!v3_clip_box(p, d, c->lo, c->hi, &t0, &t1))
        return 1; /* the segment never enters the box: no density on it */
    /* The entry point, clamped onto the box against rounding. */
    vec3 q = v3_add(p, v3_scale(d, t0));
    q = v3(fminf(fmaxf(q.x, c->lo.x), c->hi.x), fminf(fmaxf(q.y, c->lo.y), c->hi.y), fminf(fmaxf(q.z, c->lo.z), c->hi.z));
    if (!tr_cache_tau(c, q, tau))
        *tau = 0.0f;
    return 1;
}

int tr_cache_tau(const struct tr_cache *c, vec3 p, float *tau)
{
    if (!c->tau)
        return 0;
    float u[3] = {(p.x - c->lo.x) * c->inv_cell.x, (p.y - c->lo.y) * c->inv_cell.y, (p.z - c->lo.z) * c->inv_cell.z};
    uint32_t i[3];
    float f[3];
    for (int k = 0; k < 3; k++) {
        if (!(u[k] >= 0.0f && u[k] <= (float)(c->n[k] - 1)))
            return 0;
        float fl = floorf(u[k]);
        i[k] = (uint32_t)fl;
        if (i[k] >= c->n[k] - 1)
            i[k] = c->n[k] >= 2 ? c->n[k] - 2 : 0;
        f[k] = c->n[k] >= 2 ? u[k] - (float)i[k] : 0.0f;
    }
    uint32_t sx = c->n[0] >= 2 ? 1 : 0, sy = c->n[1] >= 2 ? c->n[0] : 0,
             sz = c->n[2] >= 2 ? c->n[0] * c->n[1] : 0;
    const float *v = c->tau + ((size_t)i[2] * c->n[1] + i[1]) * c->n[0] + i[0];
    float c00 = v[0] * (1 - f[0]) + v[sx] * f[0], c10 = v[sy] * (1 - f[0]) + v[sy + sx] * f[0];
    float c01 = v[sz] * (1 - f[0]) + v[sz + sx] * f[0], c11 = v[sz + sy] * (1 - f[0]) + v[sz + sy + sx] * f[0];
    float c0 = c00 * (1 - f[1]) + c10 * f[1], c1 = c01 * (1 - f[1]) + c11 * f[1];
    *tau = c0 * (1 - f[2]) + c1 * f[2];
    return 1;
}
