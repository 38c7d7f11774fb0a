/* Tile journal (see journal.h). Layout, little-endian:
 *   header: "BRUMJNL1", key (32 bytes), u32 num_tiles, BLAKE2b-256 of those 44 bytes
 *   record: u32 "TREC", u32 tile, u32 chunk_size, stats (4 x u64, f64, u32), chunk bytes,
 *           BLAKE2b-256 of everything before it in the record
 * A reader trusts nothing: sizes are checked against the file before use. */
#include "journal.h"
#include "base/asset.h"
#include "base/bytes.h"
#include "base/log.h"
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>

#define HEADER_BODY (8 + BLOB_HASH_SIZE + 4)
#define HEADER_SIZE (HEADER_BODY + BLOB_HASH_SIZE)
#define REC_HEAD (4 + 4 + 4 + 4 * 8 + 8 + 4)
#define REC_MAGIC 0x43455254u /* "TREC" */
static const char k_magic[8] = {'B', 'R', 'U', 'M', 'J', 'N', 'L', '1'};

static void hand_over(struct journal *j);

static int write_all(int fd, const void *data, size_t n)
{
    const uint8_t *p = data;
    while (n > 0) {
        ssize_t w = write(fd, p, n);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0) {
            if (w == 0)
                errno = ENOSPC;
            return -1;
        }
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

/* The whole file into *data (*size bytes: fewer if it shrank while read). -1 on an I/O
 * error (errno): not a short journal, whose torn tail would be cut, intact records too. */
static int read_file(int fd, uint8_t **data, size_t *size)
{
    struct stat st;
    if (fstat(fd, &st) != 0)
        return -1;
    size_t n = (size_t)st.st_size, got = 0;
    *data = mem_alloc(n ? n : 1);
    while (got < n) {
        ssize_t r = pread(fd, *data + got, n - got, (off_t)got);
        if (r < 0 && errno == EINTR)
            continue;
        if (r < 0)
            return -1;
        if (r == 0)
            break;
        got += (size_t)r;
    }
    *size = got;
    return 0;
}

/* Opens the journal and takes its lock (flock, exclusive): a second master rendering to
 * the same output would replay a journal still being written, write its records over the
 * first one's at its own file offset, or (another job) start the file afresh under it, so
 * records already acknowledged to workers would be lost. A lock held by a master that was
 * just killed goes with the process: it is waited for up to JOURNAL_LOCK_WAIT_MS. A file
 * that was removed or replaced while we waited (the master before us finished) is opened
 * again. 0, or -1 with the reason (the fd closed), -2 when another master holds it. */
static int lock_open(struct journal *j, char *err, size_t errlen)
{
    const struct timespec nap = {0, 20 * 1000000L};
    for (uint32_t waited = 0;;) {
        j->fd = open(j->path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        if (j->fd < 0) {
            str_fmt(err, errlen, "%s: cannot open the journal: %s", j->path, strerror(errno));
            return -1;
        }
        int locked = flock(j->fd, LOCK_EX | LOCK_NB) == 0;
        if (!locked && errno != EWOULDBLOCK)
            return 0; /* a file system without locks: as before */
        struct stat held, named;
        if (locked && fstat(j->fd, &held) == 0 && stat(j->path, &named) == 0 && held.st_dev == named.st_dev &&
            held.st_ino == named.st_ino)
            return 0;
        close(j->fd);
        j->fd = -1;
        if (!locked && waited >= JOURNAL_LOCK_WAIT_MS) {
            str_fmt(err, errlen, "%s: the journal is in use by another master rendering to the same output; "
                    "not starting a second one", j->path);
            return -2;
        }
        nanosleep(&nap, NULL);
        waited += 20;
    }
}

static int start_fresh(struct journal *j, const struct blob_hash *key, uint32_t num_tiles, char *err, size_t errlen)
{
    uint8_t h[HEADER_SIZE];
    memcpy(h, k_magic, 8);
    memcpy(h + 8, key->bytes, BLOB_HASH_SIZE);
    bytes_put_u32(h + 8 + BLOB_HASH_SIZE, num_tiles);
    struct blob_hash sum;
    blob_hash_compute(h, HEADER_BODY, &sum);
    memcpy(h + HEADER_BODY, sum.bytes, BLOB_HASH_SIZE);
    if (ftruncate(j->fd, 0) != 0 || lseek(j->fd, 0, SEEK_SET) != 0 || write_all(j->fd, h, sizeof h) != 0 ||
        fdatasync(j->fd) != 0) {
        str_fmt(err, errlen, "%s: cannot write the journal header: %s", j->path, strerror(errno));
        return -1;
    }
    asset_fsync_parent(j->path);
    j->end = j->written = j->synced = HEADER_SIZE;
    return 0;
}

struct journal *journal_open(const char *path, const struct blob_hash *key, uint32_t num_tiles, journal_tile_fn fn,
                             void *ctx, uint32_t *recovered, uint64_t *torn_bytes, int *other_job, char *err,
                             size_t errlen)
{
    struct journal *j = mem_calloc(1, sizeof *j);
    j->fd = -1;
    *recovered = 0;
    *torn_bytes = 0;
    *other_job = 0;
    snprintf(j->path, sizeof j->path, "%s", path);
    int locked = lock_open(j, err, errlen);
    if (locked != 0) {
        journal_free(&j);
        errno = locked == -2 ? EBUSY : EIO;
        return NULL;
    }
    uint8_t *data = NULL;
    size_t size = 0;
    if (read_file(j->fd, &data, &size) != 0) {
        str_fmt(err, errlen, "%s: cannot read the journal: %s", path, strerror(errno));
        free(data);
        journal_free(&j);
        return NULL;
    }
    struct blob_hash sum;
    int header_ok = 0;
    if (size >= HEADER_SIZE && memcmp(data, k_magic, 8) == 0) {
        blob_hash_compute(data, HEADER_BODY, &sum);
        header_ok = memcmp(sum.bytes, data + HEADER_BODY, BLOB_HASH_SIZE) == 0;
    }
    if (!header_ok || memcmp(data + 8, key->bytes, BLOB_HASH_SIZE) != 0 ||
        bytes_get_u32(data + 8 + BLOB_HASH_SIZE) != num_tiles) {
        *other_job = header_ok ? 1 : size > 0 ? 2 : 0;
        free(data);
        if (start_fresh(j, key, num_tiles, err, errlen) != 0) {
            journal_free(&j);
            return NULL;
        }
        return j;
    }
    size_t pos = HEADER_SIZE;
    while (size - pos >= REC_HEAD + BLOB_HASH_SIZE) {
        const uint8_t *r = data + pos;
        uint32_t tile = bytes_get_u32(r + 4), chunk_size = bytes_get_u32(r + 8);
        if (bytes_get_u32(r) != REC_MAGIC || tile >= num_tiles || chunk_size > JOURNAL_MAX_CHUNK ||
            chunk_size > size - pos - REC_HEAD - BLOB_HASH_SIZE)
            break;
        size_t body = REC_HEAD + chunk_size;
        blob_hash_compute(r, body, &sum);
        if (memcmp(sum.bytes, r + body, BLOB_HASH_SIZE) != 0)
            break;
        struct tile_stats st;
        st.samples = bytes_get_u64(r + 12);
        st.rays = bytes_get_u64(r + 20);
        st.nan_samples = bytes_get_u64(r + 28);
        st.render_ns = bytes_get_u64(r + 36);
        uint64_t bits = bytes_get_u64(r + 44);
        memcpy(&st.sum_rel_stderr, &bits, sizeof bits);
        st.rel_stderr_pixels = bytes_get_u32(r + 52);
        if (!isfinite(st.sum_rel_stderr))
            break;
        if (fn && fn(ctx, tile, &st, r + REC_HEAD, chunk_size) != 0)
            break;
        (*recovered)++;
        pos += body + BLOB_HASH_SIZE;
    }
    free(data);
    *torn_bytes = size - pos;
    /* Cut a torn tail so the next record follows the last intact one. */
    if ((*torn_bytes && (ftruncate(j->fd, (off_t)pos) != 0 || fdatasync(j->fd) != 0)) ||
        lseek(j->fd, (off_t)pos, SEEK_SET) < 0) {
        str_fmt(err, errlen, "%s: cannot cut the torn end of the journal: %s", path, strerror(errno));
        journal_free(&j);
        return NULL;
    }
    j->end = j->written = j->synced = pos;
    return j;
}

uint8_t *journal_record(uint32_t tile, const struct tile_stats *st, const uint8_t *chunk, uint32_t chunk_size,
                        size_t *size)
{
    if (chunk_size > JOURNAL_MAX_CHUNK)
        return NULL;
    size_t n = REC_HEAD + chunk_size + BLOB_HASH_SIZE;
    uint8_t *r = mem_alloc(n);
    bytes_put_u32(r, REC_MAGIC);
    bytes_put_u32(r + 4, tile);
    bytes_put_u32(r + 8, chunk_size);
    bytes_put_u64(r + 12, st->samples);
    bytes_put_u64(r + 20, st->rays);
    bytes_put_u64(r + 28, st->nan_samples);
    bytes_put_u64(r + 36, st->render_ns);
    uint64_t bits;
    memcpy(&bits, &st->sum_rel_stderr, sizeof bits);
    bytes_put_u64(r + 44, bits);
    bytes_put_u32(r + 52, st->rel_stderr_pixels);
    if (chunk_size)
        memcpy(r + REC_HEAD, chunk, chunk_size);
    struct blob_hash sum;
    blob_hash_compute(r, REC_HEAD + chunk_size, &sum);
    memcpy(r + REC_HEAD + chunk_size, sum.bytes, BLOB_HASH_SIZE);
    *size = n;
    return r;
}

/* Appends a record to the file (the writing thread's side). 0, or errno with the file cut
 * back to its last intact record (no half record for the next append to follow). */
static int append_now(struct journal *j, const uint8_t *record, size_t size)
{
    if (write_all(j->fd, record, size) != 0) {
        int e = errno;
        if (ftruncate(j->fd, (off_t)j->written) == 0)
            lseek(j->fd, (off_t)j->written, SEEK_SET);
        return e;
    }
    j->written += size;
    return 0;
}

int journal_write_record(struct journal *j, uint32_t tile, uint8_t *record, size_t size, char *err,
                         size_t errlen)
{
    if (j->syncer_on) { /* held until journal_sync_async hands it over */
        struct journal_rec *r = mem_alloc(sizeof *r);
        *r = (struct journal_rec){record, size, tile, NULL};
        *j->held_tail = r;
        j->held_tail = &r->next;
        j->end += size;
        return 0;
    }
    int e = append_now(j, record, size);
    free(record);
    if (e) {
        str_fmt(err, errlen, "%s: cannot append tile %u to the journal: %s", j->path, tile, strerror(e));
        return -1;
    }
    j->end = j->written;
    return 0;
}

int journal_write(struct journal *j, uint32_t tile, const struct tile_stats *st, const uint8_t *chunk,
                  uint32_t chunk_size, char *err, size_t errlen)
{
    size_t n;
    uint8_t *r = journal_record(tile, st, chunk, chunk_size, &n);
    if (!r) {
        str_fmt(err, errlen, "%s: tile %u chunk of %u bytes is too large", j->path, tile, chunk_size);
        return -1;
    }
    return journal_write_record(j, tile, r, n, err, errlen);
}

int journal_sync(struct journal *j, char *err, size_t errlen)
{
    if (!j->syncer_on) {
        if (j->synced == j->end)
            return 0;
        j->syncs++;
        if (fdatasync(j->fd) != 0) {
            str_fmt(err, errlen, "%s: cannot sync the journal: %s", j->path, strerror(errno));
            return -1;
        }
        j->synced = j->end;
        return 0;
    }
    /* With a syncer: it writes what is queued and syncs; wait for it. */
    pthread_mutex_lock(&j->lock);
    hand_over(j);
    if (j->sync_want < j->end) {
        j->sync_want = j->end;
        pthread_cond_signal(&j->cond);
    }
    j->asked = j->sync_want;
    while (!j->sync_errno && j->synced < j->end)
        pthread_cond_wait(&j->done_cond, &j->lock);
    int e = j->sync_errno;
    if (e)
        str_fmt(err, errlen, "%s", j->sync_error);
    pthread_mutex_unlock(&j->lock);
    return e ? -1 : 0;
}

/* Moves the caller's held records to the thread's queue (under lock). */
static void hand_over(struct journal *j)
{
    if (!j->held)
        return;
    *j->queue_tail = j->held;
    j->queue_tail = j->held_tail;
    j->held = NULL;
    j->held_tail = &j->held;
}

static void free_queue(struct journal_rec *r)
{
    while (r) {
        struct journal_rec *next = r->next;
        free(r->data);
        free(r);
        r = next;
    }
}

static void *syncer_main(void *arg)
{
    struct journal *j = arg;
    pthread_mutex_lock(&j->lock);
    for (;;) {
        while (!j->syncer_stop && (j->sync_errno || j->sync_want <= j->synced))
            pthread_cond_wait(&j->cond, &j->lock);
        if (j->syncer_stop)
            break;
        /* Every record of the sync_want bytes is written already or in the queue now. */
        struct journal_rec *q = j->queue;
        j->queue = NULL;
        j->queue_tail = &j->queue;
        j->syncs++;
        pthread_mutex_unlock(&j->lock);
        int e = 0;
        uint32_t tile = 0;
        for (struct journal_rec *r = q; r && !e; r = r->next)
            if ((e = append_now(j, r->data, r->size)) != 0)
                tile = r->tile;
        free_queue(q);
        char why[600];
        if (e)
            str_fmt(why, sizeof why, "%s: cannot append tile %u to the journal: %s", j->path, tile, strerror(e));
        else if (fdatasync(j->fd) != 0 && (e = errno) != 0)
            str_fmt(why, sizeof why, "%s: cannot sync the journal: %s", j->path, strerror(e));
        pthread_mutex_lock(&j->lock);
        if (e) {
            j->sync_errno = e;
            memcpy(j->sync_error, why, sizeof why);
        } else if (j->synced < j->written) {
            j->synced = j->written;
        }
        pthread_cond_broadcast(&j->done_cond);
        j->rounds++;
        uint64_t one = 1;
        if (write(j->done_fd, &one, sizeof one) != sizeof one)
            log_debug("journal: eventfd write failed");
    }
    pthread_mutex_unlock(&j->lock);
    return NULL;
}

int journal_syncer_start(struct journal *j, char *err, size_t errlen)
{
    if (j->syncer_on)
        return 0;
    pthread_mutex_init(&j->lock, NULL);
    pthread_cond_init(&j->cond, NULL);
    pthread_cond_init(&j->done_cond, NULL);
    j->queue = NULL;
    j->queue_tail = &j->queue;
    j->held = NULL;
    j->held_tail = &j->held;
    j->rounds = j->rounds_seen = 0;
    j->written = j->end;
    j->syncer_stop = 0;
    j->sync_errno = 0;
    j->sync_want = j->asked = j->synced;
    j->done_fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    int rc = j->done_fd < 0 ? errno : pthread_create(&j->syncer, NULL, syncer_main, j);
    if (rc != 0) {
        if (j->done_fd >= 0)
            close(j->done_fd);
        pthread_mutex_destroy(&j->lock);
        pthread_cond_destroy(&j->cond);
        pthread_cond_destroy(&j->done_cond);
        str_fmt(err, errlen, "%s: cannot start the journal's sync thread: %s", j->path, strerror(rc));
        return -1;
    }
    j->syncer_on = 1;
    return 0;
}

void journal_sync_async(struct journal *j)
{
    if (!j->syncer_on || (!j->held && j->asked >= j->end)) /* nothing new since the last call */
        return;
    pthread_mutex_lock(&j->lock);
    hand_over(j);
    if (j->sync_want < j->end) {
        j->sync_want = j->end;
        pthread_cond_signal(&j->cond);
    }
    j->asked = j->sync_want;
    pthread_mutex_unlock(&j->lock);
}

int journal_sync_fd(const struct journal *j) { return j->syncer_on ? j->done_fd : -1; }

int64_t journal_durable(struct journal *j, char *err, size_t errlen)
{
    if (!j->syncer_on)
        return (int64_t)j->synced;
    pthread_mutex_lock(&j->lock);
    uint64_t synced = j->synced;
    int e = j->sync_errno;
    if (j->rounds != j->rounds_seen) { /* done_fd was written since: clear it (the thread writes it under lock) */
        uint64_t v;
        if (read(j->done_fd, &v, sizeof v) < 0)
            log_debug("journal: eventfd read failed");
        j->rounds_seen = j->rounds;
    }
    pthread_mutex_unlock(&j->lock);
    if (e) {
        pthread_mutex_lock(&j->lock);
        str_fmt(err, errlen, "%s", j->sync_error);
        pthread_mutex_unlock(&j->lock);
        return -1;
    }
    return (int64_t)synced;
}

static void syncer_stop(struct journal *j)
{
    if (!j->syncer_on)
        return;
    pthread_mutex_lock(&j->lock);
    j->syncer_stop = 1;
    pthread_cond_signal(&j->cond);
    pthread_mutex_unlock(&j->lock);
    pthread_join(j->syncer, NULL);
    close(j->done_fd);
    free_queue(j->queue);
    free_queue(j->held);
    j->held = NULL;
    j->held_tail = &j->held;
    j->queue = NULL;
    j->queue_tail = &j->queue;
    j->end = j->written;
    pthread_cond_destroy(&j->done_cond);
    pthread_mutex_destroy(&j->lock);
    pthread_cond_destroy(&j->cond);
    j->syncer_on = 0;
}

int journal_append(struct journal *j, uint32_t tile, const struct tile_stats *st, const uint8_t *chunk,
                   uint32_t chunk_size, char *err, size_t errlen)
{
    if (journal_write(j, tile, st, chunk, chunk_size, err, errlen) != 0)
        return -1;
    return journal_sync(j, err, errlen);
}

void journal_free(struct journal **jp)
{
    struct journal *j = *jp;
    if (!j)
        return;
    syncer_stop(j);
    if (j->fd >= 0)
        close(j->fd);
    free(j);
    *jp = NULL;
}

int journal_remove(struct journal **jp)
{
    struct journal *j = *jp;
    if (!j)
        return 0;
    char path[sizeof j->path];
    snprintf(path, sizeof path, "%s", j->path);
    /* Removed while still locked: a master waiting for the lock then finds the file gone
     * and starts its own instead of appending to this one. */
    int rc = path[0] ? unlink(path) : 0;
    journal_free(jp);
    if (path[0])
        asset_fsync_parent(path);
    return rc;
}
