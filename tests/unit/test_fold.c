/* Unit tests for the pass fold (master/fold.c): a tile's passes arriving in any order give
 * the same bits as in pass order (folded as they come, kept until the last is in, or kept
 * and folded in batches), a pass without samples is left out, and the result is
 * the batch-means mean and variance of the pass means. Run by `make unit`. */
#include <criterion/criterion.h>
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "master/fold.h"
#include "render/integrator.h"

#define PASSES 5u

/* The layout of a w x h image in tiles of `tile` px. */
static void desc_of(struct image_desc *d, uint32_t w, uint32_t h, uint32_t tile)
{
    struct render_settings rs;
    memset(&rs, 0, sizeof rs);
    rs.width = w;
    rs.height = h;
    rs.tile_size = tile;
    tile_image_desc(d, &rs);
}

static void make_desc(struct image_desc *d) { desc_of(d, 10, 7, 4); }

/* Pass p's channels for tile t: values that differ in their low bits and in magnitude, so
 * that a fold in another order would round differently. */
static void pass_pixels(uint32_t t, uint32_t p, size_t n, float *px)
{
    for (size_t i = 0; i < n; i++) {
        float *c = &px[i * TILE_NUM_CHANNELS];
        /* Some pixels far off on some passes, by turns up and down (in each stream): their
         * sums in double cancel and leave rounding errors a float sees, so that only the
         * one order of additions gives these bits. */
        int big = p % 3 == 0 && i % 5 == 1;
        for (int k = 0; k < 3; k++)
            c[CH_R + k] = big ? (p / 6 % 2 ? -3e13f : 3e13f)
                              : (float)(0.1 + 0.37 * sin(1.3 * (double)(t * 131 + p * 17 + i * 7 + k)) + 0.001 * p);
        c[CH_A] = (i + p) % 7 == 0 ? PASS_ALPHA_NONE : 0.25f * (float)((i + p) % 5) / 4.0f;
        c[CH_VAR_R] = c[CH_VAR_G] = c[CH_VAR_B] = 0.0f;
    }
}

static void fold_in_order_n(const struct image_desc *d, uint32_t passes, const uint32_t *order, float *out,
                            struct tile_stats *st)
{
    struct fold *f = fold_new(d, passes, 3, SAMPLER_STREAMS);
    uint32_t tiles = imgio_tiles_x(d) * imgio_tiles_y(d);
    float px[16 * TILE_NUM_CHANNELS];
    memset(st, 0, sizeof *st);
    uint32_t done = 0;
    for (uint32_t i = 0; i < tiles * passes; i++) {
        uint32_t u = order[i], t = u % tiles, p = u / tiles;
        uint32_t x0, y0, w, h;
        imgio_tile_rect(d, t % imgio_tiles_x(d), t / imgio_tiles_x(d), &x0, &y0, &w, &h);
        pass_pixels(t, p, (size_t)w * h, px);
        int fin = fold_add(f, t, p, px, out + (size_t)t * 16 * FOLD_NUM_CHANNELS, st);
        done += (uint32_t)fin;
    }
    cr_assert_eq(done, tiles, "every tile final exactly once");
    fold_free(&f);
    cr_assert_null(f);
}

static void fold_in_order(const struct image_desc *d, const uint32_t *order, float *out, struct tile_stats *st)
{
    fold_in_order_n(d, PASSES, order, out, st);
}

/* The master's pool way: fold_add_take (every other unit as a buffer taken over,
 * fold_add_take_own, as the checker pool hands them), then fold_run of each batch with one
 * scratch. A batch that is not its tile's last goes back (fold_units_return) at once, or,
 * with `pool` > 0, is held back like an item in the pool until `pool` batches are out, then
 * one of them (chosen by x) goes back first; the next batch it brings is folded too. The
 * most units kept at once goes to *max_kept. */
