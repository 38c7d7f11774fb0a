/* Unit tests for the tile journal (master/journal.c): records survive a reopen with their
 * bytes and statistics; a journal cut at every byte recovers exactly the whole records
 * before the cut and appends after them; a flipped byte ends the journal there; another
 * job's journal is started afresh; a read error is an error, not a torn tail. Run by
 * `make unit`. */
#include <criterion/criterion.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/syscall.h>
#include <unistd.h>
#include "master/journal.h"

struct seen { uint32_t count; uint32_t tiles[64]; uint32_t sizes[64]; uint8_t first[64]; double err[64]; };

static int on_tile(void *ctx, uint32_t tile, const struct tile_stats *st, const uint8_t *chunk, uint32_t size)
{
    struct seen *s = ctx;
    s->tiles[s->count] = tile;
    s->sizes[s->count] = size;
    s->first[s->count] = size ? chunk[size - 1] : 0;
    s->err[s->count] = st->sum_rel_stderr;
    s->count++;
    return 0;
}

static void tmp_path(char *buf, size_t n)
{
    snprintf(buf, n, "/tmp/brume-journal-test.%d.%u", (int)getpid(), (unsigned)rand());
}

static struct blob_hash key_of(const char *s)
{
    struct blob_hash h;
    blob_hash_compute(s, strlen(s), &h);
    return h;
}

/* Writes n records (tile i, i*7+1 bytes of value i) and returns the file size after each. */
static void write_records(const char *path, uint32_t n, long *ends)
{
    struct journal *j;
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    struct blob_hash k = key_of("job");
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1, "%s", err);
    uint8_t chunk[200];
    for (uint32_t i = 0; i < n; i++) {
        memset(chunk, (int)i, sizeof chunk);
        struct tile_stats st = {.samples = i, .rays = 2 * i, .sum_rel_stderr = 0.5 * i, .rel_stderr_pixels = i};
        cr_assert_eq(journal_append(j, i, &st, chunk, i * 7 + 1, err, sizeof err), 0, "%s", err);
        ends[i] = (long)j->end;
    }
    journal_free(&j);
    cr_assert_null(j, "journal_free nulls the caller's pointer");
    journal_free(&j); /* and a second call is harmless */
}

Test(journal, records_survive_reopen)
{
    char path[256];
    tmp_path(path, sizeof path);
    long ends[5];
    write_records(path, 5, ends);
    struct journal *j;
    struct seen s = {0};
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    struct blob_hash k = key_of("job");
    cr_assert_eq((j = journal_open(path, &k, 16, on_tile, &s, &rec, &torn, &other, err, sizeof err)) != NULL, 1);
    cr_assert_eq(rec, 5);
    cr_assert_eq(torn, 0);
    cr_assert_eq(other, 0);
    for (uint32_t i = 0; i < 5; i++) {
        cr_assert_eq(s.tiles[i], i);
        cr_assert_eq(s.sizes[i], i * 7 + 1);
        cr_assert_eq(s.first[i], (uint8_t)i);
        cr_assert_eq(s.err[i], 0.5 * i);
    }
    cr_assert_eq(journal_remove(&j), 0);
    cr_assert_neq(access(path, F_OK), 0);
}

/* A new journal of key k for `tiles` tiles at a fresh temporary path[256]. */
static struct journal *open_fresh(char *path, const struct blob_hash *k, uint32_t tiles)
{
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    tmp_path(path, 256);
    struct journal *j = journal_open(path, k, tiles, NULL, NULL, &rec, &torn, &other, err, sizeof err);
    cr_assert(j, "%s", err);
    return j;
}

/* Reopens path's journal, replaying into s: the records it holds (none torn). */
static uint32_t reopen(const char *path, const struct blob_hash *k, uint32_t tiles, struct seen *s, struct journal **j)
{
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    *j = journal_open(path, k, tiles, on_tile, s, &rec, &torn, &other, err, sizeof err);
    cr_assert(*j, "%s", err);
    cr_assert_eq(torn, 0);
    return rec;
}

/* Group commit: records written without a sync are pending until one journal_sync makes
 * all of them durable; they read back like appended ones. */
