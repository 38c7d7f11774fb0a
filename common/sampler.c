/* Stratified and Owen-scrambled Sobol samplers (sampler.h). Each 1D dimension and each 2D
 * pair gets its own per-pixel hashed permutation of the sample index (Cook 1984's random
 * pairing; pbrt's PaddedSobol), so pairs are stratified within and decorrelated across.
 * Pure functions of their arguments: no tables written at run time, no state. */
#include "sampler.h"
#include <math.h>
#include <string.h>

static const char *const names[SAMPLER_COUNT_] = {"independent", "stratified", "sobol"};

int sampler_type_from_name(const char *name, enum sampler_type *out)
{
    for (int i = 0; i < SAMPLER_COUNT_; i++)
        if (strcmp(name, names[i]) == 0) {
            *out = (enum sampler_type)i;
            return 0;
        }
    return -1;
}

const char *sampler_type_name(enum sampler_type t)
{
    return (unsigned)t < SAMPLER_COUNT_ ? names[t] : "?";
}

struct sampler sampler_start_type(enum sampler_type type, uint64_t seed, uint32_t frame, uint64_t pixel,
                                  uint32_t sample, uint32_t spp)
{
    struct sampler s;
    s.type = type;
    s.key = rng_key(seed, frame, pixel, sample);
    s.spp = spp ? spp : 1;
    s.index = sample % s.spp;
    s.nx = s.ny = 1;
    s.pixel_key = 0;
    if (type == SAMPLER_INDEPENDENT)
        return s;
    /* Later passes (index >= spp) get fresh permutations and scrambles. */
    s.pixel_key = rng_key(seed ^ 0x5a4d504c52ull, frame, pixel, sample / s.spp);
    if (type == SAMPLER_STRATIFIED) {
        /* The most square grid with exactly spp cells, so every cell gets one sample. */
        uint32_t nx = (uint32_t)sqrt((double)s.spp);
        while (nx > 1 && s.spp % nx != 0)
            nx--;
        s.nx = nx;
        s.ny = s.spp / nx;
    }
    return s;
}

/* Kensler, "Correlated Multi-Jittered Sampling" (2013): a hashed bijection on [0, n) for
 * any n, by cycle walking inside the next power of two. */
uint32_t sampler_permute(uint32_t i, uint32_t n, uint32_t p)
{
    if (n <= 1)
        return 0;
    uint32_t w = n - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    do {
        i ^= p;
        i *= 0xe170893du;
        i ^= p >> 16;
        i ^= (i & w) >> 4;
        i ^= p >> 8;
        i *= 0x0929eb3fu;
        i ^= p >> 23;
        i ^= (i & w) >> 1;
        i *= 1u | p >> 27;
        i *= 0x6935fa69u;
        i ^= (i & w) >> 11;
        i *= 0x74dcb303u;
        i ^= (i & w) >> 2;
        i *= 0x9e501cc3u;
        i ^= (i & w) >> 2;
        i *= 0xc860a3dfu;
        i &= w;
        i ^= i >> 5;
    } while (i >= n);
    return (i + p) % n;
}

static uint32_t reverse_bits(uint32_t x)
{
    x = (x << 16) | (x >> 16);
    x = ((x & 0x00ff00ffu) << 8) | ((x & 0xff00ff00u) >> 8);
    x = ((x & 0x0f0f0f0fu) << 4) | ((x & 0xf0f0f0f0u) >> 4);
    x = ((x & 0x33333333u) << 2) | ((x & 0xccccccccu) >> 2);
    x = ((x & 0x55555555u) << 1) | ((x & 0xaaaaaaaau) >> 1);
    return x;
}

/* Burley, "Practical Hash-based Owen Scrambling" (JCGT 2020): each output digit is flipped
 * by a hash of the digits above it, so elementary intervals map onto elementary intervals and
 * a (0,m,2)-net stays one. */
