/* The tile scheduler (see sched.h): pure state, no I/O, no clock, so every fault-tolerance
 * rule can be driven event by event in unit tests. Invariant kept by every function: a
 * worker's in_flight equals the number of tiles that list it as a holder (zero once it is
 * gone), and its held list names those tiles (each at the place the tile's holder_pos
 * says), a queued tile has no holders, qpos gives each queued tile's place in
 * queue_buf (the queue is a window there, so nothing moves when a tile leaves from the
 * front or comes back to either end), q_released counts the queued tiles below the
 * release limit, and the in-flight list (fl_*) holds exactly the assigned tiles with one
 * holder, ordered by (assigned_ms, tile), a worker's bit in takers is set exactly when it
 * can take a unit (can_take: taker_sync after every change of what that reads), and live
 * counts the workers not gone. Called by master/master.c. */
#include "sched.h"
#include "base/log.h"
#include <signal.h>
#include <stdlib.h>
#include <string.h>

struct sched *sched_new(uint32_t num_tiles)
{
    struct sched *s = mem_calloc(1, sizeof *s);
    s->num_tiles = num_tiles;
    s->tiles = mem_calloc(num_tiles ? num_tiles : 1, sizeof *s->tiles);
    s->q_cap = 2 * num_tiles + 2;
    s->queue_buf = mem_calloc(s->q_cap, sizeof *s->queue_buf);
    s->queue = s->queue_buf + s->q_cap / 2;
    s->qpos = mem_alloc((num_tiles ? num_tiles : 1) * sizeof *s->qpos);
    for (uint32_t t = 0; t < num_tiles; t++)
        s->qpos[t] = SCHED_NOT_QUEUED;
    s->failed_tile = -1;
    s->released = num_tiles;
    s->fl_prev = mem_alloc((num_tiles ? num_tiles : 1) * sizeof *s->fl_prev);
    s->fl_next = mem_alloc((num_tiles ? num_tiles : 1) * sizeof *s->fl_next);
    s->fl_in = mem_calloc(num_tiles ? num_tiles : 1, 1);
    s->fl_head = s->fl_tail = SCHED_NONE;
    return s;
}

void sched_free(struct sched **sp)
{
    struct sched *s = *sp;
    if (!s)
        return;
    free(s->tiles);
    free(s->queue_buf);
    free(s->qpos);
    free(s->fl_prev);
    free(s->fl_next);
    free(s->fl_in);
    free(s->takers);
    for (uint32_t i = 0; i < s->num_workers; i++)
        free(s->workers[i].held);
    free(s->workers);
    free(s);
    *sp = NULL;
}

static int can_take(const struct sched_worker *w)
{
    return !w->gone && w->ready && w->credits > 0 && !w->isolated && !w->blocked;
}

/* Worker wi's bit in takers, as can_take says now. */
static void taker_sync(struct sched *s, int32_t wi)
{
    uint64_t bit = 1ull << ((uint32_t)wi & 63);
    if (can_take(&s->workers[wi]))
        s->takers[(uint32_t)wi >> 6] |= bit;
    else
        s->takers[(uint32_t)wi >> 6] &= ~bit;
}

/* The first worker at or after `from` that can take a unit, or -1. */
static int32_t next_taker(const struct sched *s, uint32_t from)
{
    uint32_t wd = from >> 6;
    if (wd >= s->takers_words)
        return -1;
    uint64_t bits = s->takers[wd] & (~0ull << (from & 63));
    for (;;) {
        if (bits)
            return (int32_t)(wd * 64 + (uint32_t)__builtin_ctzll(bits));
        if (++wd >= s->takers_words)
            return -1;
        bits = s->takers[wd];
    }
}

