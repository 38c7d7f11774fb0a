/* Stratified and Owen-scrambled Sobol samplers (sampler.h). Each 1D dimension and each 2D
 * pair gets its own per-pixel hashed shuffle of the sample index (Cook 1984's random
 * pairing; pbrt's PaddedSobol; for sobol Burley 2020's nested uniform shuffle, which keeps
 * every power-of-two block of a stream a (0,m,2)-net, so streams extend), so pairs are
 * stratified within and decorrelated across. Pure functions of their arguments: no tables
 * written at run time, no state. Hot: a path asks for ~10 pairs per sample, so a pair costs
 * a few hashes and no division, sqrt or loop over digits when spp is a power of two
 * (sampler_start_type precomputes the grid). */
#include "scene/sampler.h"
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

/* Domain of the pass key, kept apart from the sample keys (whose inputs are < 2^32). */
#define PASS_DOMAIN (0x5a4d504c52ull << 32)

/* rng_key's chain up to the sample, so that the sample key and the pass key share it. */
static uint64_t key_prefix(uint64_t seed, uint32_t frame, uint64_t pixel)
{
    return rng_mix64(rng_mix64(rng_mix64(seed ^ 0x6272756d65ull) ^ frame) ^ pixel);
}

/* The key of a pixel's pass: sobol's passes share their stream's (a stream is one
 * sequence), the stratified sampler's each have their own. */
static inline uint64_t pass_key(uint64_t prefix, enum sampler_type type, uint32_t pass, uint32_t streams)
{
    return rng_mix64(prefix ^ PASS_DOMAIN ^ (type == SAMPLER_SOBOL ? pass % streams : pass));
}

/* The next power of two >= n, minus 1. */
static inline uint32_t pow2_mask(uint32_t n)
{
    uint32_t w = n ? n - 1 : 0;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    return w;
}

/* The grid and masks for spp, worked out once per pixel so that drawing a value needs no
 * sqrt and, for powers of two, no division. */
static void setup_grid(uint32_t spp, enum sampler_type type, uint32_t *perm_mask, uint32_t *nx, uint32_t *ny,
                       int *log2_spp)
{
    *perm_mask = pow2_mask(spp);
    *nx = *ny = 1;
    *log2_spp = -1;
    if ((spp & (spp - 1)) == 0) {
        /* Powers of two (the usual case): the square-most grid by shifts. */
        int k = __builtin_ctz(spp);
        *log2_spp = k;
        *nx = 1u << (k / 2);
        *ny = 1u << (k - k / 2);
    } else if (type == SAMPLER_STRATIFIED) {
        /* The most square grid with exactly spp cells, so every cell gets one sample. */
        uint32_t x = (uint32_t)sqrt((double)spp);
        while (x > 1 && spp % x != 0)
            x--;
        *nx = x;
        *ny = spp / x;
    }
}

void sampler_pixel_init(struct sampler_pixel *p, enum sampler_type type, uint64_t seed, uint32_t frame,
                        uint64_t pixel, uint32_t spp)
{
    p->type = type;
    p->spp = spp ? spp : 1;
    setup_grid(p->spp, type, &p->perm_mask, &p->nx, &p->ny, &p->log2_spp);
    p->prefix = key_prefix(seed, frame, pixel);
    p->streams = SAMPLER_STREAMS;
    p->pass = 0;
    p->pixel_key = pass_key(p->prefix, type, 0, p->streams);
    p->have = 0;
}

void sampler_pixel_set_streams(struct sampler_pixel *p, uint32_t streams)
{
    p->streams = streams >= 1 && streams <= SAMPLER_MAX_STREAMS ? streams : SAMPLER_STREAMS;
    p->pixel_key = pass_key(p->prefix, p->type, p->pass, p->streams);
    p->have = 0;
}

void sampler_pixel_set_pass(struct sampler_pixel *p, uint32_t pass)
{
    if (pass == p->pass)
        return;
    p->pass = pass;
    p->pixel_key = pass_key(p->prefix, p->type, pass, p->streams);
    p->have = 0;
}

void sampler_start_pixel_seeds_(struct sampler_pixel *p, uint32_t pass, struct sampler *s)
{
    /* Seeds memoized only for the pass p holds. */
    s->pixel_key = pass == p->pass ? p->pixel_key : pass_key(p->prefix, s->type, pass, p->streams);
    s->cache = pass == p->pass ? p : NULL;
}

