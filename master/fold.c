/* Pass folding (see fold.h). Per tile: how many passes are folded, the running per-pixel
 * batch means, and copies of passes that arrived before an earlier one; both are given up
 * once the tile is final (the batch means' buffer is kept for the next tile: a fresh one
 * costs page faults, per tile, in the master's loop). fold_add_take's tiles keep copies of
 * their units and hand them out in batches (fold_units), each carrying the tile's sums of
 * the batches before it. The error estimate's sums (fold_est) run over final tiles in
 * tile order. */
#include "fold.h"
#include "base/log.h"
#include "render/aov.h"
#include "render/integrator.h"
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *const fold_samples_channel = "samples";

/* A unit that came before its turn: a copy of its pixels, its pass and its blocks. */
struct fold_early {
    float *px;
    uint32_t pass;
    uint64_t mask;
};

struct fold_tile {
    uint32_t folded;            /* slots 0..folded-1 are in acc (fold_add_take: handed to batches) */
    int final;                  /* finished: takes nothing more */
    int busy;                   /* fold_add_take: a batch of its units is out (fold_units_return) */
    struct fold_tile *kept_state; /* fold_add_take: the batches' sums so far, while no batch is out */
    struct pass_pixel *acc;     /* per pixel, NULL before the first pass */
    struct fold_early *early;   /* per slot */
    uint32_t block_passes[TILE_MAX_BLOCKS_SIDE * TILE_MAX_BLOCKS_SIDE]; /* passes folded into each block */
    struct aov_pixel *aov;      /* per pixel, with AOVs, NULL before the first pass */
};

struct fold {
    struct image_desc desc;
    uint32_t passes, spp_per_pass, num_tiles, tiles_x, streams;
    struct tile_layout lay;     /* the units' channels (beauty, AOVs) */
    struct fold_tile *tiles;
    /* accumulators of finished tiles, kept for the next tiles (tile_size^2 pixels each):
     * reused, a tile's start costs a memset, not fresh pages */
    struct pass_pixel **spare;
    uint32_t num_spare, cap_spare;
};

struct fold *fold_new(const struct image_desc *desc, uint32_t passes, uint32_t spp_per_pass, uint32_t streams)
{
    struct fold *f = mem_calloc(1, sizeof *f);
    CHECK(streams >= 1 && streams <= SAMPLER_MAX_STREAMS);
    f->streams = streams;
    f->desc = *desc;
    f->passes = passes;
    f->spp_per_pass = spp_per_pass;
    f->tiles_x = imgio_tiles_x(desc);
    tile_layout_from_desc(&f->lay, desc);
    f->num_tiles = f->tiles_x * imgio_tiles_y(desc);
    f->tiles = mem_calloc(f->num_tiles ? f->num_tiles : 1, sizeof *f->tiles);
    return f;
}

void fold_output_desc(const struct image_desc *desc, struct image_desc *out)
{
    *out = *desc;
    out->num_channels = desc->num_channels + 1;
    snprintf(out->channel_names[FOLD_CH_SAMPLES], sizeof out->channel_names[FOLD_CH_SAMPLES], "%s",
             fold_samples_channel);
    /* The AOVs follow the samples (FLOAT), their HALF bits with them. */
    uint32_t below = (1u << FOLD_CH_SAMPLES) - 1u;
    out->half_mask = (desc->half_mask & below) | (desc->half_mask & ~below) << 1;
    for (uint32_t c = TILE_NUM_CHANNELS; c < desc->num_channels; c++)
        memcpy(out->channel_names[c + 1], desc->channel_names[c], sizeof out->channel_names[c]);
}

/* AOVs: a tile's per-pixel folds, one pass's pixels into them, the final channels (after
 * the samples channel). */
static void fold_aovs_start(const struct fold *f, struct fold_tile *t, size_t pixels)
{
    if (!f->lay.aovs)
        return;
    t->aov = mem_alloc(pixels * sizeof *t->aov);
    aov_tile_init(t->aov, pixels);
}

static void fold_aovs_pass(const struct fold *f, struct fold_tile *t, size_t pixels, const float *px)
{
    if (t->aov)
        aov_tile_fold(t->aov, &f->lay, px, pixels);
}

