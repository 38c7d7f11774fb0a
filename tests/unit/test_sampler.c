/* The three samplers: values are pure functions of (seed, frame, pixel, sample, dimension)
 * whatever the call order (with pinned values), in [0, 1), uniform (chi-square, 2D pairs for
 * pixel, lens and a deep bounce, and 1D dims), and stratified: at spp = N each of the N
 * strata of a 2D pair (and of a 1D dim) gets exactly one sample. */
#include <criterion/criterion.h>
#include <math.h>
#include <string.h>
#include "scene/sampler.h"

static const enum sampler_type all_types[] = {SAMPLER_INDEPENDENT, SAMPLER_STRATIFIED, SAMPLER_SOBOL};
/* As scene files and the command line spell them, in all_types' order. */
static const char *const type_names[] = {"independent", "stratified", "sobol"};

Test(sampler, names_round_trip)
{
    cr_assert_eq(SAMPLER_COUNT_, 3);
    for (int i = 0; i < SAMPLER_COUNT_; i++) {
        enum sampler_type t;
        cr_assert_eq(sampler_type_from_name(type_names[i], &t), 0, "%s", type_names[i]);
        cr_assert_eq(t, all_types[i]);
    }
    enum sampler_type t;
    cr_assert_eq(sampler_type_from_name("halton", &t), -1);
}

Test(sampler, consistent_values)
{
    /* Pinned: a change here changes every image rendered with that sampler; do it on purpose. */
    const float pinned[3][4] = {{0x1.ea7d18p-2f, 0x1.d9195ep-1f, 0x1.90349ep-1f, 0x1.02bc7cp-2f},
                                {0x1.1ea7dp-2f, 0x1.4d2b5cp-1f, 0x1.190348p-1f, 0x1.6d7438p-1f},
                                {0x1.b200c8p-1f, 0x1.d6e1a8p-1f, 0x1.3f9ae2p-1f, 0x1.a10b1ap-1f}};
    const uint32_t dims[4] = {DIM_PIXEL_X, DIM_LENS_V, DIM_TIME, sampler_bounce_dim(7, DIM_BSDF_V)};
    for (int t = 0; t < 3; t++) {
        struct sampler s = sampler_start_type(all_types[t], 1, 2, 1234, 5, 16);
        /* Reverse order, with unrelated samplers in between: nothing may change. */
        for (int k = 3; k >= 0; k--) {
            struct sampler o = sampler_start_type(all_types[t], 9, 9, 9, (uint32_t)k, 16);
            (void)sampler_get(&o, dims[k] + 1);
            cr_assert_eq(sampler_get(&s, dims[k]), pinned[t][k], "type %d dim %u", t, dims[k]);
        }
        float u, v;
        sampler_get_2d(&s, DIM_LENS_U, &u, &v);
        cr_assert_eq(v, pinned[t][1]);
        cr_assert_eq(u, sampler_get(&s, DIM_LENS_U));
    }
    /* The independent sampler keeps the bits of earlier versions. */
    struct sampler s = sampler_start(1, 0, 42, 3);
    cr_assert_eq(sampler_get(&s, DIM_PIXEL_X), rng_uniform(rng_key(1, 0, 42, 3), DIM_PIXEL_X));
}

/* The per-pixel fast path (set up once, memoized seeds) gives the values of the plain one
 * for every type, spp (powers of two or not), sample (later passes too) and dimension,
 * whatever order the dimensions are asked in. */
Test(sampler, pixel_path_matches_plain_path)
{
    const uint32_t spps[] = {1, 3, 16, 20, 64};
    for (int t = 0; t < 3; t++)
        for (size_t k = 0; k < sizeof spps / sizeof *spps; k++) {
            struct sampler_pixel p;
            sampler_pixel_init(&p, all_types[t], 77, 3, 4321, spps[k]);
            for (uint32_t si = 0; si < 3 * spps[k] + 1; si++) {
                /* Memo moved to the sample's pass, or left on pass 0 (every third pixel
                 * pass): the same values either way. */
                if (si % 3 != 2)
                    sampler_pixel_set_pass(&p, si / spps[k]);
                struct sampler a = sampler_start_pixel(&p, si);
                struct sampler b = sampler_start_type(all_types[t], 77, 3, 4321, si, spps[k]);
                for (uint32_t n = 0; n < 80; n++) {
                    uint32_t d = (n * 37u + si) % 80u; /* scattered order, past the memo's 64 */
                    cr_assert_eq(sampler_get(&a, d), sampler_get(&b, d), "type %d spp %u sample %u dim %u", t,
                                 spps[k], si, d);
                }
            }
        }
}

