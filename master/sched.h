/* The master's tile scheduler as a pure state machine: the tile table, attempts, holders,
 * crash blame, bans and straggler copies. It does no I/O and reads no clock (callers pass
 * now_ms); it takes events and returns decisions, which master/master.c maps onto
 * messages, logs and counters. Invariants: a tile has at most SCHED_MAX_HOLDERS holders,
 * each with its own attempt; a result is taken only from a holder with its attempt and
 * only while the tile is not done; a tile is done exactly once. Tested by test_sched.c.
 *
 * A tile's life (per frame):
 *
 *              sched_frame_begin
 *                     |
 *                     v            give (oldest first; a re-issue to the front)
 *   +----------->  QUEUED  -----------------------------------+
 *   |                 |                                        |
 *   | last holder     | sched_tile_set_done (journal, --tiles) v
 *   | evicted or its  |  or sched_kept_valid              ASSIGNED <--+ straggler copy: an
 *   | result invalid  v                                   |  |  |    | idle worker, empty
 *   +------------  DONE  <----- first valid result ------+  |  +----+ queue, oldest in
 *   (blame +1 per        ^      (a later one: duplicate)     |         flight, 2nd holder
 *    crash; 3 distinct   +--- sched_kept_valid --------------+
 *    workers fail the job)
 */
#ifndef BRUME_SCHED_H
#define BRUME_SCHED_H
#include <stdint.h>

#define SCHED_MAX_HOLDERS 2     /* the first holder and one straggler copy */
#define SCHED_CRASHES_TO_FAIL 3 /* distinct workers a tile may take down before the job fails */
#define SCHED_FAILS_TO_BAN 3    /* invalid results in a row that ban a worker */
#define SCHED_NONFINITE_WAIT_MS 10000 /* a tile returned non-finite waits this long for another
                                       * worker before its only worker renders it again */

/* SCHED_HELD: not wanted yet (adaptive rounds, sched_hold_all): in no queue, goes out
 * only after sched_unhold; a result or kept copy of it is stale. */
enum sched_tile_state { SCHED_QUEUED, SCHED_ASSIGNED, SCHED_DONE, SCHED_HELD };

struct sched_tile {
    enum sched_tile_state state;
    uint32_t attempt;               /* last attempt number issued */
    uint32_t num_holders;
    int32_t holder[SCHED_MAX_HOLDERS];
    uint32_t holder_attempt[SCHED_MAX_HOLDERS];
    uint32_t holder_pos[SCHED_MAX_HOLDERS]; /* this tile's place in each holder's held list */
    uint64_t assigned_ms;
    uint32_t crashes;               /* distinct workers that died holding it */
    int requeued;                   /* its next assignment is a re-issue */
    int32_t nonfinite_by;           /* 1 + the worker whose result was non-finite (it does not get the
                                     * tile again while another worker is ready, nor within
                                     * SCHED_NONFINITE_WAIT_MS while none is), or 0 */
    uint64_t nonfinite_ms;          /* when that result came */
};

struct sched_worker {
    int gone, banned, ready;
    uint32_t threads, credits, in_flight;
    uint32_t *held, held_cap;       /* the tiles it holds: held[0 .. in_flight-1], in no order (an
                                     * eviction visits these, not every tile of the frame) */
    int isolated;                   /* holds a suspect tile: gets nothing else meanwhile */
    int blocked;                    /* a TILE to it could not be queued (sched_assign_undo): it gets
                                     * nothing until it is heard from again */
    uint64_t last_heard_ms, last_progress_ms, last_samples;
    uint32_t reported_stall_ms;
    uint32_t tiles_done;
    uint32_t fail_streak;           /* invalid results in a row */
};

#define SCHED_NOT_QUEUED UINT32_MAX /* qpos of a tile not in the queue */
#define SCHED_NONE UINT32_MAX       /* no tile: the in-flight list's ends and empty links */