static void fold_taken_n(const struct image_desc *d, uint32_t passes, const uint32_t *order, float *out,
                         struct tile_stats *st, uint32_t pool, uint64_t x, uint32_t *max_kept)
{
    struct fold *f = fold_new(d, passes, 3, SAMPLER_STREAMS);
    uint32_t tiles = imgio_tiles_x(d) * imgio_tiles_y(d), done = 0, out_n = 0, kept = 0;
    struct fold_units *held[64];
    float px[16 * TILE_NUM_CHANNELS];
    void *scratch = NULL;
    size_t scratch_size = 0;
    memset(st, 0, sizeof *st);
    for (uint32_t i = 0; i <= tiles * passes; i++) {
        struct fold_units *fu = NULL;
        if (i < tiles * passes) {
            uint32_t u = order[i], t = u % tiles, p = u / tiles;
            uint32_t x0, y0, w, h;
            imgio_tile_rect(d, t % imgio_tiles_x(d), t / imgio_tiles_x(d), &x0, &y0, &w, &h);
            pass_pixels(t, p, (size_t)w * h, px);
            if (i % 2) {
                size_t n = fold_unit_floats(f, t);
                cr_assert_eq(n, (size_t)w * h * TILE_NUM_CHANNELS, "a unit's values: its tile's pixels x channels");
                float *own = malloc(sizeof(float) * n);
                memcpy(own, px, sizeof(float) * n);
                fu = fold_add_take_own(f, t, p, &own);
                cr_assert_null(own, "taken over");
            } else
                fu = fold_add_take(f, t, p, px);
        }
        /* Fold what is due; hold batches back as the pool would, and at the end (and
         * whenever the pool is full) give them back, each bringing its tile's next. */
        for (;;) {
            if (fold_kept_units(f) > kept)
                kept = fold_kept_units(f);
            if (fu) {
                uint32_t t = fold_units_tile(fu);
                fold_run(f, fu, &scratch, &scratch_size, out + (size_t)t * 16 * FOLD_NUM_CHANNELS, st);
                if (fold_units_final(fu)) {
                    fold_units_free(&fu);
                    cr_assert_null(fu);
                    done++;
                    continue;
                }
                if (pool == 0) {
                    fu = fold_units_return(f, &fu);
                    continue;
                }
                cr_assert(out_n < 64);
                held[out_n++] = fu;
                fu = NULL;
            }
            if (out_n == 0 || (out_n < pool && i < tiles * passes))
                break;
            x = x * 6364136223846793005ull + 1442695040888963407ull;
            uint32_t k = (uint32_t)((x >> 33) % out_n);
            struct fold_units *back = held[k];
            held[k] = held[--out_n];
            fu = fold_units_return(f, &back);
            cr_assert_null(back);
        }
    }
    cr_assert_eq(done, tiles, "every tile taken exactly once");
    cr_assert_eq(fold_kept_units(f), 0, "no unit left kept");
    if (max_kept)
        *max_kept = kept;
    free(scratch);
    fold_free(&f);
}

static void fold_taken(const struct image_desc *d, const uint32_t *order, float *out, struct tile_stats *st)
{
    fold_taken_n(d, PASSES, order, out, st, 0, 0, NULL);
}

/* order[0..n-1] shuffled (Fisher-Yates with a fixed LCG in *x). */
static void shuffle(uint32_t *order, uint32_t n, uint64_t *x)
{
    for (uint32_t i = n - 1; i > 0; i--) {
        *x = *x * 6364136223846793005ull + 1442695040888963407ull;
        uint32_t j = (uint32_t)((*x >> 33) % (i + 1));
        uint32_t tmp = order[i];
        order[i] = order[j];
        order[j] = tmp;
    }
}

/* Over FOLD_KEEP_ALL_PASSES passes a tile's units are folded in batches as they come
 * (fold_add_take), whatever order they arrive and batches come back in: the same bits as
 * the plain fold, and with units coming pass by pass (the master's order) only a few
 * copies of each tile are kept at once, not every pass of it. */
