/* The chunk check and its thread pool (check.h). Items move submitted (the loop's) -> todo
 * -> a checking thread -> done -> ready (the loop's); todo and done are under one mutex,
 * and an eventfd is readable exactly while done is not empty (written when it stops being
 * empty, read when the loop takes it all), so the master's zmq_poll wakes for verdicts.
 * Decode buffers are reused through a free list. */
#include "check.h"
#include "journal.h"
#include "base/log.h"
#include "render/aov.h"
#include "render/integrator.h"
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <unistd.h>

int chunk_check(const struct check_ctx *c, uint32_t unit, const uint8_t *chunk, size_t chunk_size, float *out,
                char *err, size_t errlen)
{
    uint32_t tile = unit % c->num_tiles;
    uint32_t tiles_x = imgio_tiles_x(&c->desc);
    uint32_t tx = tile % tiles_x, ty = tile / tiles_x, x0, y0, w, h;
    imgio_tile_rect(&c->desc, tx, ty, &x0, &y0, &w, &h);
    if (imgio_decode_tile(&c->desc, tx, ty, chunk, chunk_size, out, err, errlen) != 0)
        return 0;
    struct tile_layout lay;
    tile_layout_from_desc(&lay, &c->desc);
    /* The first pixel with a non-finite beauty value or bad AOVs decides (the beauty first
     * on the same pixel). */
    size_t pixels = (size_t)w * h, bad_aov = lay.aovs ? aov_tile_first_invalid(&lay, out, pixels, c->num_objects,
                                                                             c->num_materials)
                                                     : pixels;
    for (size_t i = 0; i < pixels && i <= bad_aov; i++) {
        const float *px = &out[i * lay.num_channels];
        for (int ch = 0; ch < TILE_NUM_CHANNELS; ch++)
            if (!isfinite(px[ch])) {
                str_fmt(err, errlen, "non-finite pixel value in tile %u", tile);
                return -1;
            }
    }
    if (bad_aov < pixels) {
        str_fmt(err, errlen, "tile %u: AOV value out of range", tile);
        return 0;
    }
    for (size_t i = 0; c->passes > 1 && i < (size_t)w * h; i++) {
        const float *px = &out[i * lay.num_channels];
        if (!((px[CH_A] >= 0.0f && px[CH_A] <= 1.0f) || px[CH_A] == PASS_ALPHA_NONE) || px[CH_VAR_R] < 0.0f ||
            px[CH_VAR_G] < 0.0f || px[CH_VAR_B] < 0.0f) {
            str_fmt(err, errlen, "tile %u pass %u: coverage or variance out of range", tile, unit / c->num_tiles);
            return 0;
        }
    }
    return 1;
}

struct checker {
    pthread_mutex_t mu;
    pthread_cond_t todo_cv, idle_cv;
    struct check_item *todo, **todo_tail, *done, *free_items;
    struct check_item *sub, **sub_tail; /* the loop's: submitted, not yet handed to the threads */
    uint32_t num_sub;
    struct check_item *ready;  /* the loop's: verdicts taken from done, not yet returned */
    uint32_t checking, pending; /* pending: the loop's */
    int stop, efd;
    struct check_ctx ctx;
    uint64_t gen;              /* bumped by each checker_set_ctx (the threads' encoders follow it) */
    size_t pixels_per_item;
    pthread_t *threads;
    uint32_t num_threads;
};

/* Encodes a CHECK_ENCODE item with the thread's encoder (made again when the context
 * changed, gen). */
static void encode_item(const struct checker *c, struct check_item *it, struct imgio_encoder **enc, uint64_t *enc_gen,
                        uint64_t gen)
{
    if (*enc && *enc_gen != gen)
        imgio_encoder_free(enc);
    if (!*enc) {
        *enc = imgio_encoder_new(&c->ctx.out_desc, it->err, sizeof it->err);
        *enc_gen = gen;
    }
    uint32_t tiles_x = imgio_tiles_x(&c->ctx.out_desc);
    it->verdict = *enc && imgio_encode_tile(*enc, it->unit % tiles_x, it->unit / tiles_x, it->pixels, &it->record,
                                            &it->record_size, it->err, sizeof it->err) == 0;
}

static void *check_thread(void *arg)
{
    struct checker *c = arg;
    struct imgio_encoder *enc = NULL;
    uint64_t enc_gen = 0;
    void *scratch = NULL; /* fold_run's */
    size_t scratch_size = 0;
    pthread_mutex_lock(&c->mu);
    for (;;) {
        while (!c->todo && !c->stop)
            pthread_cond_wait(&c->todo_cv, &c->mu);
        if (!c->todo)
            break;
        struct check_item *it = c->todo;
        c->todo = it->next;
        if (!c->todo)
            c->todo_tail = &c->todo;
        c->checking++;
        uint64_t gen = c->gen;
        pthread_mutex_unlock(&c->mu);
        if (it->kind == CHECK_FOLD) {
            fold_run(c->ctx.fold, it->units, &scratch, &scratch_size, it->pixels, &it->stats);
            if (fold_units_final(it->units)) {
                fold_units_free(&it->units);
                fold_est_tile_sums(&c->ctx.out_desc, it->unit, it->pixels, &it->est);
                encode_item(c, it, &enc, &enc_gen, gen);
            } else {
                it->verdict = 1; /* a batch: its units stay with the item, back to the fold (fold_units_return) */
            }
        } else if (it->kind == CHECK_ENCODE) {
            encode_item(c, it, &enc, &enc_gen, gen);
        } else {
            it->verdict = chunk_check(&c->ctx, it->unit, it->chunk, it->chunk_size, it->pixels, it->err,
                                      sizeof it->err);
            if (it->verdict == 1 && c->ctx.journal)
                it->record = journal_record(it->unit, &it->stats, it->chunk, it->chunk_size, &it->record_size);
            if (it->verdict == 1 && c->ctx.keep_units) /* the fold's copy: its page faults here, not in the loop */
                it->keep = fold_unit_copy(c->ctx.fold, it->unit % c->ctx.num_tiles, it->pixels);
        }
        pthread_mutex_lock(&c->mu);
        c->checking--;
        it->next = c->done;
        uint64_t one = 1;
        if (!c->done && write(c->efd, &one, sizeof one) != sizeof one) /* readable already while done is not empty */
            log_debug("checker: eventfd write failed");
        c->done = it;
        if (!c->todo && !c->checking)
            pthread_cond_broadcast(&c->idle_cv);
    }
    pthread_mutex_unlock(&c->mu);
    imgio_encoder_free(&enc);
    free(scratch);
    return NULL;
}

