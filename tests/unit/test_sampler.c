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
                                {0x1.3add8p-4f, 0x1.212466p-1f, 0x1.fa2b34p-1f, 0x1.5e1118p-3f}};
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