void sched_frame_begin(struct sched *s)
{
    memset(s->tiles, 0, sizeof *s->tiles * s->num_tiles);
    s->tiles_done = 0;
    s->failed_tile = -1;
    s->q_count = 0;
    s->released = s->num_tiles;
    s->q_released = s->num_tiles;
    memset(s->fl_in, 0, s->num_tiles);
    s->fl_head = s->fl_tail = SCHED_NONE;
    s->queue = s->queue_buf + 1; /* room for the tiles that come back to the front */
    for (uint32_t t = 0; t < s->num_tiles; t++) {
        s->qpos[t] = (uint32_t)(s->queue - s->queue_buf) + s->q_count;
        s->queue[s->q_count++] = t;
    }
    for (uint32_t i = 0; i < s->num_workers; i++) {
        struct sched_worker *w = &s->workers[i];
        w->ready = 0;
        w->credits = 0;
        w->in_flight = 0;
        w->isolated = 0;
    }
    if (s->takers)
        memset(s->takers, 0, sizeof *s->takers * s->takers_words); /* none is ready */
}

void sched_release(struct sched *s, uint32_t limit)
{
    uint32_t to = limit < s->num_tiles ? limit : s->num_tiles;
    /* The queued tiles between the old limit and the new one change sides. */
    for (uint32_t t = s->released; t < to; t++)
        s->q_released += s->qpos[t] != SCHED_NOT_QUEUED;
    for (uint32_t t = to; t < s->released; t++)
        s->q_released -= s->qpos[t] != SCHED_NOT_QUEUED;
    s->released = to;
}

/* Moves the queue's window to the middle of its room (when an end is reached). */
static void queue_recenter(struct sched *s)
{
    uint32_t *to = s->queue_buf + (s->q_cap - s->q_count) / 2;
    memmove(to, s->queue, sizeof *s->queue * s->q_count);
    s->queue = to;
    for (uint32_t i = 0; i < s->q_count; i++)
        s->qpos[to[i]] = (uint32_t)(to - s->queue_buf) + i;
}

static void queue_push_back(struct sched *s, uint32_t tile)
{
    if (s->queue + s->q_count == s->queue_buf + s->q_cap)
        queue_recenter(s);
    s->qpos[tile] = (uint32_t)(s->queue - s->queue_buf) + s->q_count;
    s->queue[s->q_count++] = tile;
    s->q_released += tile < s->released;
}

void sched_hold_all(struct sched *s)
{
    for (uint32_t t = 0; t < s->num_tiles; t++)
        if (s->tiles[t].state == SCHED_QUEUED) {
            s->tiles[t].state = SCHED_HELD;
            s->qpos[t] = SCHED_NOT_QUEUED;
        }
    s->q_count = 0;
    s->q_released = 0;
}

int sched_unhold(struct sched *s, uint32_t tile)
{
    if (s->tiles[tile].state != SCHED_HELD)
        return -1;
    s->tiles[tile].state = SCHED_QUEUED;
    queue_push_back(s, tile);
    return 0;
}

int sched_blocked(const struct sched *s)
{
    return s->q_count > 0 && s->q_released == 0;
}

/* Removes the tile at place i, moving the shorter side of the queue by one (the front:
 * nothing moves). */
static void queue_remove_at(struct sched *s, uint32_t i)
{
    s->qpos[s->queue[i]] = SCHED_NOT_QUEUED;
    s->q_released -= s->queue[i] < s->released;
    if (i < s->q_count / 2) {
        memmove(s->queue + 1, s->queue, sizeof *s->queue * i);
        s->queue++;
        for (uint32_t k = 0; k < i; k++)
            s->qpos[s->queue[k]]++;
    } else {
        memmove(s->queue + i, s->queue + i + 1, sizeof *s->queue * (s->q_count - i - 1));
        for (uint32_t k = i; k + 1 < s->q_count; k++)
            s->qpos[s->queue[k]]--;
    }
    s->q_count--;
}

static void queue_remove(struct sched *s, uint32_t tile)
{
    if (s->qpos[tile] != SCHED_NOT_QUEUED)
        queue_remove_at(s, s->qpos[tile] - (uint32_t)(s->queue - s->queue_buf));
}

/* Re-queued tiles go first: they are the ones holding up the end of the frame. */
static void queue_push_front(struct sched *s, uint32_t tile)
{
    if (s->queue == s->queue_buf)
        queue_recenter(s);
    s->queue--;
    s->queue[0] = tile;
    s->qpos[tile] = (uint32_t)(s->queue - s->queue_buf);
    s->q_count++;
    s->q_released += tile < s->released;
}

