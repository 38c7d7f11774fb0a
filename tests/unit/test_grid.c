/* Density grids' local majorants and the tracking that walks them:
 * - every majorant cell bounds every lookup in it, on a grid whose values span 12 orders
 *   of magnitude (and empty cells are 0);
 * - ratio tracking against the local majorants matches the fine integral of the optical
 *   depth within 4 standard errors on that grid, along several rays;
 * - free-flight distances (delta tracking) pass a Kolmogorov-Smirnov test against the
 *   exact CDF on a grid of constant blocks (piecewise linear between voxel centres);
 * - a grid a million times denser than usual next to near-empty voxels is tracked without
 *   reaching the step bound, and the bound itself holds. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "base/log.h"
#include "base/rng.h"
#include "helpers.h"
#include "scene/grid.h"
#include "scene/medium.h"

/* A grid of nx ny nz voxels with values from fill, placed on the unit cube. */
static void make_grid(struct density_grid *g, uint32_t nx, uint32_t ny, uint32_t nz, float scale,
                      float (*fill)(uint32_t, uint32_t, uint32_t))
{
    memset(g, 0, sizeof *g);
    g->nx = nx, g->ny = ny, g->nz = nz;
    g->data = mem_alloc(sizeof(float) * nx * ny * nz);
    for (uint32_t z = 0; z < nz; z++)
        for (uint32_t y = 0; y < ny; y++)
            for (uint32_t x = 0; x < nx; x++)
                g->data[((size_t)z * ny + y) * nx + x] = fill(x, y, z);
    struct xform id = xform_identity();
    grid_finish(g, &id, scale);
}

static void make_medium(struct medium *m, struct density_grid *g, vec3 sa, vec3 ss)
{
    memset(m, 0, sizeof *m);
    m->sigma_a = sa;
    m->sigma_s = ss;
    m->sigma_t = v3_add(sa, ss);
    m->grid = g;
}

/* Very uneven: log-uniform values over 1e-6 .. 1e6 in a random half of the voxels, 0
 * elsewhere, and an empty slab (x < 6). */
static float uneven(uint32_t x, uint32_t y, uint32_t z)
{
    uint64_t h = rng_mix64(((uint64_t)x << 40) ^ ((uint64_t)y << 20) ^ z ^ 0x6772696475ull);
    if (x < 6 || (h & 1))
        return 0.0f;
    return powf(10.0f, -6.0f + 12.0f * (float)((h >> 11) & 0xffff) / 65535.0f);
}

Test(grid, majorants_bound_every_lookup)
{
    struct density_grid g;
    make_grid(&g, 23, 17, 30, 0.37f, uneven);
    cr_assert_eq(g.maj_n[0], (23 + GRID_MAJ_BLOCK - 1) / GRID_MAJ_BLOCK + 1);
    uint64_t bad = 0, zero = 0;
    for (uint32_t i = 0; i < 400000; i++) {
        vec3 p = v3(rng_uniform(99, 3 * i), rng_uniform(99, 3 * i + 1), rng_uniform(99, 3 * i + 2));
        float rho = grid_density(&g, p), maj = grid_majorant(&g, p);
        bad += !(rho <= maj);
        if (p.x < 4.0f / 23.0f) /* voxels 0..5 are empty: so are the cells of x < 4 voxels */
            zero += maj != 0.0f;
    }
    cr_assert_eq(bad, 0, "%llu lookups above their cell's majorant", (unsigned long long)bad);
    cr_assert_eq(zero, 0, "%llu empty cells with a non-zero majorant", (unsigned long long)zero);
    free(g.data);
}

/* Optical depth per unit sigma_t along [0, len) of o + t d, midpoint rule in double. */
static double fine_tau(const struct density_grid *g, vec3 o, vec3 d, float len)
{
    const int n = 400000;
    double tau = 0.0;
    for (int i = 0; i < n; i++)
        tau += grid_density(g, v3_add(o, v3_scale(d, (float)((i + 0.5) * len / n))));
    return tau * len / n;
}

