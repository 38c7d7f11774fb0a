/* Counter-based random numbers and the sampler: values are pure functions of their
 * coordinates (no hidden state, call order irrelevant), in [0, 1), and uniform (chi-square). */
#include <criterion/criterion.h>
#include <math.h>
#include "rng.h"
#include "sampler.h"

Test(rng, pure_function_of_coordinates)
{
    float a = rng_uniform(rng_key(7, 3, 12345, 9), 4);
    /* Interleave unrelated calls: the value must not change. */
    for (int i = 0; i < 100; i++)
        (void)rng_uniform(rng_key(i, i, i, i), i);
    float b = rng_uniform(rng_key(7, 3, 12345, 9), 4);
    cr_assert_eq(a, b);
    cr_assert_neq(rng_uniform(rng_key(7, 3, 12345, 9), 5), a);
    cr_assert_neq(rng_uniform(rng_key(8, 3, 12345, 9), 4), a);
    cr_assert_neq(rng_uniform(rng_key(7, 4, 12345, 9), 4), a);
    cr_assert_neq(rng_uniform(rng_key(7, 3, 12346, 9), 4), a);
    cr_assert_neq(rng_uniform(rng_key(7, 3, 12345, 10), 4), a);
}

Test(rng, consistent_values)
{
    /* Pinned values: a change here changes every image ever rendered; do it on purpose. */
    uint64_t k = rng_key(0, 0, 0, 0);
    cr_assert_eq(rng_bits(k, 0), rng_mix64(k ^ 0));
    struct sampler s = sampler_start(1, 0, 42, 3);
    cr_assert_eq(sampler_get(&s, DIM_PIXEL_X), rng_uniform(rng_key(1, 0, 42, 3), DIM_PIXEL_X));
}

Test(rng, range_half_open)
{
    for (uint32_t i = 0; i < 200000; i++) {
        float u = rng_uniform(rng_key(1, 0, i, i * 7), i % 13);
        cr_assert(u >= 0.0f && u < 1.0f, "u=%g", u);
    }
}

/* Chi-square over a 16x16 grid of 2D points from consecutive sample indices of one pixel,
 * and over dimension pairs deep in the path, 255 degrees of freedom. */
static double chi2_2d(uint32_t pixel, uint32_t dim0, uint32_t dim1)
{
    enum { B = 16, N = 256 * 200 };
    static unsigned hist[B * B];
    for (int i = 0; i < B * B; i++)
        hist[i] = 0;
    for (uint32_t i = 0; i < N; i++) {
        struct sampler s = sampler_start(99, 0, pixel, i);
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
    /* 255 dof: p = 0.001 critical value is about 330.5. */
    cr_assert_lt(chi2_2d(0, DIM_PIXEL_X, DIM_PIXEL_Y), 330.5);
    cr_assert_lt(chi2_2d(777, sampler_bounce_dim(2, DIM_BSDF_U), sampler_bounce_dim(2, DIM_BSDF_V)), 330.5);
    cr_assert_lt(chi2_2d(31337, sampler_bounce_dim(0, DIM_LIGHT_U), sampler_bounce_dim(5, DIM_RR)), 330.5);
}

Test(sampler, dimensions_do_not_overlap)
{
    cr_assert_eq(sampler_bounce_dim(0, 0), DIM_BOUNCE_BASE);
    cr_assert_eq(sampler_bounce_dim(1, 0), sampler_bounce_dim(0, DIM_PER_BOUNCE - 1) + 1);
    cr_assert_gt((int)DIM_BOUNCE_BASE, (int)DIM_TIME);
}