Test(sampler, coordinates_matter)
{
    for (int t = 1; t < 3; t++) {
        struct sampler s = sampler_start_type(all_types[t], 7, 3, 12345, 9, 64);
        float x = sampler_get(&s, DIM_LENS_U);
        struct sampler s2 = sampler_start_type(all_types[t], 8, 3, 12345, 9, 64);
        struct sampler s3 = sampler_start_type(all_types[t], 7, 4, 12345, 9, 64);
        struct sampler s4 = sampler_start_type(all_types[t], 7, 3, 12346, 9, 64);
        struct sampler s5 = sampler_start_type(all_types[t], 7, 3, 12345, 10, 64);
        cr_assert_neq(sampler_get(&s2, DIM_LENS_U), x);
        cr_assert_neq(sampler_get(&s3, DIM_LENS_U), x);
        cr_assert_neq(sampler_get(&s4, DIM_LENS_U), x);
        cr_assert_neq(sampler_get(&s5, DIM_LENS_U), x);
    }
}

Test(sampler, range_half_open_any_spp)
{
    const uint32_t spps[] = {1, 2, 3, 7, 16, 100, 1024};
    for (int t = 0; t < 3; t++)
        for (size_t k = 0; k < sizeof spps / sizeof *spps; k++)
            for (uint32_t i = 0; i < 2 * spps[k] + 3; i++) {
                struct sampler s = sampler_start_type(all_types[t], 3, 0, i * 31u, i, spps[k]);
                for (uint32_t d = 0; d < 40; d++) {
                    float u = sampler_get(&s, d);
                    cr_assert(u >= 0.0f && u < 1.0f, "type %d spp %u u=%a", t, spps[k], (double)u);
                }
            }
}

Test(sampler, permutation_is_bijection)
{
    const uint32_t ns[] = {1, 2, 3, 5, 16, 17, 100, 1000};
    static unsigned char seen[1000];
    for (size_t k = 0; k < sizeof ns / sizeof *ns; k++)
        for (uint32_t seed = 0; seed < 5; seed++) {
            memset(seen, 0, sizeof seen);
            for (uint32_t i = 0; i < ns[k]; i++) {
                uint32_t j = sampler_permute(i, ns[k], seed * 0x9e3779b9u);
                cr_assert_lt(j, ns[k]);
                cr_assert_eq(seen[j], 0);
                seen[j] = 1;
            }
        }
}

/* Chi-square over a 16x16 grid of a 2D pair, over many pixels of spp samples each; 255
 * degrees of freedom, p = 0.001 critical value about 330.5. */
static double chi2_2d(enum sampler_type t, uint32_t spp, uint32_t dim0, uint32_t dim1)
{
    enum { B = 16, N = 256 * 200 };
    static unsigned hist[B * B];
    memset(hist, 0, sizeof hist);
    for (uint32_t i = 0; i < N; i++) {
        struct sampler s = sampler_start_type(t, 99, 0, i / spp, i % spp, spp);
        int x = (int)(sampler_get(&s, dim0) * B), y = (int)(sampler_get(&s, dim1) * B);
        hist[y * B + x]++;
    }
    double expect = (double)N / (B * B), chi2 = 0.0;
    for (int i = 0; i < B * B; i++)
        chi2 += (hist[i] - expect) * (hist[i] - expect) / expect;
    return chi2;
}

Test(sampler, chi_square_uniform)
{
    for (int t = 0; t < 3; t++) {
        uint32_t spp = t == 0 ? 1 : 64;
        cr_assert_lt(chi2_2d(all_types[t], spp, DIM_PIXEL_X, DIM_PIXEL_Y), 330.5, "type %d pixel", t);
        cr_assert_lt(chi2_2d(all_types[t], spp, DIM_LENS_U, DIM_LENS_V), 330.5, "type %d lens", t);
        cr_assert_lt(chi2_2d(all_types[t], spp, sampler_bounce_dim(9, DIM_BSDF_U), sampler_bounce_dim(9, DIM_BSDF_V)),
                     330.5, "type %d deep bsdf", t);
        /* Across pairs (lens u against a bounce's light v) and 1D dims paired: independence. */
        cr_assert_lt(chi2_2d(all_types[t], spp, DIM_LENS_U, sampler_bounce_dim(2, DIM_LIGHT_V)), 330.5, "type %d x", t);
        cr_assert_lt(chi2_2d(all_types[t], spp, DIM_TIME, sampler_bounce_dim(4, DIM_RR)), 330.5, "type %d 1d", t);
        /* Non-power-of-two spp. */
        cr_assert_lt(chi2_2d(all_types[t], 24, DIM_PIXEL_X, DIM_PIXEL_Y), 330.5, "type %d spp 24", t);
    }
}