static void fold_aovs_finish(const struct fold *f, const struct fold_tile *t, size_t pixels, float *out)
{
    if (!f->lay.aovs)
        return;
    struct tile_layout ol = f->lay;
    for (int a = 0; a < AOV_COUNT_; a++)
        ol.off[a] += ol.off[a] >= 0;
    ol.num_channels++;
    aov_tile_finish(t->aov, &ol, out, pixels);
}

static size_t full_tile_pixels(const struct fold *f) { return (size_t)f->desc.tile_size * f->desc.tile_size; }

/* A zeroed accumulator for `pixels` pixels (at most a full tile's): a spare one if any. */
static struct pass_pixel *acc_get(struct fold *f, size_t pixels)
{
    if (!f->num_spare)
        return mem_calloc(full_tile_pixels(f), sizeof(struct pass_pixel));
    struct pass_pixel *a = f->spare[--f->num_spare];
    memset(a, 0, pixels * sizeof *a);
    return a;
}

static void acc_put(struct fold *f, struct pass_pixel *a)
{
    if (!a)
        return;
    if (f->num_spare == f->cap_spare) {
        f->cap_spare = f->cap_spare ? 2 * f->cap_spare : 64;
        f->spare = mem_realloc(f->spare, f->cap_spare * sizeof *f->spare);
    }
    f->spare[f->num_spare++] = a;
}

/* A batch's sums between batches (fold_units.state): freed with what it holds. */
static void state_free(struct fold_tile **sp)
{
    struct fold_tile *st = *sp;
    if (!st)
        return;
    free(st->acc);
    free(st->aov);
    free(st);
    *sp = NULL;
}

static void tile_clear(struct fold *f, struct fold_tile *t)
{
    acc_put(f, t->acc);
    free(t->aov);
    for (uint32_t p = 0; t->early && p < f->passes; p++)
        free(t->early[p].px);
    free(t->early);
    state_free(&t->kept_state);
    memset(t, 0, sizeof *t);
}

void fold_reset(struct fold *f)
{
    for (uint32_t i = 0; i < f->num_tiles; i++)
        tile_clear(f, &f->tiles[i]);
}

void fold_free(struct fold **fp)
{
    struct fold *f = *fp;
    if (!f)
        return;
    fold_reset(f);
    for (uint32_t i = 0; i < f->num_spare; i++)
        free(f->spare[i]);
    free(f->spare);
    free(f->tiles);
    free(f);
    *fp = NULL;
}

/* Pixels of tile (in rows of tiles_x) of desc. */
static size_t desc_tile_pixels(const struct image_desc *desc, uint32_t tiles_x, uint32_t tile)
{
    uint32_t x0, y0, w, h;
    imgio_tile_rect(desc, tile % tiles_x, tile / tiles_x, &x0, &y0, &w, &h);
    return (size_t)w * h;
}

static size_t tile_pixels(const struct fold *f, uint32_t tile) { return desc_tile_pixels(&f->desc, f->tiles_x, tile); }

/* The width of tile; the block of its pixel i (in pixel order) is tile_pixel_block of its place. */
static uint32_t tile_width(const struct fold *f, uint32_t tile)
{
    uint32_t x0, y0, w, h;
    imgio_tile_rect(&f->desc, tile % f->tiles_x, tile / f->tiles_x, &x0, &y0, &w, &h);
    return w;
}

static uint32_t pixel_block(const struct fold *f, uint32_t w, size_t i)
{
    return tile_pixel_block(f->desc.tile_size, (uint32_t)(i % w), (uint32_t)(i / w));
}

static void fold_pass(const struct fold *f, uint32_t tile, struct fold_tile *t, size_t pixels, uint32_t pass, uint64_t mask,
                      const float *px)
{
    if (mask == TILE_MASK_ALL) {
        for (size_t i = 0; i < pixels; i++)
            pass_pixel_fold(&t->acc[i], pass % f->streams, &px[i * f->lay.num_channels]);
        fold_aovs_pass(f, t, pixels, px);
    } else { /* the mask's blocks only: the others' pixels of this unit are not rendered */
        uint32_t w = tile_width(f, tile);
        for (size_t i = 0; i < pixels; i++)
            if (mask >> pixel_block(f, w, i) & 1) {
                pass_pixel_fold(&t->acc[i], pass % f->streams, &px[i * f->lay.num_channels]);
                if (t->aov)
                    aov_pixel_fold(&t->aov[i], &f->lay, &px[i * f->lay.num_channels]);
            }
    }
    for (uint32_t b = 0; b < TILE_MAX_BLOCKS_SIDE * TILE_MAX_BLOCKS_SIDE; b++)
        t->block_passes[b] += (uint32_t)(mask >> b & 1);
    t->folded++;
}