Test(fold, batches_give_the_same_bits_and_keep_few_copies)
{
    const uint32_t passes = 3 * FOLD_KEEP_ALL_PASSES + 5;
    struct image_desc d;
    make_desc(&d);
    uint32_t tiles = imgio_tiles_x(&d) * imgio_tiles_y(&d), n = tiles * passes;
    uint32_t *order = malloc(sizeof *order * n);
    size_t bytes = sizeof(float) * tiles * 16 * FOLD_NUM_CHANNELS;
    float *a = calloc(1, bytes), *b = calloc(1, bytes);
    struct tile_stats sa, sb;
    for (uint32_t i = 0; i < n; i++)
        order[i] = i; /* u = pass x tiles + tile: pass by pass */
    fold_in_order_n(&d, passes, order, a, &sa);
    uint32_t kept = 0;
    fold_taken_n(&d, passes, order, b, &sb, 0, 1, &kept);
    cr_assert(memcmp(a, b, bytes) == 0, "pixels differ folded in batches");
    cr_assert(kept <= tiles * FOLD_BATCH, "pass by pass, at most %u units kept at once, not %u", tiles * FOLD_BATCH,
              kept);
    fold_taken_n(&d, passes, order, b, &sb, 3, 7, NULL);
    cr_assert(memcmp(a, b, bytes) == 0, "pixels differ with batches held back");
    uint64_t x = 999;
    for (int trial = 0; trial < 12; trial++) {
        shuffle(order, n, &x);
        memset(b, 0, bytes);
        fold_taken_n(&d, passes, order, b, &sb, (uint32_t)trial % 5, x, NULL);
        cr_assert(memcmp(a, b, bytes) == 0, "trial %d: pixels differ folded in batches, another arrival order", trial);
        cr_assert(fabs(sa.sum_rel_stderr - sb.sum_rel_stderr) <= 1e-12 * sa.sum_rel_stderr &&
                  sa.rel_stderr_pixels == sb.rel_stderr_pixels);
    }
    free(order);
    free(a);
    free(b);
}

Test(fold, any_arrival_order_gives_the_same_bits)
{
    struct image_desc d;
    make_desc(&d);
    uint32_t tiles = imgio_tiles_x(&d) * imgio_tiles_y(&d), n = tiles * PASSES;
    uint32_t *order = malloc(sizeof *order * n);
    size_t bytes = sizeof(float) * tiles * 16 * FOLD_NUM_CHANNELS;
    float *a = calloc(1, bytes), *b = calloc(1, bytes);
    struct tile_stats sa, sb;
    for (uint32_t i = 0; i < n; i++)
        order[i] = i;
    fold_in_order(&d, order, a, &sa);
    uint64_t x = 12345;
    for (int trial = 0; trial < 20; trial++) {
        shuffle(order, n, &x);
        memset(b, 0, bytes);
        /* odd trials: units kept until a tile's last is in, taken out and folded by
         * fold_run, the master's way */
        if (trial & 1)
            fold_taken(&d, order, b, &sb);
        else
            fold_in_order(&d, order, b, &sb);
        cr_assert(memcmp(a, b, bytes) == 0, "trial %d: pixels differ with another arrival order%s", trial,
                  trial & 1 ? " (taken)" : "");
        /* The summary's sum over tiles follows the order tiles finish in; only it may round differently. */
        cr_assert(fabs(sa.sum_rel_stderr - sb.sum_rel_stderr) <= 1e-12 * sa.sum_rel_stderr &&
                  sa.rel_stderr_pixels == sb.rel_stderr_pixels);
    }
    free(order);
    free(a);
    free(b);
}

