/* The master's tile journal: an append-only file next to the output that holds every
 * accepted tile (ids, statistics, EXR chunk bytes) with a BLAKE2b checksum per record, so a
 * restarted master resumes without re-rendering them. Invariants: a record is appended
 * and fdatasync'ed before the worker that sent the tile is told to forget it (many
 * records may share one sync: group commit); a record whose checksum fails (a torn
 * write from a crash) ends the journal and is cut off. Called by master/master.c. */
#ifndef BRUME_JOURNAL_H
#define BRUME_JOURNAL_H
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>
#include "wire/blob.h"
#include "render/tile.h"

#define JOURNAL_MAX_CHUNK (48u * 1024u * 1024u)
#define JOURNAL_LOCK_WAIT_MS 2000u /* how long journal_open waits for another master's lock */

/* A record waiting for the sync thread to write it. */
struct journal_rec { uint8_t *data; size_t size; uint32_t tile; struct journal_rec *next; };

struct journal {
    int fd;
    uint64_t end;           /* bytes of records appended: written, or queued for the sync thread */
    uint64_t written;       /* bytes of intact records in the file (the sync thread's, while it runs) */
    uint64_t synced;        /* bytes known to be on disk (under lock while a syncer runs) */
    char path[4096];
    /* the background syncer (journal_syncer_start) */
    int syncer_on, syncer_stop, sync_errno;
    uint64_t sync_want;     /* sync at least this far */
    uint64_t syncs;         /* fdatasync calls made */
    pthread_t syncer;
    struct journal_rec *queue, **queue_tail; /* records for the thread to write, in order (under lock) */
    struct journal_rec *held, **held_tail; /* the caller's: records appended since its last journal_sync_async,
                                            * handed to the thread together then (one lock, one wake-up) */
    uint64_t asked;         /* the caller's copy of sync_want */
    uint64_t rounds, rounds_seen; /* syncs ended (each wrote done_fd; under lock), and those whose write
                                   * journal_durable consumed */
    char sync_error[600];   /* with sync_errno: what failed */
    pthread_cond_t done_cond; /* a round of the thread ended */
    int done_fd;            /* eventfd: readable after a sync of the syncer ended (journal_sync_fd) */
    pthread_mutex_t lock;
    pthread_cond_t cond;
};

/* Called for each intact record found when opening; return 0 to keep it, -1 to stop
 * reading (the record and everything after it are dropped). */
typedef int (*journal_tile_fn)(void *ctx, uint32_t tile, const struct tile_stats *stats, const uint8_t *chunk,
                               uint32_t chunk_size);

/* Opens or creates the journal at path for the job identified by key (the constructor:
 * it can fail, so it is not called journal_new). An existing journal of the same key is
 * replayed through fn (which may be NULL); one of another key, or a file that holds no
 * intact journal header, is started afresh (*other_job = 1 in the first case, 2 in the
 * second unless the file was empty). *recovered: records
 * replayed; *torn_bytes: bytes cut off the end. The journal is locked (flock) while open:
 * one that another process holds open (a second master on the same output) is refused
 * once JOURNAL_LOCK_WAIT_MS have passed (NULL with errno EBUSY: the caller writes nothing
 * of that output's, its stats included). The journal, or NULL with the reason. */
struct journal *journal_open(const char *path, const struct blob_hash *key, uint32_t num_tiles, journal_tile_fn fn,
                             void *ctx, uint32_t *recovered, uint64_t *torn_bytes, int *other_job, char *err,
                             size_t errlen);
/* Appends one record and syncs it to disk. On failure (e.g. a full disk) the journal is
 * cut back to its last intact record and -1 returned with the reason. */
int journal_append(struct journal *j, uint32_t tile, const struct tile_stats *stats, const uint8_t *chunk,
                   uint32_t chunk_size, char *err, size_t errlen);
/* Group commit: journal_write appends a record without syncing; journal_sync then makes
 * every record written so far durable with one fdatasync (a no-op when nothing is
 * pending). A record counts as safe only after journal_sync returned 0. Same failure
 * handling as journal_append. */
int journal_write(struct journal *j, uint32_t tile, const struct tile_stats *stats, const uint8_t *chunk,
                  uint32_t chunk_size, char *err, size_t errlen);
/* The same in two steps: journal_record builds unit tile's record (pure: any thread; NULL
 * when the chunk is too large; *size its bytes, free the result), journal_write_record
 * appends it and takes it over. With the sync thread running, both only queue the record
 * (without a lock: the thread gets the records queued since the last call at the next
 * journal_sync_async or journal_sync); the thread writes them before its next fdatasync
 * (in order), so the caller never waits for the file; a failed write (a full disk) is then reported by journal_durable and
 * journal_sync, naming the tile, and the file is cut back to its last intact record. */
uint8_t *journal_record(uint32_t tile, const struct tile_stats *stats, const uint8_t *chunk, uint32_t chunk_size,
                        size_t *size);
int journal_write_record(struct journal *j, uint32_t tile, uint8_t *record, size_t size, char *err,
                         size_t errlen);
int journal_sync(struct journal *j, char *err, size_t errlen);
/* Group commit that does not block the caller: a thread writes the queued records and
 * runs fdatasync whenever journal_sync_async handed it records (or asked for more than is
 * on disk), so the caller
 * keeps working (and handing out tiles) while the disk catches up. journal_durable returns
 * the bytes known to be on disk, or -1 with the reason once a write or sync failed.
 * journal_sync (blocking) waits for the thread to get that far; journal_free stops it
 * (records still queued are dropped, as a killed master's would be). 0, or -1 when no thread can start (then
 * the caller syncs with journal_sync). */
int journal_syncer_start(struct journal *j, char *err, size_t errlen);
void journal_sync_async(struct journal *j);
/* Readable (POLLIN) once a sync of the thread ended since the last journal_durable, so
 * that the caller's poll wakes for the ACKs it allows; -1 without a thread. */
int journal_sync_fd(const struct journal *j);
int64_t journal_durable(struct journal *j, char *err, size_t errlen);
/* Stops the syncer, closes the file and frees the journal; *jp becomes NULL (NULL is
 * fine). The file stays for the next master. */
void journal_free(struct journal **jp);
/* journal_free, then deletes the file (after the output file is safely in place). */
int journal_remove(struct journal **jp);

#endif