uint32_t fold_add_unit(struct fold *f, uint32_t tile, uint32_t pass, const float *px)
{
    return fold_add_slot(f, tile, pass, pass, TILE_MASK_ALL, px);
}

size_t fold_unit_floats(const struct fold *f, uint32_t tile)
{
    return tile_pixels(f, tile) * f->lay.num_channels;
}

float *fold_unit_copy(const struct fold *f, uint32_t tile, const float *px)
{
    size_t n = fold_unit_floats(f, tile);
    float *c = mem_alloc(sizeof(float) * (n ? n : 1));
    memcpy(c, px, sizeof(float) * n);
    return c;
}

/* Keeps a unit that is not folded now: own (fold_unit_copy's) taken over. */
static void keep_early(struct fold_tile *t, uint32_t slot, uint32_t pass, uint64_t mask, float *own)
{
    CHECK(slot >= t->folded && !t->early[slot].px);
    t->early[slot].px = own;
    t->early[slot].pass = pass;
    t->early[slot].mask = mask;
}

uint32_t fold_add_slot(struct fold *f, uint32_t tile, uint32_t slot, uint32_t pass, uint64_t mask, const float *px)
{
    CHECK(tile < f->num_tiles && slot < f->passes && pass < f->passes);
    struct fold_tile *t = &f->tiles[tile];
    CHECK(!t->final);
    size_t pixels = tile_pixels(f, tile);
    if (!t->acc) {
        t->acc = acc_get(f, pixels);
        t->early = mem_calloc(f->passes, sizeof *t->early);
        fold_aovs_start(f, t, pixels);
    }
    if (slot != t->folded) {
        keep_early(t, slot, pass, mask, fold_unit_copy(f, tile, px));
    } else {
        fold_pass(f, tile, t, pixels, pass, mask, px);
    }
    while (t->folded < f->passes && t->early[t->folded].px) {
        struct fold_early e = t->early[t->folded];
        t->early[t->folded].px = NULL;
        fold_pass(f, tile, t, pixels, e.pass, e.mask, e.px);
        free(e.px);
    }
    return t->folded;
}

/* Tile's final pixels from t's folded passes into out (fold_finish). */
static void finish_pixels(const struct fold *f, uint32_t tile, const struct fold_tile *t, float *out,
                          struct tile_stats *stats)
{
    size_t pixels = tile_pixels(f, tile);
    uint32_t w = tile_width(f, tile);
    for (size_t i = 0; i < pixels; i++) {
        float *px = &out[i * (f->lay.num_channels + 1)];
        if (t->acc) {
            pass_pixel_finish(&t->acc[i], px, stats);
        } else {
            memset(px, 0, sizeof(float) * TILE_NUM_CHANNELS);
        }
        px[FOLD_CH_SAMPLES] = (float)((double)t->block_passes[pixel_block(f, w, i)] * f->spp_per_pass);
    }
    fold_aovs_finish(f, t, pixels, out);
}

void fold_finish(struct fold *f, uint32_t tile, float *out, struct tile_stats *stats)
{
    CHECK(tile < f->num_tiles);
    struct fold_tile *t = &f->tiles[tile];
    CHECK(!t->final);
    uint32_t folded = t->folded;
    finish_pixels(f, tile, t, out, stats);
    tile_clear(f, t);
    t->folded = folded;
    t->final = 1;
}

struct fold_units {
    uint32_t tile, count;
    uint32_t first;             /* the slot of unit[0]: the batch is slots first..first+count-1 */
    int last;                   /* the tile's last slots: fold_run finishes the tile */
    struct fold_tile *state;    /* the sums of the tile's earlier batches (NULL: none, or the
                                 * whole tile in one batch, summed in fold_run's scratch) */
    struct fold_early unit[];   /* per slot: a copy of its pixels, its pass and blocks */
};

/* The tile's next batch, if one is due: the units kept from slot `folded` on without a gap,
 * when they reach the tile's last slot, or (over FOLD_KEEP_ALL_PASSES passes) number
 * FOLD_BATCH or more; none while a batch is out. */