Test(grid, ratio_tracking_matches_fine_integral)
{
    struct density_grid g;
    /* The values reach 1e6 x 0.37: scaled so that the rays' optical depths are ~0.3-3. */
    make_grid(&g, 23, 17, 30, 4e-5f, uneven);
    struct medium m;
    make_medium(&m, &g, v3(0.4f, 0.2f, 0.8f), v3(0.6f, 0.5f, 0.1f));
    vec3 os[4] = {v3(-0.2f, 0.31f, 0.52f), v3(0.5f, -0.1f, 0.4f), v3(1.2f, 1.1f, 0.9f), v3(0.05f, 0.5f, 1.3f)};
    vec3 ts[4] = {v3(1.2f, 0.6f, 0.47f), v3(0.45f, 1.1f, 0.62f), v3(-0.1f, -0.2f, 0.1f), v3(0.9f, 0.45f, -0.2f)};
    uint64_t hits0 = grid_track_bound_hits();
    for (int r = 0; r < 4; r++) {
        vec3 to = v3_sub(ts[r], os[r]);
        float len = v3_length(to);
        vec3 d = v3_scale(to, 1.0f / len);
        double tau = fine_tau(&g, os[r], d, len);
        const int n = 40000;
        double sum[3] = {0}, sum2[3] = {0};
        for (int i = 0; i < n; i++) {
            vec3 tr = medium_tr_segment(&m, os[r], d, len, rng_mix64(0x7261ull + (uint64_t)i * 977 + (uint64_t)r), 1);
            float v[3] = {tr.x, tr.y, tr.z};
            for (int c = 0; c < 3; c++)
                sum[c] += v[c], sum2[c] += (double)v[c] * v[c];
        }
        float st[3] = {m.sigma_t.x, m.sigma_t.y, m.sigma_t.z};
        for (int c = 0; c < 3; c++) {
            double mean = sum[c] / n, var = fmax(sum2[c] / n - mean * mean, 0.0), se = sqrt(var / n);
            double ref = exp(-st[c] * tau);
            cr_assert(fabs(mean - ref) <= 4.0 * se + 1e-6, "ray %d channel %d: ratio tracking %g +- %g, fine %g (tau %g)",
                      r, c, mean, se, ref, tau);
        }
        cr_log_info("ray %d: tau %.4g, Tr %.4g\n", r, tau, exp(-m.sigma_t.x * tau));
    }
    cr_assert_eq(grid_track_bound_hits(), hits0);
    free(g.data);
}

/* Blocks of 8 voxels of one value along x (constant in y and z). */
static const float block_val[8] = {0.5f, 3.0f, 0.0f, 10.0f, 0.1f, 40.0f, 0.0f, 2.0f};
static float blocks(uint32_t x, uint32_t y, uint32_t z)
{
    (void)y, (void)z;
    return block_val[x / 8];
}

/* Exact optical depth per unit sigma_t from q = 0 to q = X (X in [0, 1]) along x of the
 * blocks grid (64 voxels, scale s): the trilinear density is linear between voxel centres
 * and constant (clamped) beyond the first and last ones. */
