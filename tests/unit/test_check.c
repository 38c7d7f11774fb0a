/* Unit tests for the chunk check and its thread pool (master/check.c): a valid chunk
 * passes and decodes to its pixels, a non-finite one is -1, garbage and a chunk of
 * another tile are refused, pass values out of range are refused; the pool gives every
 * submitted item back once, with the verdict chunk_check gives in the caller's thread,
 * and the journal record journal_record builds, and encodes CHECK_ENCODE items as the
 * caller would. Run by `make unit`. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "master/check.h"
#include "master/fold.h"
#include "master/journal.h"
#include "render/integrator.h"

static void make_ctx(struct check_ctx *c, uint32_t passes)
{
    memset(c, 0, sizeof *c);
    struct render_settings rs;
    memset(&rs, 0, sizeof rs);
    rs.width = 20;
    rs.height = 13;
    rs.tile_size = 8;
    tile_image_desc(&c->desc, &rs);
    c->num_tiles = imgio_tiles_x(&c->desc) * imgio_tiles_y(&c->desc);
    c->passes = passes;
}

/* Tile t's chunk of values from `value` (NAN or INFINITY reach the pixels as given). */
static uint8_t *chunk_of(const struct check_ctx *c, uint32_t t, float value, size_t *size)
{
    float px[64 * TILE_NUM_CHANNELS];
    for (size_t i = 0; i < 64; i++)
        for (int k = 0; k < TILE_NUM_CHANNELS; k++)
            px[i * TILE_NUM_CHANNELS + k] = k == CH_A ? 1.0f : value + 0.01f * (float)(i + k + t);
    char err[256];
    struct imgio_encoder *e = imgio_encoder_new(&c->desc, err, sizeof err);
    cr_assert(e, "%s", err);
    uint32_t tx = imgio_tiles_x(&c->desc);
    uint8_t *chunk = NULL;
    cr_assert_eq(imgio_encode_tile(e, t % tx, t / tx, px, &chunk, size, err, sizeof err), 0, "%s", err);
    imgio_encoder_free(&e);
    return chunk;
}

Test(check, verdicts)
{
    struct check_ctx c;
    make_ctx(&c, 1);
    float out[64 * FOLD_MAX_CHANNELS];
    char err[256];
    size_t n;
    uint8_t *good = chunk_of(&c, 4, 0.5f, &n);
    cr_assert_eq(chunk_check(&c, 4, good, n, out, err, sizeof err), 1, "%s", err);
    cr_assert_float_eq(out[CH_R], 0.5f + 0.04f, 1e-6f);
    /* the same chunk named as another tile: its header says tile 4 */
    cr_assert_eq(chunk_check(&c, 5, good, n, out, err, sizeof err), 0);
    uint8_t junk[64] = {1, 2, 3};
    cr_assert_eq(chunk_check(&c, 4, junk, sizeof junk, out, err, sizeof err), 0);
    uint8_t *nan = chunk_of(&c, 2, NAN, &n);
    cr_assert_eq(chunk_check(&c, 2, nan, n, out, err, sizeof err), -1);
    free(nan);
    /* with passes, a negative variance is out of range; unit 4 + tiles is tile 4's pass 1 */
    make_ctx(&c, 2);
    uint8_t *neg = chunk_of(&c, 4, -0.5f, &n);
    cr_assert_eq(chunk_check(&c, 4 + c.num_tiles, neg, n, out, err, sizeof err), 0);
    free(neg);
    free(good);
}

Test(check, pool_returns_every_item_with_its_verdict)
{
    struct check_ctx c;
    make_ctx(&c, 1);
    c.journal = 1;
    struct checker *k = checker_new(3);
    checker_set_ctx(k, &c, 64 * FOLD_MAX_CHANNELS);
    enum { N = 60 };
    int seen[N] = {0};
    uint8_t *chunks[N];
    for (uint32_t i = 0; i < N; i++) {
        struct check_item *it = checker_item_new(k);
        size_t n;
        uint32_t t = i % c.num_tiles;
        it->unit = t;
        it->peer = (int32_t)i; /* the item's name in this test */
        it->stats.samples = i;
        it->chunk = chunks[i] = chunk_of(&c, t, i % 3 == 0 ? INFINITY : 0.25f, &n); /* no payload: freed below */
        it->chunk_size = (uint32_t)n;
        checker_submit(k, it);
    }
    checker_wait_idle(k);
    cr_assert_eq(checker_pending(k), N);
    struct check_item *it;
    uint32_t taken = 0;
    while ((it = checker_take(k))) {
        uint32_t i = (uint32_t)it->peer;
        cr_assert(i < N && !seen[i]);
        seen[i] = 1;
        cr_assert_eq(it->verdict, i % 3 == 0 ? -1 : 1);
        if (it->verdict == 1) {
            size_t n;
            uint8_t *rec = journal_record(it->unit, &it->stats, it->chunk, it->chunk_size, &n);
            cr_assert_eq(it->record_size, n);
            cr_assert_eq(memcmp(it->record, rec, n), 0);
            free(rec);
        } else {
            cr_assert_null(it->record);
        }
        checker_item_free(k, it);
        free(chunks[i]);
        taken++;
    }
    cr_assert_eq(taken, N);
    cr_assert_eq(checker_pending(k), 0);
    checker_free(&k);
    cr_assert_null(k);
}

/* With keep_units (a multi-pass render's fold), each sane RESULT comes back with a copy
 * of exactly its unit's decoded values for fold_add_take_own; others without one. */