static uint32_t hash32(uint32_t x)
{
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

uint32_t sampler_owen_scramble(uint32_t x, uint32_t seed)
{
    /* The hash below flips digit k from seed bits <= k only, so its first digits have few
     * variants and neighbouring cells scramble alike. Exact Owen scrambling (one hashed
     * flip per tree node) on the first OWEN_EXACT digits fixes that; composed with the
     * hash it is still a nested uniform scramble. */
    enum { OWEN_EXACT = 6 };
    uint32_t flips = 0;
    for (uint32_t k = 0; k < OWEN_EXACT; k++) {
        uint32_t node = (1u << k) | (k ? x >> (32 - k) : 0u);
        flips |= (hash32(seed ^ (node * 0x9e3779b9u)) & 1u) << (31 - k);
    }
    x ^= flips;
    x = reverse_bits(x);
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return reverse_bits(x);
}

/* The first two Sobol dimensions: van der Corput, and the one whose direction numbers are
 * v_k = v_{k-1} ^ (v_{k-1} >> 1). Together their first 2^m points form a (0,m,2)-net. */
uint32_t sampler_sobol_bits(uint32_t index, uint32_t dim)
{
    if (dim == 0)
        return reverse_bits(index);
    uint32_t r = 0, v = 0x80000000u;
    for (; index; index >>= 1, v ^= v >> 1)
        if (index & 1u)
            r ^= v;
    return r;
}

/* 24 bits: exact in float and never 1. */
static float bits_to_unit(uint32_t b)
{
    return (float)(b >> 8) * 0x1p-24f;
}

/* (cell + jitter) / n, kept strictly inside the cell after rounding to float. */
static float jitter_cell(uint32_t cell, uint32_t n, float jitter)
{
    float f = (float)(((double)cell + (double)jitter) / (double)n);
    while (f > 0.0f && (double)f * (double)n >= (double)cell + 1.0)
        f = nextafterf(f, 0.0f);
    return f;
}

/* Hashes per (pixel, pair): salts keep permutation and scramble seeds unrelated. */
static uint32_t pair_seed(const struct sampler *s, uint32_t dim, uint64_t salt)
{
    return (uint32_t)rng_bits(s->pixel_key ^ salt, dim);
}

#define SALT_PERM 0x7065726dull
#define SALT_SCRAMBLE 0x7363726d00000000ull

static float get_1d(const struct sampler *s, uint32_t dim)
{
    uint32_t j = sampler_permute(s->index, s->spp, pair_seed(s, dim, SALT_PERM));
    switch (s->type) {
    case SAMPLER_STRATIFIED:
        return jitter_cell(j, s->spp, rng_uniform(s->key, dim));
    case SAMPLER_SOBOL:
        return bits_to_unit(sampler_owen_scramble(sampler_sobol_bits(j, 0), pair_seed(s, dim, SALT_SCRAMBLE)));
    default:
        return rng_uniform(s->key, dim);
    }
}

/* Component comp (or both when u and v are non-NULL) of the pair at dim0. */
static void get_pair(const struct sampler *s, uint32_t dim0, float *u, float *v)
{
    uint32_t j = sampler_permute(s->index, s->spp, pair_seed(s, dim0, SALT_PERM));
    switch (s->type) {
    case SAMPLER_STRATIFIED:
        if (u)
            *u = jitter_cell(j % s->nx, s->nx, rng_uniform(s->key, dim0));
        if (v)
            *v = jitter_cell(j / s->nx, s->ny, rng_uniform(s->key, dim0 + 1));
        return;
    case SAMPLER_SOBOL:
        if (u)
            *u = bits_to_unit(sampler_owen_scramble(sampler_sobol_bits(j, 0), pair_seed(s, dim0, SALT_SCRAMBLE)));
        if (v)
            *v = bits_to_unit(sampler_owen_scramble(sampler_sobol_bits(j, 1), pair_seed(s, dim0 + 1, SALT_SCRAMBLE)));
        return;
    default:
        if (u)
            *u = rng_uniform(s->key, dim0);
        if (v)
            *v = rng_uniform(s->key, dim0 + 1);
        return;
    }
}

float sampler_get_slow_(const struct sampler *s, uint32_t dim)
{
    uint32_t comp;
    int is_2d;
    uint32_t d0 = sampler_dim_pair(dim, &comp, &is_2d);
    if (!is_2d)
        return get_1d(s, dim);
    float r = 0.0f;
    get_pair(s, d0, comp == 0 ? &r : NULL, comp == 1 ? &r : NULL);
    return r;
}

void sampler_get_2d_slow_(const struct sampler *s, uint32_t dim0, float *u, float *v)
{
    get_pair(s, dim0, u, v);
}