/* The in-flight list: tile a before tile b (older, or as old with a lower index). */
static int fl_before(const struct sched *s, uint32_t a, uint32_t b)
{
    uint64_t ta = s->tiles[a].assigned_ms, tb = s->tiles[b].assigned_ms;
    return ta < tb || (ta == tb && a < b);
}

/* Puts tile in the in-flight list, or takes it out, as it now has one holder or not. A
 * tile comes in at its place from the back: it was just given, so that is the end or near. */
static void fl_sync(struct sched *s, uint32_t tile)
{
    const struct sched_tile *t = &s->tiles[tile];
    int want = t->state == SCHED_ASSIGNED && t->num_holders == 1;
    if (s->fl_in[tile] && !want) {
        uint32_t p = s->fl_prev[tile], n = s->fl_next[tile];
        if (p != SCHED_NONE)
            s->fl_next[p] = n;
        else
            s->fl_head = n;
        if (n != SCHED_NONE)
            s->fl_prev[n] = p;
        else
            s->fl_tail = p;
        s->fl_in[tile] = 0;
    } else if (!s->fl_in[tile] && want) {
        uint32_t p = s->fl_tail;
        while (p != SCHED_NONE && fl_before(s, tile, p))
            p = s->fl_prev[p];
        uint32_t n = p != SCHED_NONE ? s->fl_next[p] : s->fl_head;
        s->fl_prev[tile] = p;
        s->fl_next[tile] = n;
        if (p != SCHED_NONE)
            s->fl_next[p] = tile;
        else
            s->fl_head = tile;
        if (n != SCHED_NONE)
            s->fl_prev[n] = tile;
        else
            s->fl_tail = tile;
        s->fl_in[tile] = 1;
    }
}

static void mark_done(struct sched *s, uint32_t tile)
{
    s->tiles[tile].state = SCHED_DONE;
    s->tiles_done++;
    fl_sync(s, tile);
}

int sched_tile_set_done(struct sched *s, uint32_t tile)
{
    if (s->tiles[tile].state == SCHED_DONE)
        return -1;
    queue_remove(s, tile);
    mark_done(s, tile);
    return 0;
}

/* Takes the tile at place pos out of worker w's held list (the last one moves there). */
static void held_remove(struct sched *s, int32_t w, uint32_t pos)
{
    struct sched_worker *wk = &s->workers[w];
    CHECK(pos < wk->in_flight);
    uint32_t last = wk->held[--wk->in_flight];
    if (pos == wk->in_flight)
        return;
    wk->held[pos] = last;
    struct sched_tile *lt = &s->tiles[last];
    for (uint32_t k = 0; k < lt->num_holders; k++)
        if (lt->holder[k] == w)
            lt->holder_pos[k] = pos;
}

/* Removes holder w from the tile; it goes back to the front of the queue when nobody
 * else holds it and it is not done. */
static void drop_holder(struct sched *s, uint32_t tile, int32_t w)
{
    struct sched_tile *t = &s->tiles[tile];
    for (uint32_t k = 0; k < t->num_holders; k++)
        if (t->holder[k] == w) {
            held_remove(s, w, t->holder_pos[k]);
            t->holder[k] = t->holder[t->num_holders - 1];
            t->holder_attempt[k] = t->holder_attempt[t->num_holders - 1];
            t->holder_pos[k] = t->holder_pos[t->num_holders - 1];
            t->num_holders--;
            break;
        }
    if (t->state == SCHED_ASSIGNED && t->num_holders == 0) {
        t->state = SCHED_QUEUED;
        t->requeued = 1;
        queue_push_front(s, tile);
    }
    fl_sync(s, tile);
}

static void drop_all_holders(struct sched *s, uint32_t tile)
{
    while (s->tiles[tile].num_holders > 0)
        drop_holder(s, tile, s->tiles[tile].holder[0]);
}