struct sampler sampler_start_type(enum sampler_type type, uint64_t seed, uint32_t frame, uint64_t pixel,
                                  uint32_t sample, uint32_t spp)
{
    struct sampler s;
    s.type = type;
    s.spp = spp ? spp : 1;
    setup_grid(s.spp, type, &s.perm_mask, &s.nx, &s.ny, &s.log2_spp);
    s.index = sample % s.spp;
    s.sidx = type == SAMPLER_SOBOL ? stream_index(sample / s.spp, s.index, s.spp, SAMPLER_STREAMS) : s.index;
    uint64_t prefix = key_prefix(seed, frame, pixel);
    s.key = type == SAMPLER_SOBOL ? 0 : rng_mix64(prefix ^ sample);
    s.pixel_key = type == SAMPLER_INDEPENDENT ? 0 : pass_key(prefix, type, sample / s.spp, SAMPLER_STREAMS);
    s.cache = NULL;
    return s;
}

/* Kensler, "Correlated Multi-Jittered Sampling" (2013): a hashed bijection on [0, n) for
 * any n, by cycle walking inside the power of two w + 1 >= n (which never walks when n is
 * that power, and then needs no division). */
static inline uint32_t permute_in(uint32_t i, uint32_t n, uint32_t w, uint32_t p)
{
    if (n <= 1)
        return 0;
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
    return n == w + 1 ? (i + p) & w : (i + p) % n;
}

uint32_t sampler_permute(uint32_t i, uint32_t n, uint32_t p)
{
    return permute_in(i, n, pow2_mask(n), p);
}

static inline uint32_t reverse_bits(uint32_t x)
{
    x = __builtin_bswap32(x);
    x = ((x & 0x0f0f0f0fu) << 4) | ((x & 0xf0f0f0f0u) >> 4);
    x = ((x & 0x33333333u) << 2) | ((x & 0xccccccccu) >> 2);
    x = ((x & 0x55555555u) << 1) | ((x & 0xaaaaaaaau) >> 1);
    return x;
}

/* Everything below works on bit-reversed values: bit k is the k-th binary digit after
 * the point, so "digits above k" are the bits below k, and one reversal at the end gives
 * the value. */

/* Sobol dimension 1 (direction numbers v_k = v_{k-1} ^ (v_{k-1} >> 1), i.e. the Pascal
 * matrix mod 2), reversed: digit t is the parity of index bits i with t a subset of i
 * (Lucas), a superset-sum over bit positions done in 5 shift-xor steps, no loop. */
static inline uint32_t sobol1_rev(uint32_t j)
{
    j ^= (j >> 1) & 0x55555555u;
    j ^= (j >> 2) & 0x33333333u;
    j ^= (j >> 4) & 0x0f0f0f0fu;
    j ^= (j >> 8) & 0x00ff00ffu;
    j ^= (j >> 16) & 0x0000ffffu;
    return j;
}

/* Nested uniform (Owen) scramble of a reversed value. The first 6 digits are scrambled
 * exactly: one independent random flip per node of the binary tree, the 63 nodes being
 * bits 1..63 of tree (node = 2^k + the k digits above), so even the coarsest cells get
 * all 2^63 scramble variants. Deeper digits go through Vegdahl's improved Laine-Karras hash
 * ("Building a better LK hash", 2021; Burley, JCGT 2020), where each bit is flipped by a
 * function of the bits below it: still nested uniform, so a (0,m,2)-net stays one. */
static inline uint32_t top_flips(uint32_t r, uint64_t tree)
{
    uint32_t f = (uint32_t)(tree >> 1) & 1u;
    f |= ((uint32_t)(tree >> (2u | (r & 1u))) & 1u) << 1;
    f |= ((uint32_t)(tree >> (4u | (r & 3u))) & 1u) << 2;
    f |= ((uint32_t)(tree >> (8u | (r & 7u))) & 1u) << 3;
    f |= ((uint32_t)(tree >> (16u | (r & 15u))) & 1u) << 4;
    f |= ((uint32_t)(tree >> (32u | (r & 31u))) & 1u) << 5;
    return f;
}

static inline uint32_t owen_tail_rev(uint32_t r, uint32_t seed)
{
    r ^= r * 0x3d20adeau;
    r += seed;
    r *= (seed >> 16) | 1u;
    r ^= r * 0x05526c56u;
    r ^= r * 0x53a22864u;
    return r;
}