static void check_strata(enum sampler_type t, uint32_t spp, uint32_t nx, uint32_t ny, uint32_t dim0, uint64_t pixel)
{
    static unsigned cells[1024];
    memset(cells, 0, sizeof cells);
    for (uint32_t i = 0; i < spp; i++) {
        struct sampler s = sampler_start_type(t, 5, 1, pixel, i, spp);
        float u, v;
        sampler_get_2d(&s, dim0, &u, &v);
        uint32_t cx = (uint32_t)floor((double)u * nx), cy = (uint32_t)floor((double)v * ny);
        cells[cy * nx + cx]++;
    }
    for (uint32_t c = 0; c < nx * ny; c++)
        cr_assert_eq(cells[c], 1, "type %d spp %u dim %u cell %u has %u", t, spp, dim0, c, cells[c]);
}

Test(sampler, stratification_2d_and_1d)
{
    const uint32_t dims[] = {DIM_PIXEL_X, DIM_LENS_U, sampler_bounce_dim(0, DIM_LIGHT_U),
                             sampler_bounce_dim(11, DIM_BSDF_U)};
    for (int t = 1; t < 3; t++)
        for (size_t d = 0; d < sizeof dims / sizeof *dims; d++)
            for (uint64_t px = 0; px < 3; px++) {
                check_strata(all_types[t], 4, 2, 2, dims[d], px);
                check_strata(all_types[t], 8, 2, 4, dims[d], px);
                check_strata(all_types[t], 16, 4, 4, dims[d], px);
                check_strata(all_types[t], 64, 8, 8, dims[d], px);
                check_strata(all_types[t], 256, 16, 16, dims[d], px);
                /* Sobol (a (0,m,2)-net) is stratified in every elementary interval too. */
                if (all_types[t] == SAMPLER_SOBOL) {
                    check_strata(all_types[t], 64, 64, 1, dims[d], px);
                    check_strata(all_types[t], 64, 1, 64, dims[d], px);
                    check_strata(all_types[t], 64, 4, 16, dims[d], px);
                } else {
                    check_strata(all_types[t], 9, 3, 3, dims[d], px);
                    /* Multi-jittered: both 1D projections are stratified into spp strata. */
                    check_strata(all_types[t], 64, 64, 1, dims[d], px);
                    check_strata(all_types[t], 64, 1, 64, dims[d], px);
                    check_strata(all_types[t], 12, 12, 1, dims[d], px);
                    check_strata(all_types[t], 12, 1, 12, dims[d], px);
                    check_strata(all_types[t], 12, 3, 4, dims[d], px);
                }
            }
    /* 1D dims: N strata, one sample each. */
    const uint32_t dims1[] = {DIM_TIME, sampler_bounce_dim(3, DIM_LIGHT_PICK), sampler_bounce_dim(3, DIM_RR)};
    for (int t = 1; t < 3; t++)
        for (size_t d = 0; d < 3; d++) {
            unsigned cells[64] = {0};
            for (uint32_t i = 0; i < 64; i++) {
                struct sampler s = sampler_start_type(all_types[t], 5, 1, 77, i, 64);
                cells[(int)(sampler_get(&s, dims1[d]) * 64)]++;
            }
            for (int c = 0; c < 64; c++)
                cr_assert_eq(cells[c], 1);
        }
}

Test(sampler, second_pass_is_a_fresh_pattern)
{
    /* Sample indices beyond spp keep working (progressive passes) and differ from pass 0. */
    struct sampler a = sampler_start_type(SAMPLER_SOBOL, 1, 0, 5, 3, 16);
    struct sampler b = sampler_start_type(SAMPLER_SOBOL, 1, 0, 5, 3 + 16, 16);
    cr_assert_neq(sampler_get(&a, DIM_PIXEL_X), sampler_get(&b, DIM_PIXEL_X));
    check_strata(SAMPLER_SOBOL, 16, 4, 4, DIM_LENS_U, 5);
}