/* Callers read these fields; only sched_* functions change them. */
struct sched {
    struct sched_tile *tiles;
    uint32_t num_tiles, tiles_done;
    uint32_t *queue;                /* tiles waiting for a worker, in the order they go out:
                                     * queue[0 .. q_count-1], a window into queue_buf */
    uint32_t q_count;
    uint32_t *queue_buf, q_cap;     /* the window's room: taking from the front and putting
                                     * back at the front or the back move no other tile */
    uint32_t *qpos;                 /* per tile: its place in queue_buf while queued, else
                                     * SCHED_NOT_QUEUED (removal without a search) */
    struct sched_worker *workers;   /* index = the caller's peer index; never removed */
    uint32_t num_workers;
    int32_t failed_tile;            /* the first tile blamed by SCHED_CRASHES_TO_FAIL workers, or -1 */
    uint32_t released;              /* queued tiles with an index below this may go out (sched_release) */
    uint32_t q_released;            /* queued tiles with an index below released: none, and
                                     * nothing in the queue can go out (no search of it) */
    uint32_t *fl_prev, *fl_next;    /* the tiles in flight with one holder (the straggler copies'
                                     * candidates), oldest first: by assigned_ms, then tile */
    uint8_t *fl_in;                 /* per tile: in that list */
    uint32_t fl_head, fl_tail;      /* SCHED_NONE when empty */
    uint64_t *takers;               /* bit i: worker i can take a unit now (ready, with a credit,
                                     * not gone, isolated or blocked): the assignment walks these
                                     * in index order, not every worker */
    uint32_t takers_words;          /* 64-bit words of takers allocated */
    uint32_t live;                  /* workers not gone */
};

/* Why a worker leaves. Only a death a tile could cause blames its tiles: not leaving, a
 * ban, or SIGKILL (an operator, a test, the OOM killer). */
enum sched_evict_kind { SCHED_LEFT, SCHED_SILENT, SCHED_STALLED, SCHED_DIED, SCHED_KILLED, SCHED_ERROR, SCHED_BANNED };

/* What an eviction did: tiles that went back to the queue, and the tile that has now taken
 * down SCHED_CRASHES_TO_FAIL workers (the job fails; -1 if none, reported once per frame). */
struct sched_eviction {
    uint32_t requeued;
    int32_t blamed_tile;
};

/* One assignment to send: TILE (tile, attempt) to worker. */
struct sched_assignment {
    uint32_t tile, attempt;
    int32_t worker;
    int straggler;                  /* a second copy of a tile in flight elsewhere */
    int reissue;                    /* the tile was given out before and came back */
};

/* The verdict on a RESULT before its chunk is checked. */
enum sched_result_verdict {
    SCHED_RESULT_CHECK,             /* from a holder with its attempt: check the chunk, then _valid or _invalid */
    SCHED_RESULT_DUPLICATE,         /* a straggler copy that lost the race (tile done, attempt issued) */
    SCHED_RESULT_STALE              /* an old attempt, or a tile the worker does not hold */
};

/* Why a worker should go, from sched_worker_health. */
enum sched_health { SCHED_HEALTHY, SCHED_HEALTH_SILENT, SCHED_HEALTH_STALLED, SCHED_HEALTH_STALL_REPORTED };

/* ---- lifetime and frames ---- */
struct sched *sched_new(uint32_t num_tiles);
void sched_free(struct sched **sp);
/* A new frame: every tile queued in order, blame cleared, every tile released; workers
 * keep their ban, streak and counts but must send READY again. */
void sched_frame_begin(struct sched *s);
/* Release limit: only queued tiles with an index below `limit` (capped at num_tiles) go
 * out; the rest wait in the queue until a later call raises it. The master
 * schedules units u = pass * tiles + tile and releases a pass's units once its photon map
 * is published. */
void sched_release(struct sched *s, uint32_t limit);
/* Adaptive rounds: after sched_frame_begin, every tile held (none queued); sched_unhold
 * queues a held tile at the back (the caller unholds in the order units should go out).
 * 0, or -1 when the tile was not held (nothing changes). */
void sched_hold_all(struct sched *s);
int sched_unhold(struct sched *s, uint32_t tile);
/* 1 when queued tiles wait only for the release limit: nothing released is queued. */
int sched_blocked(const struct sched *s);
/* A tile finished without a worker (from the journal, or black outside --tiles): done and
 * out of the queue. 0, or -1 when it was done already (nothing changes). */
int sched_tile_set_done(struct sched *s, uint32_t tile);

/* ---- workers ---- */
/* A worker joined; its index (the next one). */
int32_t sched_worker_join(struct sched *s, uint32_t threads, uint64_t now_ms);
/* A new worker in the slot of gone worker w (slots are reused, so that joins cannot grow
 * the table without bound): fresh state, as if it had joined. w must be gone. */
void sched_worker_rejoin(struct sched *s, int32_t w, uint32_t threads, uint64_t now_ms);
/* READY for the current job: credits capped at 4 per thread, at least 1. -1 when the
 * worker was ready already (nothing changes). */