Test(journal, group_commit_syncs_a_batch)
{
    char path[256], err[256];
    struct blob_hash k = key_of("job");
    struct journal *j = open_fresh(path, &k, 16);
    cr_assert_eq(j->synced, j->end);
    uint8_t chunk[64];
    for (uint32_t i = 0; i < 4; i++) {
        memset(chunk, (int)i, sizeof chunk);
        struct tile_stats st = {.samples = i, .sum_rel_stderr = 0.25 * i};
        cr_assert_eq(journal_write(j, i + 3, &st, chunk, 10 + i, err, sizeof err), 0, "%s", err);
        cr_assert_lt(j->synced, j->end, "a written record is pending until the sync");
    }
    cr_assert_eq(journal_sync(j, err, sizeof err), 0, "%s", err);
    cr_assert_eq(j->synced, j->end);
    cr_assert_eq(journal_sync(j, err, sizeof err), 0, "nothing pending: a no-op");
    journal_free(&j);
    struct seen s = {0};
    cr_assert_eq(reopen(path, &k, 16, &s, &j), 4);
    for (uint32_t i = 0; i < 4; i++) {
        cr_assert_eq(s.tiles[i], i + 3);
        cr_assert_eq(s.sizes[i], 10 + i);
        cr_assert_eq(s.first[i], (uint8_t)i);
    }
    cr_assert_eq(journal_remove(&j), 0);
}

/* With the sync thread, appends only queue their records: the thread writes them in order
 * before its sync, journal_durable and the eventfd follow it, journal_sync waits for it,
 * and the records (some built apart by journal_record) read back in order. */
Test(journal, sync_thread_writes_queued_records_in_order)
{
    char path[256], err[256];
    struct blob_hash k = key_of("job");
    struct journal *j = open_fresh(path, &k, 64);
    cr_assert_eq(journal_syncer_start(j, err, sizeof err), 0, "%s", err);
    cr_assert_geq(journal_sync_fd(j), 0);
    uint8_t chunk[300];
    for (uint32_t i = 0; i < 40; i++) {
        memset(chunk, (int)(i * 7), sizeof chunk);
        struct tile_stats st = {.samples = i};
        if (i % 2) {
            size_t n;
            uint8_t *r = journal_record(i, &st, chunk, 100 + i, &n);
            cr_assert_eq(journal_write_record(j, i, r, n, err, sizeof err), 0, "%s", err);
        } else {
            cr_assert_eq(journal_write(j, i, &st, chunk, 100 + i, err, sizeof err), 0, "%s", err);
        }
        if (i % 8 == 7)
            journal_sync_async(j);
    }
    cr_assert_eq(journal_sync(j, err, sizeof err), 0, "%s", err);
    cr_assert_eq(journal_durable(j, err, sizeof err), (int64_t)j->end);
    journal_free(&j);
    struct seen s = {0};
    cr_assert_eq(reopen(path, &k, 64, &s, &j), 40);
    for (uint32_t i = 0; i < 40; i++) {
        cr_assert_eq(s.tiles[i], i);
        cr_assert_eq(s.sizes[i], 100 + i);
        cr_assert_eq(s.first[i], (uint8_t)(i * 7));
    }
    cr_assert_eq(journal_remove(&j), 0);
}

Test(journal, cut_at_every_byte_recovers_whole_records, .timeout = 60)
{
    char path[256];
    tmp_path(path, sizeof path);
    long ends[4];
    write_records(path, 4, ends);
    FILE *f = fopen(path, "rb");
    static uint8_t full[8192];
    size_t size = fread(full, 1, sizeof full, f);
    fclose(f);
    cr_assert_eq((long)size, ends[3]);
    struct blob_hash k = key_of("job");
    for (size_t cut = 0; cut <= size; cut++) {
        f = fopen(path, "wb");
        fwrite(full, 1, cut, f);
        fclose(f);
        uint32_t want = 0;
        while (want < 4 && ends[want] <= (long)cut)
            want++;
        struct journal *j;
        struct seen s = {0};
        uint32_t rec;
        uint64_t torn;
        int other;
        char err[256];
        cr_assert_eq((j = journal_open(path, &k, 16, on_tile, &s, &rec, &torn, &other, err, sizeof err)) != NULL, 1);
        cr_assert_eq(rec, want, "cut at %zu: %u records, want %u", cut, rec, want);
        /* Appending after recovery gives a journal with want + 1 records. */
        uint8_t c[3] = {9, 9, 9};
        struct tile_stats st = {0};
        cr_assert_eq(journal_append(j, 9, &st, c, 3, err, sizeof err), 0);
        journal_free(&j);
        struct seen s2 = {0};
        cr_assert_eq((j = journal_open(path, &k, 16, on_tile, &s2, &rec, &torn, &other, err, sizeof err)) != NULL, 1);
        cr_assert_eq(rec, want + 1, "cut at %zu", cut);
        cr_assert_eq(s2.tiles[want], 9);
        cr_assert_eq(torn, 0);
        journal_free(&j);
    }
    unlink(path);
}

Test(journal, flipped_byte_ends_the_journal)
{
    char path[256];
    tmp_path(path, sizeof path);
    long ends[4];
    write_records(path, 4, ends);
    FILE *f = fopen(path, "r+b");
    fseek(f, ends[1] + 20, SEEK_SET); /* inside record 2 */
    fputc(0x5a, f);
    fclose(f);
    struct journal *j;
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    struct blob_hash k = key_of("job");
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1);
    cr_assert_eq(rec, 2);
    cr_assert_eq(torn, (uint64_t)(ends[3] - ends[1]));
    journal_remove(&j);
}

