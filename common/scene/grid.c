/* Density grids and tracking through them (see grid.h). Lookups and tracking are pure
 * functions of (grid, ray, key): no state, so any thread may call them. The shadow cache
 * is filled once by tr_cache_init (threads over z slices, same values for any count). */
#include "scene/grid.h"
#include "base/bytes.h"
#include "base/log.h"
#include "scene/motion.h"
#include "base/rng.h"
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

int grid_parse(const uint8_t *data, size_t size, struct density_grid *out, char *err, size_t errlen)
{
    memset(out, 0, sizeof *out);
    if (size < 20 || memcmp(data, GRID_MAGIC, 8) != 0) {
        str_fmt(err, errlen, "not a density grid (expected the \"%s\" header)", GRID_MAGIC);
        return -1;
    }
    uint32_t nx = bytes_get_u32(data + 8), ny = bytes_get_u32(data + 12), nz = bytes_get_u32(data + 16);
    if (nx < 1 || ny < 1 || nz < 1 || (uint64_t)nx * ny * nz > GRID_MAX_VOXELS) {
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
}

float grid_density(const struct density_grid *g, vec3 p)
{
    vec3 q = xform_point(&g->world_to_grid, p);
    if (!(q.x >= 0.0f && q.y >= 0.0f && q.z >= 0.0f && q.x <= 1.0f && q.y <= 1.0f && q.z <= 1.0f))
        return 0.0f;
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
    return (c0 * (1 - f[2]) + c1 * f[2]) * g->scale;
}

int medium_clip(const struct medium *m, vec3 o, vec3 d, float tmax, float *t0, float *t1)
{
    *t0 = 0.0f;
    *t1 = tmax;
    if (!m->grid)
        return tmax > 0.0f;
    const struct density_grid *g = m->grid;
    vec3 og = xform_point(&g->world_to_grid, o), dg = xform_vector(&g->world_to_grid, d);
    float a = 0.0f, b = tmax;
    if (!v3_clip_box(og, dg, g->occ_lo, g->occ_hi, &a, &b) || !(a < b))
        return 0;
    *t0 = a;
    *t1 = b;
    return 1;
}

float medium_march_step(const struct medium *m, float step)
{
    return m->grid ? fminf(step, 0.5f * m->grid->voxel_world) : step;
}

#define TRACK_MAX 1000000

vec3 medium_tr_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key, int ratio)
{
    if (!m->grid)
        return medium_transmittance(m, len);
    float c0, c1;
    if (!medium_clip(m, o, d, len, &c0, &c1))
        return v3(1, 1, 1);
    float st_max = v3_max_component(m->sigma_t), mu = st_max * m->grid->max_density;
    if (!(mu > 0.0f))
        return v3(1, 1, 1);
    if (ratio) {
        vec3 tr = v3(1, 1, 1);
        float t = c0;
        for (uint32_t k = 0; k < TRACK_MAX; k++) {
            t += -log1pf(-rng_uniform(key, k)) / mu;
            if (!(t < c1))
                break;
            float rho = grid_density(m->grid, v3_add(o, v3_scale(d, t)));
            tr = v3_mul(tr, v3(1.0f - m->sigma_t.x * rho / mu, 1.0f - m->sigma_t.y * rho / mu,
                               1.0f - m->sigma_t.z * rho / mu));
            if (v3_max_component(tr) < 1e-7f)
                return v3(0, 0, 0);
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
    return v3(expf(-m->sigma_t.x * tau), expf(-m->sigma_t.y * tau), expf(-m->sigma_t.z * tau));
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
    if (!m->grid)
        return medium_sample_distance(m, tmax, chan, rng_uniform(key, 0), rng_uniform(key, 1), t, weight);
    *t = tmax;
    *weight = v3(1, 1, 1);
    float c0, c1;
    if (!medium_clip(m, o, d, tmax, &c0, &c1))
        return 0;
    float mu = v3_max_component(m->sigma_t) * m->grid->max_density;
    if (!(mu > 0.0f))
        return 0;
    /* Weighted delta tracking: a tentative collision is real with probability
     * avg(sigma_t(x)) / mu; the weights keep every channel unbiased. */
    vec3 w = v3(1, 1, 1);
    float tt = c0;
    for (uint32_t k = 0; k < TRACK_MAX; k++) {
        tt += -log1pf(-rng_uniform(key, 2 * k)) / mu;
        if (!(tt < c1))
            break;
        float rho = grid_density(m->grid, v3_add(o, v3_scale(d, tt)));
        vec3 st = v3_scale(m->sigma_t, rho);
        float avg = (st.x + st.y + st.z) / 3.0f, p = avg / mu;
        if (rng_uniform(key, 2 * k + 1) < p) {
            *t = tt;
            *weight = v3_mul(w, v3_scale(m->sigma_s, rho / avg));
            return 1;
        }
        float q = mu - avg;
        w = v3_mul(w, v3((mu - st.x) / q, (mu - st.y) / q, (mu - st.z) / q));
    }
    *weight = w;
    return 0;
}

/* ---- shadow transmittance cache (Jensen's methods in grids) ---- */

void grid_world_box(const struct density_grid *g, vec3 *lo, vec3 *hi)
{
    *lo = v3(INFINITY, INFINITY, INFINITY);
    *hi = v3(-INFINITY, -INFINITY, -INFINITY);
    for (int k = 0; k < 8; k++) {
        vec3 q = v3(k & 1 ? g->occ_hi.x : g->occ_lo.x, k & 2 ? g->occ_hi.y : g->occ_lo.y, k & 4 ? g->occ_hi.z : g->occ_lo.z);
        vec3 w = xform_point(&g->grid_to_world, q);
        *lo = v3(fminf(lo->x, w.x), fminf(lo->y, w.y), fminf(lo->z, w.z));
        *hi = v3(fmaxf(hi->x, w.x), fmaxf(hi->y, w.y), fmaxf(hi->z, w.z));
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
    /* Midpoint rule at steps of at most half a voxel: deterministic, no random number. */
    float span = c1 - c0, steps = ceilf(span / (0.5f * m->grid->voxel_world));
    uint32_t n = steps < 1.0f ? 1u : (steps > 100000.0f ? 100000u : (uint32_t)steps);
    float dx = span / (float)n;
    double tau = 0.0;
    for (uint32_t k = 0; k < n; k++)
        tau += grid_density(m->grid, v3_add(a, v3_scale(d, c0 + ((float)k + 0.5f) * dx)));
    return (float)(tau * dx);
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
    if (!g || !(g->occ_lo.x <= g->occ_hi.x && g->occ_lo.y <= g->occ_hi.y && g->occ_lo.z <= g->occ_hi.z))
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