static double blocks_tau(double X, double s)
{
    const int n = 64;
    double U = X * n - 0.5, tau = 0.0;
    /* [-0.5, 0): the first voxel's value */
    tau += block_val[0] * (fmin(U, 0.0) + 0.5);
    for (int k = 0; k + 1 < n && U > k; k++) {
        double a = block_val[k / 8], b = block_val[(k + 1) / 8], e = fmin(U, k + 1.0) - k;
        tau += a * e + 0.5 * (b - a) * e * e;
    }
    if (U > n - 1)
        tau += block_val[7] * (U - (n - 1));
    return tau * s / n;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

Test(grid, free_flight_ks_against_exact_cdf)
{
    struct density_grid g;
    const float scale = 0.35f;
    make_grid(&g, 64, 3, 3, scale, blocks);
    struct medium m;
    make_medium(&m, &g, v3(0.5f, 0.5f, 0.5f), v3(0.5f, 0.5f, 0.5f)); /* sigma_t 1, grey */
    vec3 o = v3(-0.5f, 0.5f, 0.5f), d = v3(1, 0, 0);
    const float tmax = 2.0f;
    const int n = 20000;
    double *ts = mem_alloc(sizeof(double) * n);
    int scattered = 0;
    for (int i = 0; i < n; i++) {
        float t;
        vec3 w;
        int s = medium_sample_flight(&m, o, d, tmax, v3(1, 1, 1), rng_mix64(0x666c69ull + (uint64_t)i), &t, &w);
        cr_assert(v3_is_finite(w));
        if (s) {
            cr_assert(fabsf(w.x - 0.5f) < 1e-5f && t >= 0.5f && t <= 1.5f, "t %g w %g", (double)t, (double)w.x);
            ts[scattered++] = t;
        } else {
            cr_assert(fabsf(w.x - 1.0f) < 1e-4f, "pass weight %g", (double)w.x);
        }
    }
    qsort(ts, (size_t)scattered, sizeof *ts, cmp_double);
    /* F(t) = 1 - exp(-tau(t)), the unit cube from t = 0.5 to 1.5; passing: the mass left. */
    double D = 0.0, total = blocks_tau(1.0, scale);
    for (int i = 0; i < scattered; i++) {
        double F = 1.0 - exp(-blocks_tau(ts[i] - 0.5, scale));
        D = fmax(D, fmax(fabs((double)(i + 1) / n - F), fabs((double)i / n - F)));
    }
    double pass_exact = exp(-total), pass = (double)(n - scattered) / n;
    free(ts);
    /* KS at alpha = 0.001: 1.95 / sqrt(n). */
    cr_assert(D < 1.95 / sqrt((double)n), "KS distance %g (limit %g)", D, 1.95 / sqrt((double)n));
    cr_assert(fabs(pass - pass_exact) < 4.0 * sqrt(pass_exact * (1 - pass_exact) / n), "passing %g, exact %g", pass,
              pass_exact);
    cr_log_info("free flight: KS distance %.4g, passing %.4g (exact %.4g)\n", D, pass, pass_exact);
    free(g.data);
}

/* A voxel of 1e6 x 3e6 next to near-empty ones (the smoke times 1e6 in miniature): rays
 * skimming the thin side, crossing the dense voxel and starting inside it are tracked
 * without reaching the bound, and finish fast (the test would time out otherwise). */
static float spike(uint32_t x, uint32_t y, uint32_t z)
{
    return (x == 4 && y == 4 && z == 4) ? 1.0f : ((x + y + z) % 3 == 0 ? 1e-12f : 0.0f);
}

Test(grid, huge_density_tracks_without_the_bound, .timeout = 60)
{
    struct density_grid g;
    make_grid(&g, 9, 9, 9, 3e12f, spike);
    struct medium m;
    make_medium(&m, &g, v3(0.05f, 0.05f, 0.05f), v3(2.5f, 2.5f, 2.5f));
    uint64_t hits0 = grid_track_bound_hits();
    vec3 os[3] = {v3(-0.1f, 0.37f, 0.52f), v3(-0.1f, 0.5f, 0.5f), v3(0.5f, 0.5f, 0.5f)};
    vec3 d = v3(1, 0, 0);
    int opaque = 0;
    for (int r = 0; r < 3; r++)
        for (int i = 0; i < 2000; i++) {
            uint64_t key = rng_mix64((uint64_t)i * 31 + (uint64_t)r);
            vec3 tr = medium_tr_segment(&m, os[r], d, 1.5f, key, 1);
            cr_assert(v3_is_finite(tr) && tr.x >= 0.0f && tr.x <= 1.0f);
            opaque += r > 0 && tr.x == 0.0f;
            float t;
            vec3 w;
            int s = medium_sample_flight(&m, os[r], d, 1.5f, v3(1, 1, 1), key, &t, &w);
            cr_assert(v3_is_finite(w) && (!s || (t >= 0.0f && t < 1.5f)));
        }
    cr_assert_eq(opaque, 4000, "rays through the dense voxel: %d of 4000 opaque", opaque);
    cr_assert_eq(grid_track_bound_hits(), hits0, "the step bound was reached");
    free(g.data);
}

/* A lopsided blob: dense on one side, thin on the other, empty beyond a sphere. */
static float blob(uint32_t x, uint32_t y, uint32_t z)
{
    float dx = ((float)x - 9.5f) / 9.0f, dy = ((float)y - 6.5f) / 6.0f, dz = ((float)z - 12.0f) / 11.0f;
    float r2 = dx * dx + dy * dy + dz * dz;
    return r2 < 1.0f ? (1.0f - r2) * (0.2f + 3.0f * (dx > 0.0f ? dx : 0.0f)) : 0.0f;
}

/* grid_aim_sample against grid_aim_pdf (test_direction_chi_square), from a point outside
 * the grid and one inside it, on a grid rotated and stretched unevenly. */
struct aim_at { const struct grid_aim *a; vec3 p; };
static float aim_pdf_of(void *ctx, vec3 w)
{
    const struct aim_at *q = ctx;
    return grid_aim_pdf(q->a, q->p, w);
}
static vec3 aim_sample_of(void *ctx, uint32_t k)
{
    const struct aim_at *q = ctx;
    uint64_t key = 0xa13ull + k;
    return grid_aim_sample(q->a, q->p, rng_uniform(key, 0), rng_uniform(key, 1), rng_uniform(key, 2), rng_uniform(key, 3));
}

Test(grid, aim_sampling_chi_square, .timeout = 120)
{
    struct density_grid g;
    make_grid(&g, 20, 14, 25, 1.0f, blob);
    /* rotate 0.7 rad about (1, 2, 3), stretch to 2 x 1 x 1.5, move to (1, -2, 3) */
    vec3 ax = v3_normalize(v3(1, 2, 3));
    float ca = cosf(0.7f), sa = sinf(0.7f), k[3] = {ax.x, ax.y, ax.z}, sc[3] = {2.0f, 1.0f, 1.5f}, tr[3] = {1, -2, 3};
    struct xform xf;
    for (int r = 0; r < 3; r++) {
        for (int col = 0; col < 3; col++) {
            float cross = (r == 0 ? (col == 1 ? -k[2] : col == 2 ? k[1] : 0.0f)
                                  : r == 1 ? (col == 0 ? k[2] : col == 2 ? -k[0] : 0.0f)
                                           : (col == 0 ? -k[1] : col == 1 ? k[0] : 0.0f));
            float rot = ca * (r == col) + sa * cross + (1.0f - ca) * k[r] * k[col];
            xf.m[r][col] = rot * sc[col];
        }
        xf.m[r][3] = tr[r];
    }
    grid_finish(&g, &xf, 1.0f);
    struct grid_aim a;
    cr_assert(grid_aim_init(&a, &g));
    vec3 centre = xform_point(&g.grid_to_world, v3(0.5f, 0.5f, 0.5f));
    vec3 outside = v3(4.0f, 1.0f, -1.0f), c = v3_normalize(v3_sub(centre, outside));
    double cone = 0.0; /* the grid box's half-angle from outside, around c */
    for (int k8 = 0; k8 < 8; k8++) {
        vec3 q = xform_point(&g.grid_to_world, v3((float)(k8 & 1), (float)(k8 >> 1 & 1), (float)(k8 >> 2)));
        cone = fmax(cone, acos(fmax(-1.0, fmin(1.0, v3_dot(c, v3_normalize(v3_sub(q, outside)))))));
    }
    cr_assert(cone < 1.2);
    struct aim_at at = {&a, outside};
    test_direction_chi_square("grid aim, outside", c, cone + 0.02, 12, 8, 48, aim_pdf_of, aim_sample_of, &at, 200000,
                              5e-3, 200, 40);
    at.p = xform_point(&g.grid_to_world, v3(0.45f, 0.5f, 0.55f)); /* in the blob */
    test_direction_chi_square("grid aim, inside", v3(0, 1, 0), M_PI, 12, 8, 48, aim_pdf_of, aim_sample_of, &at, 200000,
                              5e-3, 200, 80);
    grid_aim_fini(&a);
    /* an empty grid has nothing to aim at */
    struct density_grid e;
    make_grid(&e, 4, 4, 4, 1.0f, spike);
    memset(e.data, 0, sizeof(float) * 64);
    grid_finish(&e, &xf, 1.0f);
    cr_assert_not(grid_aim_init(&a, &e));
    grid_aim_fini(&a);
    free(e.data);
    free(g.data);
}

static float nothing(uint32_t x, uint32_t y, uint32_t z)
{
    (void)x, (void)y, (void)z;
    return 0.0f;
}

/* A grid with no density anywhere has an empty world box (lo > hi), and the box that
 * bounds the media (photon tracing, the media job's bounds) does not grow by it; a grid
 * with density grows it by exactly its occupied box. */
Test(grid, empty_grid_has_an_empty_world_box)
{
    struct density_grid empty, full;
    make_grid(&empty, 4, 4, 4, 1.0f, nothing);
    make_grid(&full, 8, 8, 8, 1.0f, blob);
    vec3 lo, hi;
    grid_world_box(&empty, &lo, &hi);
    cr_assert(lo.x > hi.x && lo.y > hi.y && lo.z > hi.z, "empty: %g..%g", (double)lo.x, (double)hi.x);
    struct medium md[2];
    make_medium(&md[0], &empty, v3(0.1f, 0.1f, 0.1f), v3(1, 1, 1));
    make_medium(&md[1], &full, v3(0.1f, 0.1f, 0.1f), v3(1, 1, 1));
    struct scene_media sm = {.media = md, .num_media = 1};
    vec3 blo = v3(5, 5, 5), bhi = v3(6, 6, 6);
    media_grids_grow_box(&sm, &blo, &bhi);
    cr_assert(blo.x == 5 && blo.y == 5 && blo.z == 5 && bhi.x == 6 && bhi.y == 6 && bhi.z == 6,
              "an empty grid grew the box to %g %g %g .. %g %g %g", (double)blo.x, (double)blo.y, (double)blo.z,
              (double)bhi.x, (double)bhi.y, (double)bhi.z);
    sm.num_media = 2;
    media_grids_grow_box(&sm, &blo, &bhi);
    vec3 flo, fhi;
    grid_world_box(&full, &flo, &fhi);
    cr_assert(flo.x < fhi.x && flo.x >= 0.0f && fhi.x <= 1.0f, "the blob's box %g..%g", (double)flo.x, (double)fhi.x);
    cr_assert(blo.x == flo.x && blo.y == flo.y && blo.z == flo.z && bhi.x == 6 && bhi.y == 6 && bhi.z == 6);
    free(empty.data), free(full.data);
}