static struct fold_units *take_batch(struct fold *f, uint32_t tile)
{
    struct fold_tile *t = &f->tiles[tile];
    if (t->busy || t->final || !t->early)
        return NULL;
    uint32_t n = 0;
    while (t->folded + n < f->passes && t->early[t->folded + n].px)
        n++;
    int last = t->folded + n == f->passes;
    if (n == 0 || (!last && (f->passes <= FOLD_KEEP_ALL_PASSES || n < FOLD_BATCH)))
        return NULL;
    struct fold_units *u = mem_alloc(sizeof *u + n * sizeof u->unit[0]);
    u->tile = tile;
    u->count = n;
    u->first = t->folded;
    u->last = last;
    u->state = t->kept_state;
    t->kept_state = NULL;
    memcpy(u->unit, &t->early[t->folded], n * sizeof u->unit[0]);
    memset(&t->early[t->folded], 0, n * sizeof u->unit[0]);
    t->folded += n;
    if (last) {
        free(t->early);
        memset(t, 0, sizeof *t);
        t->folded = f->passes;
        t->final = 1;
    } else {
        t->busy = 1;
    }
    return u;
}

struct fold_units *fold_add_take_own(struct fold *f, uint32_t tile, uint32_t pass, float **px)
{
    CHECK(tile < f->num_tiles && pass < f->passes);
    struct fold_tile *t = &f->tiles[tile];
    CHECK(!t->final && !t->acc);
    if (!t->early)
        t->early = mem_calloc(f->passes, sizeof *t->early);
    keep_early(t, pass, pass, TILE_MASK_ALL, *px);
    *px = NULL;
    return take_batch(f, tile);
}

struct fold_units *fold_add_take(struct fold *f, uint32_t tile, uint32_t pass, const float *px)
{
    float *own = fold_unit_copy(f, tile, px);
    return fold_add_take_own(f, tile, pass, &own);
}

void fold_run(const struct fold *f, struct fold_units *u, void **scratch, size_t *scratch_size, float *out,
              struct tile_stats *stats)
{
    size_t pixels = tile_pixels(f, u->tile), need = pixels * sizeof(struct pass_pixel);
    struct fold_tile whole, *t = u->state;
    if (u->first == 0 && u->last) { /* the whole tile at once: sums in the scratch */
        if (*scratch_size < need) {
            free(*scratch);
            *scratch = mem_alloc(need);
            *scratch_size = need;
        }
        memset(&whole, 0, sizeof whole);
        whole.acc = *scratch;
        memset(whole.acc, 0, need);
        fold_aovs_start(f, &whole, pixels);
        t = &whole;
    } else if (!t) { /* a tile's first batch: its sums, kept for the next batches */
        t = u->state = mem_calloc(1, sizeof *u->state);
        t->acc = mem_calloc(pixels ? pixels : 1, sizeof(struct pass_pixel));
        fold_aovs_start(f, t, pixels);
    }
    /* The batch's slots added to the sums of the earlier ones (the same additions in the
     * same order as in one go), its copies freed at once. */
    for (uint32_t i = 0; i < u->count; i++) {
        fold_pass(f, u->tile, t, pixels, u->unit[i].pass, u->unit[i].mask, u->unit[i].px);
        free(u->unit[i].px);
        u->unit[i].px = NULL;
    }
    if (!u->last)
        return;
    finish_pixels(f, u->tile, t, out, stats);
    if (t == &whole)
        free(whole.aov);
    else
        state_free(&u->state);
}

int fold_units_final(const struct fold_units *u) { return u->last; }

struct fold_units *fold_units_return(struct fold *f, struct fold_units **up)
{
    struct fold_units *u = *up;
    *up = NULL;
    struct fold_tile *t = &f->tiles[u->tile];
    uint32_t tile = u->tile;
    if (u->last || !t->busy) { /* a final batch, or the frame was reset meanwhile */
        fold_units_free(&u);
        return NULL;
    }
    t->kept_state = u->state;
    u->state = NULL;
    t->busy = 0;
    fold_units_free(&u);
    return take_batch(f, tile);
}