Test(sampler, dimensions_do_not_overlap)
{
    cr_assert_eq(sampler_bounce_dim(0, 0), DIM_BOUNCE_BASE);
    cr_assert_eq(sampler_bounce_dim(1, 0), sampler_bounce_dim(0, DIM_PER_BOUNCE - 1) + 1);
    cr_assert_gt((int)DIM_BOUNCE_BASE, (int)DIM_TIME);
    uint32_t comp;
    int is2;
    cr_assert_eq(sampler_dim_pair(DIM_PIXEL_Y, &comp, &is2), DIM_PIXEL_X);
    cr_assert(is2 && comp == 1);
    cr_assert_eq(sampler_dim_pair(DIM_TIME, &comp, &is2), DIM_TIME);
    cr_assert(!is2);
    cr_assert_eq(sampler_dim_pair(sampler_bounce_dim(4, DIM_BSDF_V), &comp, &is2), sampler_bounce_dim(4, DIM_BSDF_U));
    cr_assert(is2 && comp == 1);
    cr_assert_eq(sampler_dim_pair(sampler_bounce_dim(4, DIM_LIGHT_U), &comp, &is2), sampler_bounce_dim(4, DIM_LIGHT_U));
    cr_assert(is2 && comp == 0);
    cr_assert_eq(sampler_dim_pair(sampler_bounce_dim(4, DIM_RR), &comp, &is2), sampler_bounce_dim(4, DIM_RR));
    cr_assert(!is2);
}

/* sampler_pixel_cells claims a grid only where the pixel pair really holds one
 * sample per cell (texture lookups centre on that cell), and no grid otherwise. */
Test(sampler, pixel_cells_only_where_the_grid_holds)
{
    static const uint32_t spps[] = {1, 2, 4, 8, 9, 12, 16, 25, 64, 256};
    for (int t = 0; t < 3; t++)
        for (size_t k = 0; k < sizeof spps / sizeof *spps; k++) {
            uint32_t spp = spps[k];
            struct sampler s0 = sampler_start_type(all_types[t], 5, 0, 3, 0, spp);
            uint32_t nx, ny;
            int grid = sampler_pixel_cells(&s0, &nx, &ny);
            const char *name = type_names[t];
            if (spp == 1)
                cr_expect(grid && nx == 1 && ny == 1, "%s: one sample is alone in its pixel", name);
            else if (all_types[t] == SAMPLER_INDEPENDENT || (all_types[t] == SAMPLER_SOBOL && (spp & (spp - 1)) != 0))
                cr_expect(!grid, "%s spp %u: no grid", name, spp);
            else
                cr_expect(grid && nx * ny == spp && nx <= ny && ny <= 2 * nx + 2, "%s spp %u: grid %ux%u", name, spp, nx, ny);
            if (grid && spp > 1)
                for (uint64_t px = 0; px < 3; px++)
                    check_strata(all_types[t], spp, nx, ny, DIM_PIXEL_X, px);
        }
}

/* ---- sobol replicate streams (sampler.h: pass p is block p / SAMPLER_STREAMS of stream
 * p mod SAMPLER_STREAMS) ---- */

/* The sampler of index `idx` of stream `stream` with passes of k samples. */
static struct sampler stream_sample(uint64_t pixel, uint32_t stream, uint32_t idx, uint32_t k)
{
    uint32_t pass = idx / k * SAMPLER_STREAMS + stream;
    return sampler_start_type(SAMPLER_SOBOL, 5, 1, pixel, pass * k + idx % k, k);
}

/* Indices [first, first + 2^m) of a stream form a (0,m,2)-net in the pair at dim0: every
 * elementary box of area 2^-m, of every shape 2^a x 2^(m-a), holds exactly one point; and
 * the 1D dim dim1 is stratified into 2^m strata. */
static void check_net(uint64_t pixel, uint32_t stream, uint32_t k, uint32_t first, int m, uint32_t dim0,
                      uint32_t dim1)
{
    uint32_t n = 1u << m;
    static float us[4096], vs[4096], ws[4096];
    for (uint32_t i = 0; i < n; i++) {
        struct sampler s = stream_sample(pixel, stream, first + i, k);
        sampler_get_2d(&s, dim0, &us[i], &vs[i]);
        ws[i] = sampler_get(&s, dim1);
    }
    static unsigned cells[4096];
    for (int a = 0; a <= m; a++) {
        uint32_t nx = 1u << a, ny = 1u << (m - a);
        memset(cells, 0, sizeof(unsigned) * n);
        for (uint32_t i = 0; i < n; i++)
            cells[(uint32_t)(vs[i] * (float)ny) * nx + (uint32_t)(us[i] * (float)nx)]++;
        for (uint32_t c = 0; c < n; c++)
            cr_assert_eq(cells[c], 1, "stream %u k %u indices [%u, %u) dim %u box %ux%u cell %u holds %u", stream, k,
                         first, first + n, dim0, nx, ny, c, cells[c]);
    }
    memset(cells, 0, sizeof(unsigned) * n);
    for (uint32_t i = 0; i < n; i++)
        cells[(uint32_t)(ws[i] * (float)n)]++;
    for (uint32_t c = 0; c < n; c++)
        cr_assert_eq(cells[c], 1, "stream %u 1D dim %u stratum %u of %u", stream, dim1, c, n);
}

