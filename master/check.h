/* The decode check of tile chunks, and a pool of threads that runs it off the master's
 * loop. A chunk is checked (chunk_check: it decodes in the frame's layout, finite pixels,
 * AOVs and pass values in range) before the master journals or acknowledges it; with a
 * pool the loop submits a RESULT and takes its verdict later, in any order, and decides
 * then, against the scheduler's state at that time, whether it still counts (master.c).
 * The pool also builds the journal record of a sane chunk, so the loop only appends it,
 * copies a multi-pass unit's pixels for the fold to keep (keep_units), and folds and
 * encodes the master's multi-pass tiles (CHECK_FOLD, CHECK_ENCODE items) with the error
 * estimate's sums of each. The loop's side batches:
 * items submitted in a pass reach the threads together (one lock, one wake-up) at its next
 * checker_take, checker_flush or checker_wait_idle, and checker_take takes every ready
 * verdict under one lock. The context (layout, counts) changes only while the pool is idle
 * (checker_wait_idle). Used by master/master.c; tested by tests/unit/test_check.c. */
#ifndef BRUME_CHECK_H
#define BRUME_CHECK_H
#include <stddef.h>
#include <stdint.h>
#include "image/imgio.h"
#include "render/tile.h"
#include "wire/net.h"
#include "fold.h"

/* What a chunk of unit u must be: u's tile is u % num_tiles of desc. */
struct check_ctx {
    struct image_desc desc;
    uint32_t num_tiles;
    uint32_t passes;          /* > 1: coverage in [0, 1] or PASS_ALPHA_NONE, variance >= 0 */
    uint32_t num_objects, num_materials; /* for the id AOVs */
    int journal;              /* the pool also builds a sane chunk's journal record (journal_record) */
    struct image_desc out_desc; /* the layout CHECK_ENCODE items are encoded in (the folded tiles') */
    const struct fold *fold;  /* what CHECK_FOLD items fold with (fold_run: its settings only) */
    int keep_units;           /* a sane RESULT's pixels are also copied into keep, exactly its unit's values
                               * (fold_unit_floats of fold), for the loop to hand to fold_add_take_own */
};

/* Decodes unit's chunk into out (tile_size^2 x desc.num_channels floats) and checks it.
 * 1 when sane; 0 when not (err says why); -1 when it decodes but holds non-finite values
 * (which the scene may cause). Pure apart from out and err. */
int chunk_check(const struct check_ctx *c, uint32_t unit, const uint8_t *chunk, size_t chunk_size, float *out,
                char *err, size_t errlen);

enum check_kind {
    CHECK_RESULT,             /* a RESULT's chunk: chunk_check (and its journal record) */
    CHECK_ENCODE,             /* a folded tile: pixels (unit is the tile, ctx.out_desc's layout) encoded into
                               * record (the chunk, record_size bytes); verdict 1, or 0 with err */
    CHECK_FOLD                /* a batch of a tile's units (fold_add_take): folded (fold_run); the tile's last
                               * into pixels (their relative errors added to stats, zero before), then
                               * encoded as CHECK_ENCODE; another comes back with units still set */
};

/* A RESULT waiting for or holding its verdict, or a tile to encode. The item owns the
 * received frame (payload): chunk points into it. */
struct check_item {
    enum check_kind kind;
    int32_t peer;
    uint8_t peer_id[NET_MAX_IDENTITY]; /* the connection it came from (a reused slot is another) */
    size_t peer_id_len;
    uint64_t job_id;
    uint32_t frame, unit, attempt;
    struct tile_stats stats;
    struct net_payload *payload;
    const uint8_t *chunk;
    uint32_t chunk_size;
    float *pixels;            /* decoded, tile_size^2 x FOLD_MAX_CHANNELS floats */
    int verdict;              /* chunk_check's */
    uint8_t *record;          /* with ctx.journal and a sane chunk: its journal record, record_size bytes */
    struct fold_units *units; /* CHECK_FOLD: taken over (freed by the pool once final; else back to the fold) */
    float *keep;              /* with ctx.keep_units, a sane CHECK_RESULT's copy of its pixels (or NULL) */
    int credit_owed;          /* the caller's: the worker's credit waits for this check (master.c on_result) */
    struct fold_est_sums est; /* CHECK_FOLD: the folded tile's sums for the error estimate */
    size_t record_size;
    char err[256];
    struct check_item *next;
};

struct checker;
/* A pool of threads (>= 1) checking threads. */
struct checker *checker_new(uint32_t threads);
void checker_free(struct checker **c);
/* Sets the context for the next items, each with a decode buffer of pixels_per_item
 * floats; waits until none is being checked first. */
void checker_set_ctx(struct checker *c, const struct check_ctx *ctx, size_t pixels_per_item);
/* Queues an item (taken over; its pixels buffer is the checker's): the threads get it at
 * the next checker_flush, checker_take or checker_wait_idle, with the others queued since. */
struct check_item *checker_item_new(struct checker *c);
void checker_submit(struct checker *c, struct check_item *it);
void checker_flush(struct checker *c);
/* A checked item, or NULL when none is ready now; give it back with checker_item_free.
 * Flushes first. */
struct check_item *checker_take(struct checker *c);
void checker_item_free(struct checker *c, struct check_item *it);
/* Readable (POLLIN) while checked items wait to be taken. */
int checker_fd(const struct checker *c);
/* The pool's threads. */
uint32_t checker_threads(const struct checker *c);
/* Items submitted and not yet taken. */
uint32_t checker_pending(struct checker *c);
/* Flushes, then blocks until every submitted item is checked (then checker_take returns
 * them all). */
void checker_wait_idle(struct checker *c);

#endif