uint32_t fold_kept_units(const struct fold *f)
{
    uint32_t n = 0;
    for (uint32_t i = 0; i < f->num_tiles; i++) {
        const struct fold_tile *t = &f->tiles[i];
        for (uint32_t p = 0; !t->acc && t->early && p < f->passes; p++)
            n += t->early[p].px != NULL;
    }
    return n;
}

uint32_t fold_units_tile(const struct fold_units *u) { return u->tile; }

void fold_units_free(struct fold_units **up)
{
    struct fold_units *u = *up;
    if (!u)
        return;
    for (uint32_t i = 0; i < u->count; i++)
        free(u->unit[i].px);
    state_free(&u->state);
    free(u);
    *up = NULL;
}

int fold_add(struct fold *f, uint32_t tile, uint32_t pass, const float *px, float *out, struct tile_stats *stats)
{
    if (fold_add_unit(f, tile, pass, px) < f->passes)
        return 0;
    fold_finish(f, tile, out, stats);
    return 1;
}

void fold_tile_sums(const struct fold *f, uint32_t tile, double *sum_var, double *sum_var_sq, double *sum_mean)
{
    fold_block_sums(f, tile, TILE_MASK_ALL, sum_var, sum_var_sq, sum_mean);
}

/* A pixel's terms of the block sums: the variance of its mean, its square over q + 1, its mean. */
static void pixel_sums(const struct pass_batch *b, double *pv, double *pv2, double *mu)
{
    double v = (pass_batch_var_of_mean(b, 0) + pass_batch_var_of_mean(b, 1) + pass_batch_var_of_mean(b, 2)) / 3.0;
    uint32_t q = 0;
    for (uint32_t s = 0; s < SAMPLER_MAX_STREAMS; s++)
        q += b->count[s] > 0;
    *pv = v;
    /* sigma^4 / (q - 1) estimated without bias: a variance s^2 from q - 1 degrees of
     * freedom has E[s^4] = sigma^4 (q + 1) / (q - 1), so s^4 / (q + 1). (s^4 / (q - 1)
     * counted a pixel's noise 3x over with 2 streams: a third of the degrees of freedom.) */
    *pv2 = q > 1 ? v * v / (q + 1) : 0.0;
    *mu = (b->mean[0] + b->mean[1] + b->mean[2]) / 3.0;
}

void fold_block_sums(const struct fold *f, uint32_t tile, uint64_t mask, double *sum_var, double *sum_var_sq,
                     double *sum_mean)
{
    CHECK(tile < f->num_tiles);
    const struct fold_tile *t = &f->tiles[tile];
    double v = 0.0, v2 = 0.0, mu = 0.0;
    size_t pixels = tile_pixels(f, tile);
    uint32_t w = tile_width(f, tile);
    for (size_t i = 0; t->acc && i < pixels; i++) {
        if (mask != TILE_MASK_ALL && !(mask >> pixel_block(f, w, i) & 1))
            continue;
        double pv, pv2, pmu;
        pixel_sums(&t->acc[i].b, &pv, &pv2, &pmu);
        v += pv;
        v2 += pv2;
        mu += pmu;
    }
    *sum_var = v;
    *sum_var_sq = v2;
    *sum_mean = mu;
}

void fold_blocks_sums(const struct fold *f, uint32_t tile, double *sum_var, double *sum_var_sq, double *sum_mean)
{
    CHECK(tile < f->num_tiles);
    const struct fold_tile *t = &f->tiles[tile];
    uint32_t nb = tile_blocks_side(f->desc.tile_size) * tile_blocks_side(f->desc.tile_size);
    for (uint32_t b = 0; b < nb; b++)
        sum_var[b] = sum_var_sq[b] = sum_mean[b] = 0.0;
    size_t pixels = tile_pixels(f, tile);
    uint32_t w = tile_width(f, tile);
    /* Each block's pixels are added in pixel order, as fold_block_sums adds them: the same bits. */
    for (size_t i = 0; t->acc && i < pixels; i++) {
        uint32_t b = pixel_block(f, w, i);
        double pv, pv2, pmu;
        pixel_sums(&t->acc[i].b, &pv, &pv2, &pmu);
        sum_var[b] += pv;
        sum_var_sq[b] += pv2;
        sum_mean[b] += pmu;
    }
}