Test(check, pool_copies_the_units_the_fold_keeps)
{
    struct check_ctx c;
    make_ctx(&c, 2);
    struct fold *f = fold_new(&c.desc, 2, 1, SAMPLER_STREAMS);
    c.fold = f;
    c.keep_units = 1;
    struct checker *k = checker_new(2);
    checker_set_ctx(k, &c, 64 * FOLD_MAX_CHANNELS);
    enum { N = 2 * 6 };
    uint8_t *chunks[N];
    for (uint32_t i = 0; i < N; i++) {
        struct check_item *it = checker_item_new(k);
        size_t n;
        it->unit = i; /* tile i % 6, pass i / 6: edge tiles have fewer pixels */
        it->peer = (int32_t)i;
        it->chunk = chunks[i] = chunk_of(&c, i % c.num_tiles, i == 7 ? NAN : 0.25f, &n);
        it->chunk_size = (uint32_t)n;
        checker_submit(k, it);
    }
    checker_wait_idle(k);
    struct check_item *it;
    uint32_t kept = 0;
    while ((it = checker_take(k))) {
        uint32_t i = (uint32_t)it->peer, t = i % c.num_tiles;
        if (i == 7) {
            cr_assert_eq(it->verdict, -1);
            cr_assert_null(it->keep, "nothing kept of a refused chunk");
        } else {
            cr_assert_eq(it->verdict, 1, "%s", it->err);
            cr_assert_not_null(it->keep);
            uint32_t x0, y0, w, h;
            imgio_tile_rect(&c.desc, t % imgio_tiles_x(&c.desc), t / imgio_tiles_x(&c.desc), &x0, &y0, &w, &h);
            size_t nf = fold_unit_floats(f, t);
            cr_assert_eq(nf, (size_t)w * h * c.desc.num_channels);
            cr_assert_eq(memcmp(it->keep, it->pixels, sizeof(float) * nf), 0, "unit %u: the decoded values", i);
            kept++;
        }
        checker_item_free(k, it); /* frees what the loop did not take over */
        free(chunks[i]);
    }
    cr_assert_eq(kept, N - 1);
    checker_free(&k);
    fold_free(&f);
}

/* Encodes tile t of layout d from px in this thread, for comparison. */
static uint8_t *encode_here(const struct image_desc *d, uint32_t t, const float *px, size_t *size)
{
    char err[256];
    struct imgio_encoder *e = imgio_encoder_new(d, err, sizeof err);
    cr_assert(e, "%s", err);
    uint32_t tx = imgio_tiles_x(d);
    uint8_t *chunk = NULL;
    cr_assert_eq(imgio_encode_tile(e, t % tx, t / tx, px, &chunk, size, err, sizeof err), 0, "%s", err);
    imgio_encoder_free(&e);
    return chunk;
}

/* CHECK_ENCODE items (the master's folded tiles) come back encoded in the context's
 * out_desc, byte for byte as an encoder in the caller's thread makes them, also after the
 * context changed to another layout, and mixed with RESULT items. */
Test(check, pool_encodes_tiles_in_the_context_layout)
{
    struct check_ctx c;
    make_ctx(&c, 2);
    fold_output_desc(&c.desc, &c.out_desc);
    struct checker *k = checker_new(2);
    for (int round = 0; round < 2; round++) {
        if (round == 1)
            c.out_desc = c.desc; /* another layout: the threads' encoders must follow */
        checker_set_ctx(k, &c, 64 * FOLD_MAX_CHANNELS);
        enum { N = 24 };
        static float want_px[N][64 * FOLD_MAX_CHANNELS];
        uint8_t *results[N] = {0};
        for (uint32_t i = 0; i < N; i++) {
            struct check_item *it = checker_item_new(k);
            it->peer = (int32_t)i;
            if (i % 4 == 3) { /* a RESULT among them */
                size_t n;
                it->unit = i % c.num_tiles;
                it->chunk = results[i] = chunk_of(&c, it->unit, 0.25f, &n);
                it->chunk_size = (uint32_t)n;
            } else {
                it->kind = CHECK_ENCODE;
                it->unit = i % c.num_tiles;
                for (size_t v = 0; v < 64 * FOLD_MAX_CHANNELS; v++)
                    want_px[i][v] = it->pixels[v] = 0.001f * (float)(v * 7 + i * 13 + (uint32_t)round);
            }
            checker_submit(k, it);
        }
        uint32_t taken = 0;
        checker_wait_idle(k);
        struct check_item *it;
        while ((it = checker_take(k))) {
            uint32_t i = (uint32_t)it->peer;
            if (i % 4 == 3) {
                cr_assert_eq(it->kind, CHECK_RESULT);
                cr_assert_eq(it->verdict, 1, "%s", it->err);
            } else {
                cr_assert_eq(it->kind, CHECK_ENCODE);
                cr_assert_eq(it->verdict, 1, "%s", it->err);
                size_t n;
                uint8_t *want = encode_here(&c.out_desc, it->unit, want_px[i], &n);
                cr_assert_eq(it->record_size, n, "round %d item %u", round, i);
                cr_assert_eq(memcmp(it->record, want, n), 0);
                free(want);
            }
            checker_item_free(k, it);
            taken++;
        }
        cr_assert_eq(taken, N);
        for (uint32_t i = 0; i < N; i++)
            free(results[i]);
    }
    checker_free(&k);
}
