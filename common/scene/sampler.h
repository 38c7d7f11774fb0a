/* The sample dimensions a camera path consumes, and the three samplers that fill them.
 * One fixed layout (pixel 2D, lens 2D, time 1D, then per bounce a fixed block) so a
 * dimension means the same thing in every pixel, sample and process. Every value is a pure
 * function of (seed, frame, pixel, sample index, dimension): no state, any call order.
 * Callers: integrator.c (camera ray and bounce loop), camera.c (lens, time). */
#ifndef BRUME_SAMPLER_H
#define BRUME_SAMPLER_H
#include <stdint.h>
#include "base/rng.h"
#include "scene/scene.h"

enum sampler_dim {
    DIM_PIXEL_X = 0,  /* 2D pair (x, y) */
    DIM_PIXEL_Y = 1,
    DIM_LENS_U = 2,   /* 2D pair (u, v); consumed only when the aperture is open */
    DIM_LENS_V = 3,
    DIM_TIME = 4,     /* 1D; consumed only when the shutter is open and something moves */
    DIM_BOUNCE_BASE = 5,
    /* per bounce, offsets from DIM_BOUNCE_BASE + bounce * DIM_PER_BOUNCE */
    DIM_LIGHT_PICK = 0, /* 1D */
    DIM_LIGHT_U = 1,    /* 2D pair (u, v) */
    DIM_LIGHT_V = 2,
    DIM_BSDF_U = 3,     /* 2D pair (u, v) */
    DIM_BSDF_V = 4,
    DIM_RR = 5,         /* 1D */
    DIM_PER_BOUNCE = 6
};

/* Replicate streams of the sobol sampler. A pixel's passes belong to R independent
 * streams: pass p is block p / R of stream p mod R, i.e. its k samples are the indices
 * [b k, (b + 1) k) of ONE Owen-scrambled Sobol sequence seeded by (pixel, stream), so a
 * stream's samples so far are a prefix of one sequence (Sobol's convergence kept) and the
 * streams' means are independent replicates (the batch means of the error estimate,
 * docs/adaptive.md). R is SAMPLER_STREAMS, or SAMPLER_STREAMS_MAPS with photon maps, whose
 * noise is smooth across pixels, so that its estimate needs more replicates. The
 * stratified and independent samplers give each pass its own randomisation. */
#ifndef SAMPLER_STREAMS
#define SAMPLER_STREAMS 2u
#endif
#define SAMPLER_STREAMS_MAPS 4u
#define SAMPLER_MAX_STREAMS 4u

/* Seeds of one dimension for one pixel pass: the index permutation, and for sobol the
 * seed of the hash for the deep digits and the exact flips of the first 6 digits as a
 * table indexed by the first 5 (byte p of the 4 words: the flips for prefix p). */
struct sampler_dim_seeds {
    uint32_t perm, tail;
    uint64_t flips[4];
};

enum { SAMPLER_CACHE_DIMS = 64 };

/* What all samples of one pixel share, built once per pixel (sampler_pixel_init) so that
 * a sample only permutes its index: the square-most grid, masks, the key prefix and,
 * filled lazily, the per-dimension seeds (a memo: values are the same with or without it).
 * Per thread, on the stack; never shared. */
struct sampler_pixel {
    enum sampler_type type;
    uint32_t spp;       /* points in one pass (>= 1) */
    uint32_t perm_mask; /* next power of two >= spp, minus 1: the permutations' domain */
    uint32_t nx, ny;    /* stratified: 2D grid nx * ny == spp */
    int log2_spp;       /* log2(spp) when spp is a power of two, else -1 */
    uint64_t prefix;    /* rng_key's (seed, frame, pixel) part */
    uint32_t streams;   /* R (sampler_pixel_init: SAMPLER_STREAMS) */
    uint32_t pass;      /* the pass whose seeds are memoized here (sampler_pixel_set_pass) */
    uint64_t pixel_key; /* hash of (seed, frame, pixel, stream) (stratified: pass) */
    uint64_t have;      /* bit d: seeds[d] filled */
    struct sampler_dim_seeds seeds[SAMPLER_CACHE_DIMS];
};

/* One sample of one pixel. key drives the independent sampler (and the jitter of the
 * stratified one); pixel_key seeds the per-pixel permutations and scrambles. */