Test(sampler, stream_prefixes_and_blocks_are_nets)
{
    const uint32_t pairs[] = {DIM_PIXEL_X, DIM_LENS_U, sampler_bounce_dim(0, DIM_LIGHT_U),
                              sampler_bounce_dim(5, DIM_BSDF_U)};
    const uint32_t ones[] = {DIM_TIME, sampler_bounce_dim(0, DIM_RR), sampler_bounce_dim(5, DIM_LIGHT_PICK),
                             sampler_bounce_dim(1, DIM_RR)};
    const uint32_t ks[] = {1, 4, 8, 32};
    for (uint32_t s = 0; s < SAMPLER_STREAMS; s++)
        for (size_t ki = 0; ki < sizeof ks / sizeof *ks; ki++)
            for (size_t d = 0; d < 4; d++)
                for (uint64_t px = 0; px < 2; px++) {
                    /* Every power-of-two prefix of the stream, whatever the pass size. */
                    for (int m = 0; m <= 10; m++)
                        check_net(px * 977u, s, ks[ki], 0, m, pairs[d], ones[d]);
                    /* And any aligned block (a later pass, the second half of a prefix). */
                    check_net(px * 977u, s, ks[ki], 8 * ks[ki], 3, pairs[d], ones[d]);
                    check_net(px * 977u, s, ks[ki], 256, 8, pairs[d], ones[d]);
                }
}

/* The shuffle is a bijection that maps aligned blocks of 2^m onto aligned blocks of 2^m. */
Test(sampler, shuffle_keeps_aligned_blocks)
{
    static unsigned char seen[1024];
    for (uint32_t seed = 1; seed < 40; seed++) {
        uint32_t sd = seed * 0x9e3779b9u;
        for (int m = 0; m <= 10; m++)
            for (uint32_t block = 0; block < 4; block++) {
                uint32_t n = 1u << m, first = block * n + (seed % 3) * (n << 3);
                uint32_t base = sampler_shuffle(first, sd) & ~(n - 1u);
                memset(seen, 0, n);
                for (uint32_t i = first; i < first + n; i++) {
                    uint32_t j = sampler_shuffle(i, sd);
                    cr_assert_eq(j & ~(n - 1u), base, "seed %u m %u: index %u leaves the block", seed, m, i);
                    cr_assert_eq(seen[j & (n - 1u)], 0);
                    seen[j & (n - 1u)] = 1;
                }
            }
        /* Not the identity: the order is shuffled. */
        uint32_t moved = 0;
        for (uint32_t i = 0; i < 64; i++)
            moved += sampler_shuffle(i, sd) != i;
        cr_assert_gt(moved, 16);
    }
}

/* A value is a pure function of (seed, frame, pixel, stream, index in the stream, dim):
 * the same stream index reached with another pass size gives the same bits; another
 * stream, pixel or index does not. */