int32_t sched_worker_join(struct sched *s, uint32_t threads, uint64_t now_ms)
{
    s->workers = mem_realloc(s->workers, sizeof *s->workers * (s->num_workers + 1));
    struct sched_worker *w = &s->workers[s->num_workers];
    memset(w, 0, sizeof *w);
    w->threads = threads ? threads : 1;
    w->last_heard_ms = w->last_progress_ms = now_ms;
    if (s->num_workers / 64 + 1 > s->takers_words) {
        uint32_t words = s->takers_words ? 2 * s->takers_words : 1;
        s->takers = mem_realloc(s->takers, sizeof *s->takers * words);
        memset(s->takers + s->takers_words, 0, sizeof *s->takers * (words - s->takers_words));
        s->takers_words = words;
    }
    s->live++;
    return (int32_t)s->num_workers++; /* not ready: its bit stays clear */
}

void sched_worker_rejoin(struct sched *s, int32_t wi, uint32_t threads, uint64_t now_ms)
{
    struct sched_worker *w = &s->workers[wi];
    CHECK(w->gone);
    uint32_t *held = w->held, cap = w->held_cap; /* empty (it is gone); the room is kept */
    memset(w, 0, sizeof *w);
    w->held = held;
    w->held_cap = cap;
    w->threads = threads ? threads : 1;
    w->last_heard_ms = w->last_progress_ms = now_ms;
    s->live++;
}

int sched_worker_ready(struct sched *s, int32_t wi, uint32_t credits)
{
    struct sched_worker *w = &s->workers[wi];
    if (w->ready)
        return -1;
    w->ready = 1;
    w->credits = credits < w->threads * 4 ? credits : w->threads * 4;
    if (w->credits == 0)
        w->credits = 1;
    taker_sync(s, wi);
    return 0;
}

void sched_worker_heard(struct sched *s, int32_t w, uint64_t now_ms)
{
    s->workers[w].last_heard_ms = now_ms;
    s->workers[w].blocked = 0;
    taker_sync(s, w);
}

void sched_worker_progress(struct sched *s, int32_t w, uint64_t now_ms)
{
    s->workers[w].last_progress_ms = now_ms;
}

void sched_worker_credit(struct sched *s, int32_t wi)
{
    struct sched_worker *w = &s->workers[wi];
    if (w->credits < w->threads * 4)
        w->credits++;
    taker_sync(s, wi);
}

void sched_worker_heartbeat(struct sched *s, int32_t wi, uint64_t samples_done, uint32_t stalled_ms, uint64_t now_ms)
{
    struct sched_worker *w = &s->workers[wi];
    if (samples_done > w->last_samples) {
        w->last_samples = samples_done;
        w->last_progress_ms = now_ms;
    }
    w->reported_stall_ms = stalled_ms;
}

enum sched_health sched_worker_health(const struct sched *s, int32_t wi, uint64_t now_ms, uint32_t timeout_ms,
                                      uint32_t stall_ms, uint64_t *for_ms)
{
    const struct sched_worker *w = &s->workers[wi];
    *for_ms = 0;
    if (w->gone)
        return SCHED_HEALTHY;
    if (now_ms - w->last_heard_ms > timeout_ms) {
        *for_ms = now_ms - w->last_heard_ms;
        return SCHED_HEALTH_SILENT;
    }
    /* Only a worker with tiles can stall: idle time is not a stall. */
    if (w->in_flight > 0 && now_ms - w->last_progress_ms > stall_ms) {
        *for_ms = now_ms - w->last_progress_ms;
        return SCHED_HEALTH_STALLED;
    }
    if (w->in_flight > 0 && w->reported_stall_ms > stall_ms) {
        *for_ms = w->reported_stall_ms;
        return SCHED_HEALTH_STALL_REPORTED;
    }
    return SCHED_HEALTHY;
}