Test(fold, batch_means_of_the_passes_with_samples)
{
    struct image_desc d;
    make_desc(&d);
    uint32_t tiles = imgio_tiles_x(&d) * imgio_tiles_y(&d);
    uint32_t *order = malloc(sizeof *order * tiles * PASSES);
    for (uint32_t i = 0; i < tiles * PASSES; i++)
        order[i] = tiles * PASSES - 1 - i; /* last pass first */
    float *out = calloc((size_t)tiles * 16 * FOLD_NUM_CHANNELS, sizeof(float));
    struct tile_stats st;
    fold_in_order(&d, order, out, &st);
    /* Tile 0, pixel 3: the mean of the stream means (pass p in stream p mod
     * SAMPLER_STREAMS) and s^2 / q of the q stream means, over the passes whose alpha is not
     * NONE. */
    float px[16 * TILE_NUM_CHANNELS];
    double ssum[SAMPLER_STREAMS] = {0}, cover = 0;
    uint32_t scount[SAMPLER_STREAMS] = {0}, n = 0;
    for (uint32_t p = 0; p < PASSES; p++) {
        pass_pixels(0, p, 16, px);
        const float *c = &px[3 * TILE_NUM_CHANNELS];
        if (c[CH_A] < 0.0f)
            continue;
        ssum[p % SAMPLER_STREAMS] += c[CH_G];
        scount[p % SAMPLER_STREAMS]++;
        cover += c[CH_A];
        n++;
    }
    double sum = 0, sum2 = 0;
    uint32_t q = 0;
    for (uint32_t s = 0; s < SAMPLER_STREAMS; s++)
        if (scount[s]) {
            double sm = ssum[s] / scount[s];
            sum += sm;
            sum2 += sm * sm;
            q++;
        }
    cr_assert_geq(q, 2u);
    double mean = sum / q, var = (sum2 - q * mean * mean) / (q - 1) / q;
    const float *o = &out[3 * FOLD_NUM_CHANNELS];
    cr_assert(fabs(o[CH_G] - mean) < 1e-6, "mean %g, expected %g", o[CH_G], mean);
    cr_assert_eq(o[FOLD_CH_SAMPLES], (float)(PASSES * 3), "samples: passes x spp per pass");
    cr_assert(fabs(o[CH_VAR_G] - var) < 1e-6 * (1 + var), "variance %g, expected %g", o[CH_VAR_G], var);
    cr_assert(fabs(o[CH_A] - cover / n) < 1e-6);
    free(order);
    free(out);
}

/* Tile t's final pixels for the error estimate: magnitudes over several decades, so that
 * summing them in another order rounds differently. */
static void est_pixels(uint32_t t, size_t n, uint32_t nc, float *px)
{
    for (size_t i = 0; i < n; i++) {
        float *c = &px[i * nc];
        for (int k = 0; k < 3; k++) {
            double s = sin(0.7 * (double)(t * 97 + i * 13 + k * 5));
            c[CH_R + k] = (float)(pow(10.0, 3.0 * s) * (1.0 + 0.1 * k));
            c[CH_VAR_R + k] = (float)(pow(10.0, -2.0 + 4.0 * cos(0.3 * (double)(t * 31 + i * 3 + k))));
        }
        c[CH_A] = 1.0f;
    }
}

/* What the estimate must be: every given tile's pixels summed in tile order, then pixel
 * order, as one running sum. */
static double est_reference(const struct image_desc *d, const uint8_t *given, const float *const *px)
{
    uint32_t tiles = imgio_tiles_x(d) * imgio_tiles_y(d);
    double var = 0.0, mean = 0.0;
    uint64_t pixels = 0;
    for (uint32_t t = 0; t < tiles; t++) { /* per tile in pixel order, then the tiles in order */
        if (!given[t])
            continue;
        uint32_t x0, y0, w, h;
        imgio_tile_rect(d, t % imgio_tiles_x(d), t / imgio_tiles_x(d), &x0, &y0, &w, &h);
        double tv = 0.0, tm = 0.0;
        for (size_t i = 0; i < (size_t)w * h; i++) {
            const float *c = &px[t][i * d->num_channels];
            tv += ((double)c[CH_VAR_R] + c[CH_VAR_G] + c[CH_VAR_B]) / 3.0;
            tm += ((double)c[CH_R] + c[CH_G] + c[CH_B]) / 3.0;
        }
        var += tv;
        mean += tm;
        pixels += (uint64_t)w * h;
    }
    return sqrt(var / (double)pixels) / (mean / (double)pixels);
}