struct sampler {
    enum sampler_type type;
    uint32_t index;     /* sample index within the pixel's pass: index < spp */
    uint32_t sidx;      /* sobol: index within the pass's stream (block * spp + index); others: index */
    uint32_t spp;
    uint32_t perm_mask;
    uint32_t nx, ny;
    int log2_spp;
    uint64_t key;       /* rng_key(seed, frame, pixel, sample); 0 for sobol (unused) */
    uint64_t pixel_key; /* hash of (seed, frame, pixel, stream) (stratified: pass) */
    struct sampler_pixel *cache; /* seeds memo of this pixel and pass, or NULL */
};

/* Names as the scene and command line spell them; returns -1 for an unknown name. */
int sampler_type_from_name(const char *name, enum sampler_type *out);

/* Sample `sample` of pixel `pixel` for passes of spp samples. Sample indices >= spp are
 * valid too: they are further passes (pass = sample / spp), for sobol further blocks of the
 * pass's stream, for stratified fresh permutations. */
struct sampler sampler_start_type(enum sampler_type type, uint64_t seed, uint32_t frame, uint64_t pixel,
                                  uint32_t sample, uint32_t spp);

/* The same samples, cheaper for many samples of one pixel: init once per pixel, then start
 * each sample from it. The sampler keeps a pointer to p (it memoizes seeds there). */
void sampler_pixel_init(struct sampler_pixel *p, enum sampler_type type, uint64_t seed, uint32_t frame,
                        uint64_t pixel, uint32_t spp);
void sampler_start_pixel_seeds_(struct sampler_pixel *p, uint32_t pass, struct sampler *s);
/* Index within the pass's stream of sample `index` of pass `pass`. */
static inline uint32_t stream_index(uint32_t pass, uint32_t index, uint32_t spp, uint32_t streams)
{
    return pass / streams * spp + index;
}
/* A number that tells a pixel's samples apart across all its passes, beside the sampler's
 * keys: sobol's key is 0 and its pixel_key the stream's (pass mod streams), so its index
 * within the stream; the other samplers' keys already differ per pass, so the index. Both
 * are what sidx holds. */
static inline uint32_t sampler_sample_id(const struct sampler *s) { return s->sidx; }
/* Inline: the independent sampler's start is one hash, less than a call. */
static inline struct sampler sampler_start_pixel(struct sampler_pixel *p, uint32_t sample)
{
    struct sampler s;
    s.type = p->type;
    s.spp = p->spp;
    s.perm_mask = p->perm_mask;
    s.nx = p->nx;
    s.ny = p->ny;
    s.log2_spp = p->log2_spp;
    uint32_t pass = s.log2_spp >= 0 ? sample >> s.log2_spp : sample / s.spp;
    s.index = sample - pass * s.spp;
    /* Only sobol reads sidx (its streams); the others keep the index there. */
    s.sidx = s.type == SAMPLER_SOBOL ? stream_index(pass, s.index, s.spp, p->streams) : s.index;
    /* The Sobol sampler draws nothing per sample: its key would be wasted work. */
    s.key = s.type == SAMPLER_SOBOL ? 0 : rng_mix64(p->prefix ^ sample);
    s.pixel_key = 0;
    s.cache = NULL;
    if (s.type != SAMPLER_INDEPENDENT)
        sampler_start_pixel_seeds_(p, pass, &s);
    return s;
}
/* Sets p's stream count (1..SAMPLER_MAX_STREAMS; init sets SAMPLER_STREAMS). */
void sampler_pixel_set_streams(struct sampler_pixel *p, uint32_t streams);
/* Moves p's memo to pass `pass` (samples [pass spp, (pass + 1) spp)). Values are the same
 * with or without it. */
void sampler_pixel_set_pass(struct sampler_pixel *p, uint32_t pass);

/* The independent sampler of earlier versions (same bits). */
static inline struct sampler sampler_start(uint64_t seed, uint32_t frame, uint64_t pixel, uint32_t sample)
{
    return sampler_start_type(SAMPLER_INDEPENDENT, seed, frame, pixel, sample, 1);
}