static inline uint32_t owen_rev(uint32_t r, uint64_t tree, uint32_t seed)
{
    return owen_tail_rev(r ^ top_flips(r, tree), seed);
}

/* The same flips from the table of sampler_dim_seeds (one lookup instead of six). */
static inline uint32_t owen_rev_table(uint32_t r, const uint64_t flips[4], uint32_t seed)
{
    uint32_t f = (uint32_t)(flips[(r >> 3) & 3u] >> ((r & 7u) * 8u)) & 0x3fu;
    return owen_tail_rev(r ^ f, seed);
}

/* Bit b of x (8 bits) to bit 0 of byte b. */
static inline uint64_t spread8(uint64_t x)
{
    uint64_t y = ((x & 0xffu) * 0x0101010101010101ull) & 0x8040201008040201ull;
    return ((y + 0x7f7f7f7f7f7f7f7full) >> 7) & 0x0101010101010101ull;
}

/* top_flips(p, tree) for the 32 prefixes p, as bytes: bit k of byte p is tree bit
 * 2^k + (p mod 2^k), so digit k's pattern repeats every 2^k bytes. */
static void flips_table(uint64_t tree, uint64_t out[4])
{
    uint64_t low = (((tree >> 1) & 1u) * 0x0101010101010101ull) | spread8(((tree >> 2) & 3u) * 0x55u) << 1 |
                   spread8(((tree >> 4) & 15u) * 0x11u) << 2 | spread8(tree >> 8) << 3;
    uint64_t d4[2] = {spread8(tree >> 16) << 4, spread8(tree >> 24) << 4};
    for (int q = 0; q < 4; q++)
        out[q] = low | d4[q & 1] | spread8(tree >> (32 + 8 * q)) << 5;
}

/* 24 bits of a reversed value: exact in float and never 1. */
static inline float rev_to_unit(uint32_t r)
{
    return (float)(reverse_bits(r) >> 8) * 0x1p-24f;
}

/* Cell `cell` of 2^k plus a jitter of the m's top 24 - k bits: a 24-bit fraction, exact
 * in float, so strictly inside the cell with no rounding to correct. */
static inline float jitter_cell_pow2(uint32_t cell, int k, uint32_t m)
{
    return (float)(int32_t)((cell << (24 - k)) | (m >> k)) * 0x1p-24f;
}

/* (cell + jitter) / n, kept strictly inside the cell after rounding to float. */
static float jitter_cell(uint32_t cell, uint32_t n, uint32_t m)
{
    float f = (float)(((double)cell + (double)m * 0x1p-24) / (double)n);
    while (f > 0.0f && (double)f * (double)n >= (double)cell + 1.0)
        f = nextafterf(f, 0.0f);
    return f;
}

/* Per-(pixel, dimension) hashes; salts keep the permutation and tree seeds unrelated. */
#define SALT_PERM 0x7065726dull
#define SALT_TREE 0x7363726d00000000ull

static inline uint64_t dim_tree(const struct sampler *s, uint32_t d)
{
    return rng_bits(s->pixel_key ^ SALT_TREE, d);
}

/* A 2D component or 1D value of sobol at reversed index r for dimension d: from the memo
 * when there is one, else straight from the hashes (the same bits). */
static inline const struct sampler_dim_seeds *cached_seeds(const struct sampler *s, uint32_t d)
{
    struct sampler_pixel *c = s->cache;
    if (!c || d >= SAMPLER_CACHE_DIMS)
        return NULL;
    struct sampler_dim_seeds *e = &c->seeds[d];
    if (!((c->have >> d) & 1u)) {
        uint64_t a = rng_bits(s->pixel_key ^ SALT_PERM, d);
        e->perm = (uint32_t)a;
        e->tail = (uint32_t)(a >> 32);
        if (s->type == SAMPLER_SOBOL)
            flips_table(dim_tree(s, d), e->flips);
        c->have |= 1ull << d;
    }
    return e;
}

/* Permutation seed (low half) and sobol tail seed (high half) of dimension d. */
static inline uint64_t perm_tail(const struct sampler *s, uint32_t d, const struct sampler_dim_seeds *e)
{
    return e ? (uint64_t)e->tail << 32 | e->perm : rng_bits(s->pixel_key ^ SALT_PERM, d);
}