Test(fold, error_estimate_has_the_same_bits_for_any_tile_order)
{
    struct image_desc d;
    desc_of(&d, 37, 29, 8);
    uint32_t tiles = imgio_tiles_x(&d) * imgio_tiles_y(&d);
    float **px = malloc(sizeof *px * tiles);
    uint32_t *order = malloc(sizeof *order * tiles);
    uint8_t *given = malloc(tiles);
    for (uint32_t t = 0; t < tiles; t++) {
        px[t] = malloc(sizeof(float) * 64 * d.num_channels);
        est_pixels(t, 64, d.num_channels, px[t]);
        order[t] = t;
    }
    struct fold_est *e = fold_est_new(&d);
    uint64_t sat = 99, x = 777;
    cr_assert_eq(fold_est_result(e, &sat), 0.0, "no tile: 0");
    cr_assert_eq(sat, 0u);
    for (int trial = 0; trial < 24; trial++) {
        for (uint32_t i = tiles - 1; i > 0 && trial > 0; i--) {
            x = x * 6364136223846793005ull + 1442695040888963407ull;
            uint32_t j = (uint32_t)((x >> 33) % (i + 1));
            uint32_t tmp = order[i];
            order[i] = order[j];
            order[j] = tmp;
        }
        /* Odd trials leave a tile out (a frame cut short): the tiles after it still count. */
        uint32_t missing = trial % 2 ? (uint32_t)(x >> 40) % tiles : tiles;
        memset(given, 0, tiles);
        fold_est_reset(e);
        for (uint32_t i = 0; i < tiles; i++)
            if (order[i] != missing) {
                if (trial % 4 >= 2) { /* the checker pool's way: the sums there, the put in the loop */
                    struct fold_est_sums sums;
                    fold_est_tile_sums(&d, order[i], px[order[i]], &sums);
                    fold_est_put(e, order[i], &sums);
                } else
                    fold_est_add(e, order[i], px[order[i]]);
                given[order[i]] = 1;
            }
        double want = est_reference(&d, given, (const float *const *)px);
        double got = fold_est_result(e, &sat);
        cr_assert(memcmp(&want, &got, sizeof want) == 0, "trial %d (tile %u missing): %.17g, expected %.17g", trial,
                  missing, got, want);
        cr_assert_eq(sat, 0u);
        cr_assert_eq(fold_est_result(e, &sat), got, "the result leaves the sums as they are");
    }
    /* A saturated variance is counted; a black image estimates 0. */
    fold_est_reset(e);
    px[5][3 * d.num_channels + CH_VAR_G] = FLT_MAX;
    for (uint32_t t = 0; t < tiles; t++) {
        if (t != 5)
            memset(px[t], 0, sizeof(float) * 64 * d.num_channels);
        fold_est_add(e, tiles - 1 - t, px[tiles - 1 - t]);
    }
    fold_est_result(e, &sat);
    cr_assert_eq(sat, 1u);
    struct fold_est_sums s5;
    fold_est_tile_sums(&d, 5, px[5], &s5);
    cr_assert_eq(s5.saturated, 1u, "the pool's sums count it too");
    fold_est_reset(e);
    memset(px[5], 0, sizeof(float) * 64 * d.num_channels);
    for (uint32_t t = 0; t < tiles; t++)
        fold_est_add(e, t, px[t]);
    cr_assert_eq(fold_est_result(e, &sat), 0.0, "black: 0");
    fold_est_free(&e);
    cr_assert_null(e);
    for (uint32_t t = 0; t < tiles; t++)
        free(px[t]);
    free(px);
    free(order);
    free(given);
}

/* Units of some pixel blocks of a tile (an adaptive render's slots): an 8-px tile of 2x2
 * blocks of 4 px; blocks 0..3 get 4, 2, 6 and 2 passes in slots released round by round
 * (passes 0-1 every block, 2-3 blocks 0 and 2, 4-5 block 2), arriving last slot first.
 * Each block's pixels, samples included, have the bits of a plain fold of its passes. */