float sampler_get_slow_(const struct sampler *s, uint32_t dim);
void sampler_get_2d_slow_(const struct sampler *s, uint32_t dim0, float *u, float *v);

/* One value in [0, 1). For a component of a 2D pair it is that component of the pair's
 * 2D point, so calling it for both components equals sampler_get_2d (at twice the cost). */
static inline float sampler_get(const struct sampler *s, uint32_t dim)
{
    if (s->type == SAMPLER_INDEPENDENT)
        return rng_uniform(s->key, dim);
    return sampler_get_slow_(s, dim);
}

/* The 2D point of the pair starting at dim0 (DIM_PIXEL_X, DIM_LENS_U, or a bounce's
 * DIM_LIGHT_U / DIM_BSDF_U). */
static inline void sampler_get_2d(const struct sampler *s, uint32_t dim0, float *u, float *v)
{
    if (s->type == SAMPLER_INDEPENDENT) {
        *u = rng_uniform(s->key, dim0);
        *v = rng_uniform(s->key, dim0 + 1);
        return;
    }
    sampler_get_2d_slow_(s, dim0, u, v);
}

/* 1 with the grid (*nx cells along x, *ny along y) when every sample of a pass over s's
 * pixel lies alone in its own cell of that grid over the pixel (the DIM_PIXEL pair), else
 * 0: 1 x 1 at 1 spp (any sampler); stratified at any spp; sobol when spp is a power of
 * two (any aligned power-of-two block of a stream is a (0, m, 2)-net, scrambling and
 * shuffle included, so every elementary box of its size holds one). For sobol the grid is
 * that of the stream's samples so far, block b of k samples giving the largest power of
 * two <= (b + 1) k (a block lies inside an aligned block of that size), so that later
 * passes of a stream filter as finely as its samples so far and a pixel's textures
 * sharpen as its passes grow. Texture footprints are that cell (texshade_camera). */
static inline int sampler_pixel_cells(const struct sampler *s, uint32_t *nx, uint32_t *ny)
{
    *nx = *ny = 1;
    if (s->type == SAMPLER_SOBOL && s->log2_spp >= 0) {
        uint64_t n = (uint64_t)(s->sidx / s->spp + 1u) * s->spp;
        int m = 63 - __builtin_clzll(n);
        m = m > 24 ? 24 : m;
        *nx = 1u << (m / 2);
        *ny = 1u << (m - m / 2);
        return 1;
    }
    if (s->spp == 1)
        return 1;
    if (s->type == SAMPLER_INDEPENDENT || s->nx * s->ny != s->spp)
        return 0;
    *nx = s->nx, *ny = s->ny;
    return 1;
}

static inline uint32_t sampler_bounce_dim(uint32_t bounce, uint32_t offset)
{
    return DIM_BOUNCE_BASE + bounce * DIM_PER_BOUNCE + offset;
}

/* First dimension of the 2D pair holding dim, or dim itself when dim is 1D; *comp gets
 * the component (0 or 1) and the return of sampler_dim_is_2d says which case. */
static inline uint32_t sampler_dim_pair(uint32_t dim, uint32_t *comp, int *is_2d)
{
    uint32_t off;
    if (dim < DIM_BOUNCE_BASE) {
        if (dim == DIM_TIME) {
            *comp = 0;
            *is_2d = 0;
            return dim;
        }
        *comp = dim & 1u;
        *is_2d = 1;
        return dim & ~1u;
    }
    off = (dim - DIM_BOUNCE_BASE) % DIM_PER_BOUNCE;
    if (off == DIM_LIGHT_PICK || off == DIM_RR) {
        *comp = 0;
        *is_2d = 0;
        return dim;
    }
    *comp = (off - 1u) & 1u;
    *is_2d = 1;
    return dim - *comp;
}

/* Building blocks, exposed for tests. */
uint32_t sampler_permute(uint32_t i, uint32_t n, uint32_t seed); /* bijection on [0, n) */
/* Burley's (2020) shuffle of a sobol index: a nested uniform scramble of its bits (bit k
 * flipped by a hash of the bits above k), so every aligned block of 2^m indices maps onto
 * an aligned block of 2^m (a bijection of 32-bit indices). */
uint32_t sampler_shuffle(uint32_t i, uint32_t seed);

#endif