static inline float sobol_value(const struct sampler *s, uint32_t d, uint32_t r, const struct sampler_dim_seeds *e,
                                uint32_t tail)
{
    return rev_to_unit(e ? owen_rev_table(r, e->flips, tail) : owen_rev(r, dim_tree(s, d), tail));
}

uint32_t sampler_shuffle(uint32_t i, uint32_t seed)
{
    return reverse_bits(owen_tail_rev(reverse_bits(i), seed));
}

/* The point a 1D dimension or 2D pair takes for this sample: sobol shuffles the stream
 * index (blocks of 2^m stay blocks: every power-of-two prefix of a stream, and every pass
 * of a power-of-two size, is a (0,m,2)-net); stratified permutes within the pass. */
static inline uint32_t index_for(const struct sampler *s, uint32_t perm_seed)
{
    if (s->type == SAMPLER_SOBOL)
        return sampler_shuffle(s->sidx, perm_seed);
    return permute_in(s->index, s->spp, s->perm_mask, perm_seed);
}

static float get_1d(const struct sampler *s, uint32_t dim)
{
    const struct sampler_dim_seeds *e = cached_seeds(s, dim);
    uint64_t pt = perm_tail(s, dim, e);
    uint32_t j = index_for(s, (uint32_t)pt);
    switch (s->type) {
    case SAMPLER_STRATIFIED: {
        uint32_t m = (uint32_t)(rng_bits(s->key, dim) >> 40);
        return s->log2_spp >= 0 ? jitter_cell_pow2(j, s->log2_spp, m) : jitter_cell(j, s->spp, m);
    }
    case SAMPLER_SOBOL:
        return sobol_value(s, dim, j, e, (uint32_t)(pt >> 32));
    default:
        return rng_uniform(s->key, dim);
    }
}

/* The pair at dim0: both components, or only the one whose pointer is non-NULL. */
static inline void get_pair(const struct sampler *s, uint32_t dim0, float *u, float *v)
{
    const struct sampler_dim_seeds *e0 = cached_seeds(s, dim0);
    uint64_t pt0 = perm_tail(s, dim0, e0);
    uint32_t j = index_for(s, (uint32_t)pt0);
    switch (s->type) {
    case SAMPLER_STRATIFIED: {
        /* Correlated multi-jittered (Kensler 2013): sample j takes cell (c, r) of the
         * nx x ny grid, and inside it the sub-column permute(r) of ny and the sub-row
         * permute(c) of nx, so each grid cell holds one sample and so does each of the spp
         * strata of either 1D projection (edges, which are nearly 1D, converge faster).
         * One hash jitters both components (24 bits each) inside their fine stratum. */
        uint64_t b = rng_bits(s->key, dim0);
        uint32_t mu = (uint32_t)(b >> 40), mv = (uint32_t)(b >> 16) & 0xffffffu;
        uint32_t p = (uint32_t)pt0;
        if (s->log2_spp >= 0) {
            int kx = s->log2_spp / 2;
            uint32_t c = j & (s->nx - 1u), r = j >> kx;
            if (u)
                *u = jitter_cell_pow2(c * s->ny + permute_in(r, s->ny, s->ny - 1u, p * 0x63d83595u), s->log2_spp, mu);
            if (v)
                *v = jitter_cell_pow2(r * s->nx + permute_in(c, s->nx, s->nx - 1u, p * 0xa511e9b3u), s->log2_spp, mv);
        } else {
            uint32_t c = j % s->nx, r = j / s->nx;
            if (u)
                *u = jitter_cell(c * s->ny + permute_in(r, s->ny, pow2_mask(s->ny), p * 0x63d83595u), s->spp, mu);
            if (v)
                *v = jitter_cell(r * s->nx + permute_in(c, s->nx, pow2_mask(s->nx), p * 0xa511e9b3u), s->spp, mv);
        }
        return;
    }
    case SAMPLER_SOBOL:
        if (u)
            *u = sobol_value(s, dim0, j, e0, (uint32_t)(pt0 >> 32));
        if (v) {
            const struct sampler_dim_seeds *e1 = cached_seeds(s, dim0 + 1);
            *v = sobol_value(s, dim0 + 1, sobol1_rev(j), e1, (uint32_t)(perm_tail(s, dim0 + 1, e1) >> 32));
        }
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