Test(journal, another_job_starts_afresh)
{
    char path[256];
    tmp_path(path, sizeof path);
    long ends[3];
    write_records(path, 3, ends);
    struct journal *j;
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    struct blob_hash k = key_of("another job");
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1);
    cr_assert_eq(rec, 0);
    cr_assert_eq(other, 1);
    journal_free(&j);
    k = key_of("job"); /* the old records are gone for good */
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1);
    cr_assert_eq(rec, 0);
    cr_assert_eq(other, 1);
    journal_remove(&j);
}

Test(journal, tile_out_of_range_is_not_replayed)
{
    char path[256];
    tmp_path(path, sizeof path);
    long ends[5];
    write_records(path, 5, ends); /* tiles 0..4 of 16 */
    struct journal *j;
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    struct blob_hash k = key_of("job");
    /* Same key but fewer tiles: the header differs, so nothing is trusted. */
    cr_assert_eq((j = journal_open(path, &k, 3, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1);
    cr_assert_eq(rec, 0);
    journal_remove(&j);
}

/* A second master on the same output (a journal open elsewhere) is refused with the file's
 * name, and the first one's records stay; once it is closed the journal opens again. */
Test(journal, second_open_is_refused_while_the_first_holds_it, .timeout = 30)
{
    char path[256];
    tmp_path(path, sizeof path);
    long ends[3];
    write_records(path, 3, ends);
    struct journal *j, *j2;
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    struct blob_hash k = key_of("job"), k2 = key_of("another job");
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1, "%s", err);
    cr_assert_eq(rec, 3);
    err[0] = '\0';
    j2 = journal_open(path, &k2, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err);
    cr_assert_null(j2, "a journal held open by another master is not taken over");
    cr_assert(strstr(err, path) && strstr(err, "in use by another master"), "%s", err);
    journal_free(&j);
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1, "%s", err);
    cr_assert_eq(rec, 3, "the first master's records are intact");
    cr_assert_eq(other, 0);
    journal_remove(&j);
}

/* A file at the journal's name that holds no intact header (garbage, a damaged header) is
 * started afresh and said so (*other_job = 2), unlike an empty or missing one. */
Test(journal, damaged_header_is_reported)
{
    char path[256];
    tmp_path(path, sizeof path);
    long ends[3];
    write_records(path, 3, ends);
    FILE *f = fopen(path, "r+b");
    cr_assert_not_null(f);
    fseek(f, 20, SEEK_SET); /* inside the key: the header's checksum fails */
    fputc(0x5a, f);
    fclose(f);
    struct journal *j;
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256];
    struct blob_hash k = key_of("job");
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1, "%s", err);
    cr_assert_eq(rec, 0);
    cr_assert_eq(other, 2, "a damaged header is reported, not taken for a fresh file");
    journal_free(&j);
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1, "%s", err);
    cr_assert_eq(other, 0, "the journal started afresh is ours");
    journal_remove(&j);
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1, "%s", err);
    cr_assert_eq(other, 0, "a new journal is no news");
    journal_remove(&j);
}

/* pread as the journal calls it, with an I/O error injected while fail_pread is set
 * (this binary's pread: the journal's reads go through it, everything else passes). */
static volatile int fail_pread;
ssize_t pread(int fd, void *buf, size_t n, off_t off)
{
    if (fail_pread) {
        errno = EIO;
        return -1;
    }
    return syscall(SYS_pread64, fd, buf, n, off);
}

/* A journal that cannot be read (EIO) is an error naming it, not a torn tail: nothing of
 * it is cut or started afresh, and once it reads again its records are all there. */
Test(journal, read_error_is_an_error_not_a_truncation)
{
    char path[256];
    tmp_path(path, sizeof path);
    long ends[3];
    write_records(path, 3, ends);
    struct journal *j;
    uint32_t rec;
    uint64_t torn;
    int other;
    char err[256] = "";
    struct blob_hash k = key_of("job");
    fail_pread = 1;
    j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err);
    fail_pread = 0;
    cr_assert_null(j, "an unreadable journal is not opened");
    cr_assert(strstr(err, path) && strstr(err, "cannot read the journal"), "%s", err);
    cr_assert_eq((j = journal_open(path, &k, 16, NULL, NULL, &rec, &torn, &other, err, sizeof err)) != NULL, 1, "%s", err);
    cr_assert_eq(rec, 3, "the records are intact");
    cr_assert_eq(torn, 0);
    journal_remove(&j);
}