int sched_worker_ready(struct sched *s, int32_t w, uint32_t credits);
void sched_worker_heard(struct sched *s, int32_t w, uint64_t now_ms);
/* Render progress: a result or kept tile arrived. */
void sched_worker_progress(struct sched *s, int32_t w, uint64_t now_ms);
/* A result of the current job returns its credit (up to the cap). */
void sched_worker_credit(struct sched *s, int32_t w);
/* A heartbeat: samples done so far (progress when it grows) and the worker's own longest
 * render-thread stall. */
void sched_worker_heartbeat(struct sched *s, int32_t w, uint64_t samples_done, uint32_t stalled_ms,
                            uint64_t now_ms);
/* Whether worker w should be evicted now; *for_ms is how long it was silent or stalled. */
enum sched_health sched_worker_health(const struct sched *s, int32_t w, uint64_t now_ms, uint32_t timeout_ms,
                                      uint32_t stall_ms, uint64_t *for_ms);
/* The eviction kind of a local worker that ended (WIFSIGNALED, WTERMSIG). */
enum sched_evict_kind sched_death_kind(int signaled, int signo);
/* Puts w's unfinished tiles back at the front of the queue and forgets w; a blaming kind
 * counts one crash against each tile w held. A gone worker: nothing happens. */
void sched_evict(struct sched *s, int32_t w, enum sched_evict_kind kind, struct sched_eviction *ev);
uint32_t sched_live_workers(const struct sched *s);

/* ---- tiles ---- */
/* The next tile to send, or 0 when none goes out now. Released queued tiles go first, in queue
 * order, to workers in index order with credits; a tile that already took a worker down
 * goes only to an idle worker, which then gets nothing else. With the queue empty, an idle
 * worker gets a copy of the oldest tile in flight elsewhere (never a suspect one); a
 * straggler copy waits while queued tiles wait for their release. */
int sched_assign_next(struct sched *s, uint64_t now_ms, struct sched_assignment *a);
/* The TILE of assignment a could not be queued for its worker (its queue is full: a burst
 * of more tiles than the socket holds, or it stopped reading; or it is gone): the
 * assignment is taken back (the tile goes back to the front of the queue unless another
 * holder has it) with its credit, and the worker gets nothing more until it is heard from
 * (sched_worker_heard), so that the others get the tiles meanwhile. */
void sched_assign_undo(struct sched *s, const struct sched_assignment *a);
/* A RESULT for (tile, attempt) from w (tile < num_tiles: the caller checks). */
enum sched_result_verdict sched_result(const struct sched *s, int32_t w, uint32_t tile, uint32_t attempt);
/* After SCHED_RESULT_CHECK: the chunk is good (and journaled): the tile is done, its
 * other holder's result will be a duplicate. */
void sched_result_valid(struct sched *s, int32_t w, uint32_t tile);
/* After SCHED_RESULT_CHECK: the chunk is bad: the tile goes back to the queue; 1 when
 * this was the worker's SCHED_FAILS_TO_BAN-th in a row (it is banned and evicted, *ev
 * says what that did), else 0. */
int sched_result_invalid(struct sched *s, int32_t w, uint32_t tile, struct sched_eviction *ev);
/* After SCHED_RESULT_CHECK: the chunk has non-finite values, which the scene may cause
 * (then every worker agrees) or the worker may have got wrong: the tile goes back to the
 * queue and, while another worker lives, goes to another worker; no blame yet. The
 * caller judges by the next result: non-finite again fails the job (the scene's), a
 * valid one from another worker blames w (sched_worker_invalid). */
void sched_result_nonfinite(struct sched *s, int32_t w, uint32_t tile, uint64_t now_ms);
/* An invalid result of w found out later (its non-finite tile rendered finite elsewhere):
 * counts towards a ban like sched_result_invalid (same return and *ev). */
int sched_worker_invalid(struct sched *s, int32_t w, struct sched_eviction *ev);
/* A tile a worker kept for an earlier master, for this job: 1 if it is done already (a
 * duplicate), else 0 (check the chunk, then _valid or _invalid). */
int sched_kept(const struct sched *s, uint32_t tile);
void sched_kept_valid(struct sched *s, int32_t w, uint32_t tile);
/* A bad kept chunk counts towards a ban like a bad result (same return and *ev). */
int sched_kept_invalid(struct sched *s, int32_t w, struct sched_eviction *ev);

#endif