Test(sampler, stream_values_are_pure)
{
    for (uint32_t s = 0; s < SAMPLER_STREAMS; s++)
        for (uint32_t idx = 0; idx < 64; idx += 7) {
            struct sampler a = stream_sample(11, s, idx, 8), b = stream_sample(11, s, idx, 2),
                           c = stream_sample(11, s, idx, 1);
            struct sampler_pixel p;
            sampler_pixel_init(&p, SAMPLER_SOBOL, 5, 1, 11, 4);
            sampler_pixel_set_pass(&p, idx / 4 * SAMPLER_STREAMS + s);
            struct sampler e = sampler_start_pixel(&p, (idx / 4 * SAMPLER_STREAMS + s) * 4 + idx % 4);
            /* With photon maps (SAMPLER_STREAMS_MAPS streams), pass p is block p / 4 of
             * stream p mod 4: stream 0's blocks are the same sequence as here. */
            struct sampler_pixel pm;
            sampler_pixel_init(&pm, SAMPLER_SOBOL, 5, 1, 11, 4);
            sampler_pixel_set_streams(&pm, SAMPLER_STREAMS_MAPS);
            uint32_t pass_m = idx / 4 * SAMPLER_STREAMS_MAPS + s;
            struct sampler f = sampler_start_pixel(&pm, pass_m * 4 + idx % 4);
            struct sampler o = stream_sample(11, (s + 1) % SAMPLER_STREAMS, idx, 8);
            struct sampler q = stream_sample(12, s, idx, 8);
            for (uint32_t d = 0; d < 70; d++) {
                float v = sampler_get(&a, d);
                cr_assert_eq(v, sampler_get(&b, d), "stream %u index %u dim %u", s, idx, d);
                cr_assert_eq(v, sampler_get(&c, d));
                cr_assert_eq(v, sampler_get(&e, d));
                cr_assert_eq(v, sampler_get(&f, d), "%u streams: stream %u index %u dim %u", SAMPLER_STREAMS_MAPS, s,
                             idx, d);
                cr_assert_neq(v, sampler_get(&o, d), "streams %u and %u share a value", s, (s + 1) % SAMPLER_STREAMS);
                cr_assert_neq(v, sampler_get(&q, d));
            }
        }
}

/* Streams are independent: over many pixels, the means of a smooth integrand over 16
 * points of two streams are uncorrelated (each is an unbiased estimate: their average is
 * the integral), and the scrambles of the same index differ. */
Test(sampler, streams_are_independent)
{
    enum { PIXELS = 4000, N = 16 };
    for (uint32_t s = 1; s < SAMPLER_STREAMS; s++) {
        double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
        for (uint32_t px = 0; px < PIXELS; px++) {
            double m[2] = {0, 0};
            for (int w = 0; w < 2; w++)
                for (uint32_t i = 0; i < N; i++) {
                    struct sampler a = stream_sample(px, w ? s : 0, i, 4);
                    float u, v;
                    sampler_get_2d(&a, DIM_LENS_U, &u, &v);
                    m[w] += (u * v + sampler_get(&a, DIM_TIME)) / N;
                }
            sx += m[0], sy += m[1], sxx += m[0] * m[0], syy += m[1] * m[1], sxy += m[0] * m[1];
        }
        double cov = sxy / PIXELS - sx / PIXELS * sy / PIXELS;
        double r = cov / sqrt((sxx / PIXELS - sx * sx / PIXELS / PIXELS) * (syy / PIXELS - sy * sy / PIXELS / PIXELS));
        /* 4000 pairs: the correlation of independent estimates is within +-0.06 (3.8 sigma). */
        cr_assert(fabs(r) < 0.06, "streams 0 and %u: correlation %g", s, r);
        cr_assert(fabs(sx / PIXELS - 0.75) < 0.002 && fabs(sy / PIXELS - 0.75) < 0.002, "means %g %g", sx / PIXELS,
                  sy / PIXELS);
    }
}

/* A sobol pass's texture cells follow its stream's samples so far: block b of k samples
 * has the grid of the largest power of two <= (b + 1) k, and each of its samples lies
 * alone in its cell of that grid (the block is inside an aligned net of that size). */
Test(sampler, pixel_cells_follow_the_stream)
{
    const uint32_t k = 8;
    for (uint32_t b = 0; b < 12; b++)
        for (uint32_t s = 0; s < SAMPLER_STREAMS; s++) {
            uint32_t n = (b + 1) * k, p2 = 1;
            while (p2 * 2 <= n)
                p2 *= 2;
            static unsigned char seen[1024];
            memset(seen, 0, sizeof seen);
            for (uint32_t i = 0; i < k; i++) {
                struct sampler smp = stream_sample(3, s, b * k + i, k);
                uint32_t nx, ny;
                cr_assert(sampler_pixel_cells(&smp, &nx, &ny));
                cr_assert_eq(nx * ny, p2, "block %u: grid %ux%u, expected %u cells", b, nx, ny, p2);
                float u, v;
                sampler_get_2d(&smp, DIM_PIXEL_X, &u, &v);
                uint32_t c = (uint32_t)(v * (float)ny) * nx + (uint32_t)(u * (float)nx);
                cr_assert_eq(seen[c], 0, "block %u: two samples in cell %u", b, c);
                seen[c] = 1;
            }
        }
}
