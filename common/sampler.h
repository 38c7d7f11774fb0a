/* The sample dimensions a camera path consumes, and where each comes from. One fixed
 * layout (pixel, then per bounce a fixed block) so a dimension means the same thing in
 * every pixel, sample and process. Today every dimension is an independent uniform from
 * rng.h; stratified and Sobol samplers plug in here (issue: 5D sampling). */
#ifndef BRUME_SAMPLER_H
#define BRUME_SAMPLER_H
#include <stdint.h>
#include "rng.h"

enum sampler_dim {
    DIM_PIXEL_X = 0,
    DIM_PIXEL_Y = 1,
    DIM_LENS_U = 2,   /* reserved: thin lens */
    DIM_LENS_V = 3,
    DIM_TIME = 4,     /* reserved: motion blur */
    DIM_BOUNCE_BASE = 5,
    /* per bounce, offsets from DIM_BOUNCE_BASE + bounce * DIM_PER_BOUNCE */
    DIM_LIGHT_PICK = 0,
    DIM_LIGHT_U = 1,
    DIM_LIGHT_V = 2,
    DIM_BSDF_U = 3,
    DIM_BSDF_V = 4,
    DIM_RR = 5,
    DIM_PER_BOUNCE = 6
};

struct sampler {
    uint64_t key;
};

static inline struct sampler sampler_start(uint64_t seed, uint32_t frame, uint64_t pixel, uint32_t sample)
{
    struct sampler s = {rng_key(seed, frame, pixel, sample)};
    return s;
}

static inline float sampler_get(const struct sampler *s, uint32_t dim)
{
    return rng_uniform(s->key, dim);
}

static inline uint32_t sampler_bounce_dim(uint32_t bounce, uint32_t offset)
{
    return DIM_BOUNCE_BASE + bounce * DIM_PER_BOUNCE + offset;
}

#endif
