/* Counter-based random numbers: every value is a pure function of its coordinates
 * (seed, frame, pixel, sample index, dimension), so nothing random lives in a thread or
 * a worker and any tile can be re-rendered anywhere with the same bits. The mixer is
 * SplitMix64's finaliser chained over the coordinates; inline because it sits in the
 * innermost loop. */
#ifndef BRUME_RNG_H
#define BRUME_RNG_H
#include <stdint.h>

static inline uint64_t rng_mix64(uint64_t z)
{
    z += 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/* Key of one sample stream: (seed, frame, pixel, sample). */
static inline uint64_t rng_key(uint64_t seed, uint32_t frame, uint64_t pixel, uint32_t sample)
{
    uint64_t h = rng_mix64(seed ^ 0x6272756d65ull);
    h = rng_mix64(h ^ frame);
    h = rng_mix64(h ^ pixel);
    return rng_mix64(h ^ sample);
}

static inline uint64_t rng_bits(uint64_t key, uint32_t dim)
{
    return rng_mix64(key ^ ((uint64_t)dim * 0xd1b54a32d192ed03ull));
}

/* Uniform in [0, 1): 24 random bits, so the result is exact in float and never 1. */
static inline float rng_uniform(uint64_t key, uint32_t dim)
{
    return (float)(rng_bits(key, dim) >> 40) * 0x1p-24f;
}

#endif