void fold_blocks_worst(const struct fold *f, uint32_t tile, double floor, double bound, double *worst, uint32_t *over)
{
    CHECK(tile < f->num_tiles);
    const struct fold_tile *t = &f->tiles[tile];
    uint32_t nb = tile_blocks_side(f->desc.tile_size) * tile_blocks_side(f->desc.tile_size);
    for (uint32_t b = 0; b < nb; b++) {
        worst[b] = 0.0;
        over[b] = 0;
    }
    size_t pixels = tile_pixels(f, tile);
    uint32_t w = tile_width(f, tile);
    double b2 = bound * bound;
    for (size_t i = 0; t->acc && i < pixels; i++) {
        uint32_t b = pixel_block(f, w, i);
        double pv, pv2, pmu;
        pixel_sums(&t->acc[i].b, &pv, &pv2, &pmu);
        double scale = pmu > floor ? pmu : floor;
        double r = scale > 0.0 && pv > 0.0 ? pv / (scale * scale) : 0.0;
        worst[b] = r > worst[b] ? r : worst[b];
        over[b] += r > b2;
    }
}

struct fold_est {
    struct image_desc desc;
    uint32_t num_tiles, tiles_x;
    uint8_t *given;             /* per tile */
    double (*sums)[2];          /* per given tile: its pixels' sums of (variance, mean), in pixel order */
    uint64_t saturated;         /* pixels of every given tile with a saturated variance */
};

struct fold_est *fold_est_new(const struct image_desc *desc)
{
    struct fold_est *e = mem_calloc(1, sizeof *e);
    e->desc = *desc;
    e->tiles_x = imgio_tiles_x(desc);
    e->num_tiles = e->tiles_x * imgio_tiles_y(desc);
    e->given = mem_calloc(e->num_tiles ? e->num_tiles : 1, 1);
    e->sums = mem_calloc(e->num_tiles ? e->num_tiles : 1, sizeof *e->sums);
    return e;
}

void fold_est_reset(struct fold_est *e)
{
    memset(e->given, 0, e->num_tiles ? e->num_tiles : 1);
    e->saturated = 0;
}

void fold_est_free(struct fold_est **ep)
{
    struct fold_est *e = *ep;
    if (!e)
        return;
    free(e->given);
    free(e->sums);
    free(e);
    *ep = NULL;
}

void fold_est_tile_sums(const struct image_desc *desc, uint32_t tile, const float *px, struct fold_est_sums *out)
{
    size_t pixels = desc_tile_pixels(desc, imgio_tiles_x(desc), tile), nc = desc->num_channels;
    double sv = 0.0, sm = 0.0;
    uint64_t saturated = 0;
    for (size_t i = 0; i < pixels; i++) {
        const float *p = &px[i * nc];
        sv += ((double)p[CH_VAR_R] + p[CH_VAR_G] + p[CH_VAR_B]) / 3.0;
        sm += ((double)p[CH_R] + p[CH_G] + p[CH_B]) / 3.0;
        saturated += p[CH_VAR_R] == FLT_MAX || p[CH_VAR_G] == FLT_MAX || p[CH_VAR_B] == FLT_MAX;
    }
    out->var = sv;
    out->mean = sm;
    out->saturated = saturated;
}

void fold_est_put(struct fold_est *e, uint32_t tile, const struct fold_est_sums *sums)
{
    CHECK(tile < e->num_tiles && !e->given[tile]);
    e->given[tile] = 1;
    e->saturated += sums->saturated;
    e->sums[tile][0] = sums->var;
    e->sums[tile][1] = sums->mean;
}

void fold_est_add(struct fold_est *e, uint32_t tile, const float *px)
{
    struct fold_est_sums s;
    fold_est_tile_sums(&e->desc, tile, px, &s);
    fold_est_put(e, tile, &s);
}

double fold_est_result(const struct fold_est *e, uint64_t *saturated)
{
    double sum_var = 0.0, sum_mean = 0.0;
    uint64_t pixels = 0;
    for (uint32_t t = 0; t < e->num_tiles; t++) /* tile order: the same bits for any arrival order */
        if (e->given[t]) {
            sum_var += e->sums[t][0];
            sum_mean += e->sums[t][1];
            pixels += desc_tile_pixels(&e->desc, e->tiles_x, t);
        }
    *saturated = e->saturated;
    return pixels && sum_mean > 0.0 ? sqrt(sum_var / (double)pixels) / (sum_mean / (double)pixels) : 0.0;
}