Test(fold, slots_of_blocks_fold_as_each_block_s_own_passes)
{
    struct image_desc d;
    desc_of(&d, 8, 8, 8);
    cr_assert_eq(tile_blocks_side(8), 2);
    const uint32_t slot_pass[6] = {0, 1, 2, 3, 4, 5};
    const uint64_t slot_mask[6] = {TILE_MASK_ALL, TILE_MASK_ALL, 0x5, 0x5, 0x4, 0x4};
    const uint32_t block_passes[4] = {4, 2, 6, 2};
    enum { N = 64 };
    float *px = malloc(sizeof(float) * N * TILE_NUM_CHANNELS), *out = malloc(sizeof(float) * N * FOLD_NUM_CHANNELS),
          *ref = malloc(sizeof(float) * N * FOLD_NUM_CHANNELS);
    struct fold *f = fold_new(&d, 8, 3, SAMPLER_STREAMS);
    struct tile_stats st = {0};
    for (int s = 5; s >= 0; s--) {
        pass_pixels(0, slot_pass[s], N, px);
        for (size_t i = 0; i < N; i++) /* what a worker sends outside the mask: zeros */
            if (!(slot_mask[s] >> tile_pixel_block(8, (uint32_t)(i % 8), (uint32_t)(i / 8)) & 1))
                memset(&px[i * TILE_NUM_CHANNELS], 0, sizeof(float) * TILE_NUM_CHANNELS);
        cr_assert_eq(fold_add_slot(f, 0, (uint32_t)s, slot_pass[s], slot_mask[s], px), s == 0 ? 6u : 0u);
    }
    double v[4], v2[4], mu[4];
    for (uint32_t b = 0; b < 4; b++)
        fold_block_sums(f, 0, (uint64_t)1 << b, &v[b], &v2[b], &mu[b]);
    fold_finish(f, 0, out, &st);
    fold_free(&f);
    for (uint32_t b = 0; b < 4; b++) {
        struct fold *g = fold_new(&d, 8, 3, SAMPLER_STREAMS);
        for (uint32_t p = 0; p < block_passes[b]; p++) {
            pass_pixels(0, p, N, px);
            fold_add_unit(g, 0, p, px);
        }
        double gv, gv2, gmu, all[3];
        fold_block_sums(g, 0, (uint64_t)1 << b, &gv, &gv2, &gmu);
        fold_tile_sums(g, 0, &all[0], &all[1], &all[2]);
        cr_assert(gv == v[b] && gv2 == v2[b] && gmu == mu[b], "block %u: the block's sums", b);
        cr_assert(gmu < all[2], "a block's sums cover its pixels only");
        struct tile_stats gs = {0};
        fold_finish(g, 0, ref, &gs);
        fold_free(&g);
        for (size_t i = 0; i < N; i++) {
            if (tile_pixel_block(8, (uint32_t)(i % 8), (uint32_t)(i / 8)) != b)
                continue;
            cr_assert(memcmp(&out[i * FOLD_NUM_CHANNELS], &ref[i * FOLD_NUM_CHANNELS], sizeof(float) * FOLD_NUM_CHANNELS) == 0,
                      "block %u pixel %zu differs from %u plain passes", b, i, block_passes[b]);
            cr_assert_eq(out[i * FOLD_NUM_CHANNELS + FOLD_CH_SAMPLES], 3.0f * block_passes[b]);
        }
    }
    free(px);
    free(out);
    free(ref);
}

/* The sums of every block of a tile in one pass (fold_blocks_sums) have the bits of one
 * fold_block_sums per block: 32-px tiles of 8 x 8 blocks, an edge tile cut in both ways
 * (44x20: tiles of 32x20 and 12x20), blocks at different passes, a tile with nothing folded. */