enum sched_evict_kind sched_death_kind(int signaled, int signo)
{
    return signaled && signo == SIGKILL ? SCHED_KILLED : SCHED_DIED;
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

void sched_evict(struct sched *s, int32_t wi, enum sched_evict_kind kind, struct sched_eviction *ev)
{
    struct sched_worker *w = &s->workers[wi];
    ev->requeued = 0;
    ev->blamed_tile = -1;
    if (w->gone)
        return;
    int blames = kind != SCHED_LEFT && kind != SCHED_BANNED && kind != SCHED_KILLED;
    /* The tiles it holds, in tile order (as a walk of every tile met them: the blame and
     * the queue's order after the eviction do not depend on the order they were given). */
    uint32_t n = w->in_flight, *tiles = mem_alloc(sizeof *tiles * (n ? n : 1));
    if (n > 0) { /* a worker that never held one has no list */
        memcpy(tiles, w->held, sizeof *tiles * n);
        qsort(tiles, n, sizeof *tiles, cmp_u32);
    }
    for (uint32_t i = 0; i < n; i++) {
        uint32_t tile = tiles[i];
        struct sched_tile *t = &s->tiles[tile];
        CHECK(t->state == SCHED_ASSIGNED); /* a held tile is assigned (the invariant above) */
        if (blames && ++t->crashes >= SCHED_CRASHES_TO_FAIL && s->failed_tile < 0) {
            s->failed_tile = (int32_t)tile;
            ev->blamed_tile = (int32_t)tile;
        }
        drop_holder(s, tile, wi);
        ev->requeued += t->state == SCHED_QUEUED;
    }
    free(tiles);
    CHECK(w->in_flight == 0); /* drop_holder took each out of its list */
    w->gone = 1;
    s->live--;
    taker_sync(s, wi);
}

uint32_t sched_live_workers(const struct sched *s)
{
    return s->live;
}

/* Whether a live, ready worker other than i exists (one that could take a tile i should not). */
static int other_ready_worker(const struct sched *s, uint32_t i)
{
    for (uint32_t k = 0; k < s->num_workers; k++)
        if (k != i && !s->workers[k].gone && s->workers[k].ready)
            return 1;
    return 0;
}

static void give(struct sched *s, uint32_t tile, int32_t wi, int straggler, uint64_t now_ms,
                 struct sched_assignment *a)
{
    struct sched_worker *w = &s->workers[wi];
    struct sched_tile *t = &s->tiles[tile];
    if (w->in_flight == 0)
        w->last_progress_ms = now_ms; /* idle time is not a stall */
    t->state = SCHED_ASSIGNED;
    t->attempt++;
    if (w->in_flight == w->held_cap) {
        w->held_cap = w->held_cap ? 2 * w->held_cap : 8;
        w->held = mem_realloc(w->held, sizeof *w->held * w->held_cap);
    }
    t->holder[t->num_holders] = wi;
    t->holder_attempt[t->num_holders] = t->attempt;
    t->holder_pos[t->num_holders] = w->in_flight;
    t->num_holders++;
    t->assigned_ms = now_ms;
    w->credits--;
    w->held[w->in_flight++] = tile;
    a->tile = tile;
    a->attempt = t->attempt;
    a->worker = wi;
    a->straggler = straggler;
    a->reissue = !straggler && t->requeued;
    t->requeued = 0;
    fl_sync(s, tile);
    /* A tile that already took a worker down is rendered alone, so that a second crash
     * is blamed on it and not on its neighbours. */
    if (t->crashes > 0)
        w->isolated = 1;
    taker_sync(s, wi);
}

int sched_assign_next(struct sched *s, uint64_t now_ms, struct sched_assignment *a)
{
    /* Nothing queued is released (every queued unit waits for its pass's photon map):
     * nothing to search, and no straggler copies while units wait. */
    if (sched_blocked(s))
        return 0;
    for (int32_t wi = next_taker(s, 0); wi >= 0 && s->q_count > 0; wi = next_taker(s, (uint32_t)wi + 1)) {
        uint32_t i = (uint32_t)wi;
        const struct sched_worker *w = &s->workers[i];
        for (uint32_t qi = 0; qi < s->q_count; qi++) {
            uint32_t tile = s->queue[qi];
            if (tile >= s->released || (s->tiles[tile].crashes > 0 && w->in_flight > 0) ||
                (s->tiles[tile].nonfinite_by == (int32_t)i + 1 &&
                 (other_ready_worker(s, i) || now_ms < s->tiles[tile].nonfinite_ms + SCHED_NONFINITE_WAIT_MS)))
                continue;
            queue_remove_at(s, qi);
            give(s, tile, (int32_t)i, 0, now_ms, a);
            return 1;
        }
    }
    if (s->q_count > 0)
        return 0;
    /* Stragglers: an idle worker also takes the oldest tile still in flight elsewhere;
     * the first valid result wins (tiles are deterministic, so either will do). */
    for (int32_t wi = next_taker(s, 0); wi >= 0; wi = next_taker(s, (uint32_t)wi + 1)) {
        uint32_t i = (uint32_t)wi;
        const struct sched_worker *w = &s->workers[i];
        if (w->in_flight > 0)
            continue;
        /* The in-flight list is in that order: its first tile this worker may copy. */
        uint32_t best = s->fl_head;
        while (best != SCHED_NONE && (s->tiles[best].holder[0] == (int32_t)i || s->tiles[best].crashes > 0))
            best = s->fl_next[best];
        if (best == SCHED_NONE)
            return 0;
        give(s, best, (int32_t)i, 1, now_ms, a);
        return 1;
    }
    return 0;
}

void sched_assign_undo(struct sched *s, const struct sched_assignment *a)
{
    struct sched_worker *w = &s->workers[a->worker];
    struct sched_tile *t = &s->tiles[a->tile];
    drop_holder(s, a->tile, a->worker);
    if (t->state == SCHED_QUEUED)
        t->requeued = a->reissue; /* as it was: it never went out */
    w->credits++;
    w->isolated = 0; /* give() isolates only a worker that was not */
    w->blocked = 1;
    taker_sync(s, a->worker);
}

enum sched_result_verdict sched_result(const struct sched *s, int32_t w, uint32_t tile, uint32_t attempt)
{
    const struct sched_tile *t = &s->tiles[tile];
    int holder = 0;
    for (uint32_t i = 0; i < t->num_holders; i++)
        holder |= t->holder[i] == w && t->holder_attempt[i] == attempt;
    if (t->state != SCHED_DONE && holder)
        return SCHED_RESULT_CHECK;
    /* A straggler copy that lost the race is expected; anything else is stale. */
    if (t->state == SCHED_DONE && attempt <= t->attempt && attempt > 0)
        return SCHED_RESULT_DUPLICATE;
    return SCHED_RESULT_STALE;
}

void sched_result_valid(struct sched *s, int32_t wi, uint32_t tile)
{
    struct sched_worker *w = &s->workers[wi];
    w->fail_streak = 0;
    w->isolated = 0;
    w->tiles_done++;
    mark_done(s, tile);
    /* Both holders stop holding it (it is done, so nothing is re-queued). */
    drop_all_holders(s, tile);
    taker_sync(s, wi);
}

static int sent_invalid(struct sched *s, int32_t wi, struct sched_eviction *ev)
{
    struct sched_worker *w = &s->workers[wi];
    ev->requeued = 0;
    ev->blamed_tile = -1;
    if (++w->fail_streak < SCHED_FAILS_TO_BAN)
        return 0;
    w->banned = 1;
    sched_evict(s, wi, SCHED_BANNED, ev);
    return 1;
}

int sched_result_invalid(struct sched *s, int32_t wi, uint32_t tile, struct sched_eviction *ev)
{
    drop_holder(s, tile, wi);
    s->workers[wi].isolated = 0;
    taker_sync(s, wi);
    return sent_invalid(s, wi, ev);
}

void sched_result_nonfinite(struct sched *s, int32_t wi, uint32_t tile, uint64_t now_ms)
{
    drop_holder(s, tile, wi);
    s->workers[wi].isolated = 0;
    taker_sync(s, wi);
    s->tiles[tile].nonfinite_by = wi + 1;
    s->tiles[tile].nonfinite_ms = now_ms;
}

int sched_worker_invalid(struct sched *s, int32_t wi, struct sched_eviction *ev)
{
    return sent_invalid(s, wi, ev);
}

int sched_kept(const struct sched *s, uint32_t tile)
{
    return s->tiles[tile].state == SCHED_DONE;
}

void sched_kept_valid(struct sched *s, int32_t wi, uint32_t tile)
{
    struct sched_worker *w = &s->workers[wi];
    w->fail_streak = 0;
    w->tiles_done++;
    mark_done(s, tile);
    queue_remove(s, tile);
    drop_all_holders(s, tile); /* copies in flight elsewhere will be duplicates */
}

int sched_kept_invalid(struct sched *s, int32_t wi, struct sched_eviction *ev)
{
    return sent_invalid(s, wi, ev);
}