struct checker *checker_new(uint32_t threads)
{
    struct checker *c = mem_calloc(1, sizeof *c);
    pthread_mutex_init(&c->mu, NULL);
    pthread_cond_init(&c->todo_cv, NULL);
    pthread_cond_init(&c->idle_cv, NULL);
    c->todo_tail = &c->todo;
    c->sub_tail = &c->sub;
    c->efd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    CHECK(c->efd >= 0);
    c->threads = mem_calloc(threads, sizeof *c->threads);
    for (uint32_t i = 0; i < threads; i++)
        CHECK(pthread_create(&c->threads[i], NULL, check_thread, c) == 0);
    c->num_threads = threads;
    return c;
}

static void free_list(struct check_item *it)
{
    while (it) {
        struct check_item *next = it->next;
        net_payload_free(&it->payload);
        fold_units_free(&it->units);
        free(it->record);
        free(it->keep);
        free(it->pixels);
        free(it);
        it = next;
    }
}

void checker_free(struct checker **cp)
{
    struct checker *c = *cp;
    if (!c)
        return;
    pthread_mutex_lock(&c->mu);
    c->stop = 1;
    pthread_cond_broadcast(&c->todo_cv);
    pthread_mutex_unlock(&c->mu);
    for (uint32_t i = 0; i < c->num_threads; i++)
        pthread_join(c->threads[i], NULL);
    free_list(c->sub);
    free_list(c->todo);
    free_list(c->done);
    free_list(c->ready);
    free_list(c->free_items);
    close(c->efd);
    pthread_cond_destroy(&c->todo_cv);
    pthread_cond_destroy(&c->idle_cv);
    pthread_mutex_destroy(&c->mu);
    free(c->threads);
    free(c);
    *cp = NULL;
}

void checker_wait_idle(struct checker *c)
{
    checker_flush(c);
    pthread_mutex_lock(&c->mu);
    while (c->todo || c->checking)
        pthread_cond_wait(&c->idle_cv, &c->mu);
    pthread_mutex_unlock(&c->mu);
}

void checker_set_ctx(struct checker *c, const struct check_ctx *ctx, size_t pixels_per_item)
{
    checker_wait_idle(c);
    c->ctx = *ctx;
    c->gen++;
    if (pixels_per_item != c->pixels_per_item) {
        free_list(c->free_items);
        c->free_items = NULL;
        c->pixels_per_item = pixels_per_item;
    }
}

/* Items and the free list belong to the loop's thread; only todo/done cross threads. */
struct check_item *checker_item_new(struct checker *c)
{
    struct check_item *it = c->free_items;
    if (it) {
        c->free_items = it->next;
        float *px = it->pixels;
        memset(it, 0, sizeof *it);
        it->pixels = px;
    } else {
        it = mem_calloc(1, sizeof *it);
        it->pixels = mem_alloc(sizeof(float) * (c->pixels_per_item ? c->pixels_per_item : 1));
    }
    return it;
}

void checker_item_free(struct checker *c, struct check_item *it)
{
    net_payload_free(&it->payload);
    fold_units_free(&it->units);
    free(it->record);
    it->record = NULL;
    free(it->keep);
    it->keep = NULL;
    it->next = c->free_items;
    c->free_items = it;
}

void checker_submit(struct checker *c, struct check_item *it)
{
    it->next = NULL;
    *c->sub_tail = it;
    c->sub_tail = &it->next;
    c->num_sub++;
    c->pending++;
}

void checker_flush(struct checker *c)
{
    if (!c->sub)
        return;
    pthread_mutex_lock(&c->mu);
    *c->todo_tail = c->sub;
    c->todo_tail = c->sub_tail;
    if (c->num_sub > 1)
        pthread_cond_broadcast(&c->todo_cv);
    else
        pthread_cond_signal(&c->todo_cv);
    pthread_mutex_unlock(&c->mu);
    c->sub = NULL;
    c->sub_tail = &c->sub;
    c->num_sub = 0;
}

struct check_item *checker_take(struct checker *c)
{
    checker_flush(c);
    if (!c->ready) {
        pthread_mutex_lock(&c->mu);
        if (c->done) {
            c->ready = c->done;
            c->done = NULL;
            uint64_t v;
            if (read(c->efd, &v, sizeof v) != sizeof v)
                log_debug("checker: eventfd read failed");
        }
        pthread_mutex_unlock(&c->mu);
    }
    struct check_item *it = c->ready;
    if (it) {
        c->ready = it->next;
        c->pending--;
    }
    return it;
}

int checker_fd(const struct checker *c) { return c->efd; }

uint32_t checker_threads(const struct checker *c) { return c->num_threads; }

uint32_t checker_pending(struct checker *c) { return c->pending; }