Test(fold, blocks_sums_in_one_pass_are_the_per_block_sums)
{
    struct image_desc d;
    desc_of(&d, 44, 20, 32);
    enum { NB = TILE_MAX_BLOCKS_SIDE * TILE_MAX_BLOCKS_SIDE };
    cr_assert_eq(tile_blocks_side(32) * tile_blocks_side(32), (uint32_t)NB);
    const uint64_t slot_mask[4] = {TILE_MASK_ALL, TILE_MASK_ALL, 0x00ff00ff00ff00ffull, 0x0f0f0f0f0f0f0f0full};
    float *px = malloc(sizeof(float) * 32 * 32 * TILE_NUM_CHANNELS);
    struct fold *f = fold_new(&d, 8, 3, SAMPLER_STREAMS);
    for (uint32_t t = 0; t < 2; t++) {
        uint32_t x0, y0, w, h;
        imgio_tile_rect(&d, t, 0, &x0, &y0, &w, &h);
        for (uint32_t s = 0; s < 4; s++) {
            pass_pixels(t, s, (size_t)w * h, px);
            fold_add_slot(f, t, s, s, slot_mask[s], px);
        }
    }
    struct fold *g = fold_new(&d, 8, 3, SAMPLER_STREAMS); /* nothing folded */
    const struct fold *both[2] = {f, g};
    for (uint32_t k = 0; k < 2; k++)
        for (uint32_t t = 0; t < 2; t++) {
            double v[NB], v2[NB], mu[NB];
            fold_blocks_sums(both[k], t, v, v2, mu);
            for (uint32_t b = 0; b < NB; b++) {
                double bv, bv2, bmu;
                fold_block_sums(both[k], t, (uint64_t)1 << b, &bv, &bv2, &bmu);
                cr_assert(memcmp(&bv, &v[b], sizeof bv) == 0 && memcmp(&bv2, &v2[b], sizeof bv2) == 0 &&
                              memcmp(&bmu, &mu[b], sizeof bmu) == 0,
                          "fold %u tile %u block %u: the same bits as the block's own sums", k, t, b);
                cr_assert(k == 1 || t == 1 || b >= 40 || (v[b] > 0.0 && mu[b] > 0.0), "tile 0 block %u has pixels", b);
            }
        }
    fold_free(&f);
    fold_free(&g);
    free(px);
}

/* The per-pixel bound's figures (fold_blocks_worst): a block's worst squared relative
 * error and its pixels above the bound, each pixel's variance of the mean over max(its
 * mean, floor)^2. A near-black pixel whose stream means differ (0.001 and 0.003: a
 * relative error of 0.5 of its own value) is measured against the floor instead, and does
 * not count as above a bound of 0.1; a bright pixel with the same spread relative to it
 * does. */
Test(fold, blocks_worst_pixel_with_a_floor)
{
    struct image_desc d;
    desc_of(&d, 8, 8, 8);
    enum { N = 64 };
    float *px = calloc(N * TILE_NUM_CHANNELS, sizeof(float));
    struct fold *f = fold_new(&d, 4, 8, SAMPLER_STREAMS);
    for (uint32_t p = 0; p < 4; p++) { /* pass p in stream p mod 2 */
        for (size_t i = 0; i < N; i++) {
            float *c = &px[i * TILE_NUM_CHANNELS];
            uint32_t b = tile_pixel_block(8, (uint32_t)(i % 8), (uint32_t)(i / 8));
            double v = b == 0 ? 0.002 : b == 1 ? 1.0 : 0.5; /* block 0 near black, block 1 bright */
            if (i == 0) /* block 0's noisy black pixel */
                v = p % 2 ? 0.003 : 0.001;
            if (i == 4) /* block 1's noisy bright pixel: stream means 0.5 and 1.5 */
                v = p % 2 ? 1.5 : 0.5;
            c[CH_R] = c[CH_G] = c[CH_B] = (float)v;
            c[CH_A] = 1.0f;
        }
        fold_add_unit(f, 0, p, px);
    }
    double worst[4], ref_worst[4];
    uint32_t over[4], ref_over[4];
    /* floor 0: every pixel against its own value; the black one at 0.5 */
    fold_blocks_worst(f, 0, 0.0, 0.1, ref_worst, ref_over);
    cr_assert(fabs(ref_worst[0] - 0.25) < 1e-6, "black pixel against itself: %g", ref_worst[0]);
    cr_assert_eq(ref_over[0], 1u);
    /* floor 0.1 (a tenth of an image mean of 1): the black pixel's 0.001 over 0.1 */
    fold_blocks_worst(f, 0, 0.1, 0.1, worst, over);
    cr_assert(fabs(worst[0] - 1e-4) < 1e-8, "black pixel against the floor: %g", worst[0]);
    cr_assert_eq(over[0], 0u, "the floor keeps the black pixel under the bound");
    cr_assert(fabs(worst[1] - 0.25) < 1e-9 && over[1] == 1u, "the bright pixel (0.5 / 1) is above: %g", worst[1]);
    cr_assert(worst[2] == 0.0 && over[2] == 0u && worst[3] == 0.0, "blocks without variance");
    fold_free(&f);
    free(px);
}
