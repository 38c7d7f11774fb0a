/* Unit tests for the tile scheduler (master/sched.c), event by event with no processes,
 * sockets or sleeps (time is an argument): re-issue to the front, first result wins,
 * stale attempts, crash blame, bans, straggler copies, eviction for silence and stall, and
 * a property test over random event sequences (every tile done exactly once; only a
 * holder's result with its attempt is ever taken). Run by `make unit`. */
#include <criterion/criterion.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include "master/sched.h"

static struct sched_assignment give_one(struct sched *s, uint64_t now)
{
    struct sched_assignment a;
    cr_assert_eq(sched_assign_next(s, now, &a), 1, "expected an assignment");
    return a;
}

static void assert_none(struct sched *s, uint64_t now)
{
    struct sched_assignment a;
    cr_assert_eq(sched_assign_next(s, now, &a), 0, "unexpected: tile %u to worker %d", a.tile, a.worker);
}

/* A new scheduler in its first frame with n ready workers of `credits` credits each. */
static struct sched *setup(uint32_t tiles, uint32_t workers, uint32_t credits)
{
    struct sched *s = sched_new(tiles);
    sched_frame_begin(s);
    for (uint32_t i = 0; i < workers; i++) {
        int32_t w = sched_worker_join(s, 4, 0);
        cr_assert_eq(w, (int32_t)i);
        cr_assert_eq(sched_worker_ready(s, w, credits), 0);
    }
    return s;
}

Test(sched, tiles_go_out_in_order_within_credits)
{
    struct sched *s = setup(5, 2, 2);
    uint32_t want_tile[4] = {0, 1, 2, 3};
    int32_t want_worker[4] = {0, 0, 1, 1};
    for (int i = 0; i < 4; i++) {
        struct sched_assignment a = give_one(s, 10);
        cr_assert_eq(a.tile, want_tile[i]);
        cr_assert_eq(a.worker, want_worker[i]);
        cr_assert_eq(a.attempt, 1);
        cr_assert_eq(a.straggler, 0);
        cr_assert_eq(a.reissue, 0);
    }
    assert_none(s, 10); /* no credits left, tile 4 waits */
    cr_assert_eq(s->q_count, 1);
    cr_assert_eq(sched_worker_ready(s, 0, 3), -1, "a second READY changes nothing");
    sched_free(&s);
    cr_assert_null(s);
}

/* Units u = pass * tiles + tile: a pass's units go out only once its map is released;
 * a re-issued unit of a released pass still goes first, and no straggler copy is made
 * while units wait for their release. */
Test(sched, units_wait_for_their_release)
{
    struct sched *s = setup(6, 1, 8); /* 3 tiles x 2 passes */
    sched_release(s, 0);
    cr_assert(sched_blocked(s));
    assert_none(s, 10);
    sched_release(s, 3);
    cr_assert(!sched_blocked(s));
    for (uint32_t u = 0; u < 3; u++)
        cr_assert_eq(give_one(s, 10).tile, u);
    assert_none(s, 10); /* units 3..5 wait for pass 1, and no straggler copy meanwhile */
    cr_assert(sched_blocked(s));
    cr_assert_eq(sched_live_workers(s), 1);
    int32_t w1 = sched_worker_join(s, 4, 10);
    cr_assert_eq(sched_worker_ready(s, w1, 8), 0);
    assert_none(s, 10);
    struct sched_eviction ev;
    sched_evict(s, 0, SCHED_LEFT, &ev);
    cr_assert_eq(ev.requeued, 3);
    for (int i = 0; i < 3; i++)
        cr_assert_lt(give_one(s, 20).tile, 3, "re-issued units of a released pass go out");
    assert_none(s, 20);
    sched_release(s, 100); /* capped at the number of units */
    cr_assert_eq(s->released, 6);
    for (uint32_t u = 3; u < 6; u++)
        cr_assert_eq(give_one(s, 20).tile, u);
    sched_frame_begin(s);
    cr_assert_eq(s->released, 6, "a new frame releases everything until told otherwise");
    sched_free(&s);
}

Test(sched, ready_credits_are_capped_and_at_least_one)
{
    struct sched *s = sched_new(1);
    sched_frame_begin(s);
    int32_t a = sched_worker_join(s, 2, 0), b = sched_worker_join(s, 0, 0);
    sched_worker_ready(s, a, 1000);
    sched_worker_ready(s, b, 0);
    cr_assert_eq(s->workers[a].credits, 8);
    cr_assert_eq(s->workers[b].credits, 1);
    for (int i = 0; i < 5; i++)
        sched_worker_credit(s, b);
    cr_assert_eq(s->workers[b].credits, 4, "a worker that said 0 threads has 1: cap 4");
    sched_free(&s);
}

Test(sched, reissue_goes_to_the_front_of_the_queue)
{
    struct sched *s = setup(4, 1, 2);
    give_one(s, 1);
    give_one(s, 1);
    cr_assert_eq(s->q_count, 2);
    struct sched_eviction ev;
    sched_evict(s, 0, SCHED_SILENT, &ev);
    cr_assert_eq(ev.requeued, 2);
    cr_assert_eq(ev.blamed_tile, -1);
    cr_assert_eq(s->q_count, 4);
    cr_assert_eq(s->queue[0], 1);
    cr_assert_eq(s->queue[1], 0);
    cr_assert_eq(s->queue[2], 2);
    int32_t b = sched_worker_join(s, 1, 5);
    sched_worker_ready(s, b, 1);
    struct sched_assignment a = give_one(s, 6);
    cr_assert_eq(a.tile, 1);
    cr_assert_eq(a.worker, b);
    cr_assert_eq(a.attempt, 2, "attempts count on per tile");
    cr_assert_eq(a.reissue, 1);
    cr_assert_eq(s->tiles[1].crashes, 1, "silence blames");
    sched_free(&s);
}

/* An eviction puts a worker's tiles back in tile order (each to the front: the highest
 * first), whatever order it was given them in and its held list keeps them in. */
Test(sched, an_eviction_requeues_in_tile_order)
{
    struct sched *s = setup(8, 1, 4);
    for (int i = 0; i < 4; i++)
        give_one(s, 1); /* tiles 0-3 */
    sched_result_valid(s, 0, 0);
    sched_worker_credit(s, 0);
    sched_result_valid(s, 0, 2);
    sched_worker_credit(s, 0);
    give_one(s, 2); /* tile 4 */
    give_one(s, 2); /* tile 5: it holds 3, 1, 4, 5 in its list (places moved by the removals) */
    const uint32_t list[] = {3, 1, 4, 5}; /* not in tile order: the eviction must sort it */
    cr_assert_eq(s->workers[0].in_flight, 4);
    for (uint32_t i = 0; i < 4; i++)
        cr_assert_eq(s->workers[0].held[i], list[i], "held[%u] = %u", i, s->workers[0].held[i]);
    struct sched_eviction ev;
    sched_evict(s, 0, SCHED_LEFT, &ev);
    cr_assert_eq(ev.requeued, 4);
    const uint32_t want[] = {5, 4, 3, 1, 6, 7};
    cr_assert_eq(s->q_count, 6);
    for (uint32_t i = 0; i < 6; i++)
        cr_assert_eq(s->queue[i], want[i], "queue[%u] = %u", i, s->queue[i]);
    cr_assert_eq(s->workers[0].in_flight, 0);
    sched_free(&s);
}

Test(sched, first_result_wins_and_the_straggler_copy_is_a_duplicate)
{
    struct sched *s = setup(2, 1, 2);
    give_one(s, 100); /* tile 0 */
    give_one(s, 200); /* tile 1 */
    int32_t b = sched_worker_join(s, 1, 300);
    sched_worker_ready(s, b, 1);
    struct sched_assignment c = give_one(s, 300);
    cr_assert_eq(c.tile, 0, "the oldest tile in flight is copied");
    cr_assert_eq(c.straggler, 1);
    cr_assert_eq(c.reissue, 0);
    cr_assert_eq(c.attempt, 2);
    cr_assert_eq(s->tiles[0].num_holders, 2);
    cr_assert_eq(sched_result(s, 0, 0, 1), SCHED_RESULT_CHECK);
    sched_result_valid(s, 0, 0);
    cr_assert_eq(s->tiles[0].state, SCHED_DONE);
    cr_assert_eq(s->tiles[0].num_holders, 0);
    cr_assert_eq(s->workers[b].in_flight, 0);
    cr_assert_eq(s->q_count, 0, "a done tile is not re-queued when its holders go");
    cr_assert_eq(sched_result(s, b, 0, 2), SCHED_RESULT_DUPLICATE);
    cr_assert_eq(sched_result(s, 0, 0, 1), SCHED_RESULT_DUPLICATE, "the same result twice");
    cr_assert_eq(s->tiles_done, 1);
    sched_free(&s);
}

Test(sched, the_straggler_copy_can_win)
{
    struct sched *s = setup(1, 1, 1);
    give_one(s, 0);
    int32_t b = sched_worker_join(s, 1, 0);
    sched_worker_ready(s, b, 1);
    give_one(s, 1);
    cr_assert_eq(sched_result(s, b, 0, 2), SCHED_RESULT_CHECK);
    sched_result_valid(s, b, 0);
    cr_assert_eq(sched_result(s, 0, 0, 1), SCHED_RESULT_DUPLICATE);
    cr_assert_eq(s->workers[b].tiles_done, 1);
    cr_assert_eq(s->workers[0].tiles_done, 0);
    sched_free(&s);
}

Test(sched, stale_attempts_and_non_holders_are_dropped)
{
    struct sched *s = setup(2, 2, 1);
    give_one(s, 0); /* tile 0 attempt 1 to worker 0 */
    give_one(s, 0); /* tile 1 attempt 1 to worker 1 */
    cr_assert_eq(sched_result(s, 1, 0, 1), SCHED_RESULT_STALE, "worker 1 does not hold tile 0");
    cr_assert_eq(sched_result(s, 0, 0, 2), SCHED_RESULT_STALE, "an attempt never issued");
    cr_assert_eq(sched_result(s, 0, 0, 0), SCHED_RESULT_STALE);
    /* Tile 0 comes back (an invalid result) and goes out again as attempt 2. */
    struct sched_eviction ev;
    cr_assert_eq(sched_result_invalid(s, 0, 0, &ev), 0);
    cr_assert_eq(s->tiles[0].state, SCHED_QUEUED);
    cr_assert_eq(s->queue[0], 0);
    sched_worker_credit(s, 0);
    struct sched_assignment a = give_one(s, 1);
    cr_assert_eq(a.attempt, 2);
    cr_assert_eq(a.reissue, 1);
    cr_assert_eq(sched_result(s, 0, 0, 1), SCHED_RESULT_STALE, "the old attempt of the same worker");
    cr_assert_eq(sched_result(s, 0, 0, 2), SCHED_RESULT_CHECK);
    sched_result_valid(s, 0, 0);
    cr_assert_eq(sched_result(s, 0, 0, 3), SCHED_RESULT_STALE, "after done: an attempt never issued");
    sched_free(&s);
}

Test(sched, three_crashes_by_different_workers_fail_the_job)
{
    struct sched *s = setup(3, 0, 0);
    struct sched_eviction ev;
    for (uint32_t i = 0; i < 3; i++) {
        int32_t w = sched_worker_join(s, 1, 0);
        sched_worker_ready(s, w, 4);
        struct sched_assignment a = give_one(s, i);
        cr_assert_eq(a.tile, 0, "the crashed tile goes out first");
        cr_assert_eq(a.worker, w);
        if (i > 0) {
            cr_assert_eq(s->workers[w].isolated, 1, "a suspect tile is rendered alone");
            assert_none(s, i);
        }
        sched_evict(s, w, SCHED_DIED, &ev);
        cr_assert_eq(s->tiles[0].crashes, i + 1);
        if (i < 2) {
            cr_assert_eq(ev.blamed_tile, -1);
        } else {
            cr_assert_eq(ev.blamed_tile, 0);
            cr_assert_eq(s->failed_tile, 0);
        }
    }
    sched_free(&s);
}

Test(sched, kill_left_and_ban_do_not_blame)
{
    cr_assert_eq(sched_death_kind(1, SIGKILL), SCHED_KILLED);
    cr_assert_eq(sched_death_kind(1, SIGSEGV), SCHED_DIED);
    cr_assert_eq(sched_death_kind(0, 0), SCHED_DIED);
    struct sched *s = setup(1, 0, 0);
    enum sched_evict_kind kinds[] = {SCHED_KILLED, SCHED_LEFT, SCHED_KILLED, SCHED_LEFT, SCHED_KILLED};
    for (uint32_t i = 0; i < 5; i++) {
        int32_t w = sched_worker_join(s, 1, 0);
        sched_worker_ready(s, w, 1);
        give_one(s, 0);
        struct sched_eviction ev;
        sched_evict(s, w, kinds[i], &ev);
        cr_assert_eq(ev.requeued, 1);
        cr_assert_eq(ev.blamed_tile, -1);
    }
    cr_assert_eq(s->tiles[0].crashes, 0);
    cr_assert_eq(s->failed_tile, -1);
    /* Stalled, silent and error do blame. */
    enum sched_evict_kind blame[] = {SCHED_STALLED, SCHED_SILENT, SCHED_ERROR};
    for (uint32_t i = 0; i < 3; i++) {
        int32_t w = sched_worker_join(s, 1, 0);
        sched_worker_ready(s, w, 1);
        give_one(s, 0);
        struct sched_eviction ev;
        sched_evict(s, w, blame[i], &ev);
    }
    cr_assert_eq(s->failed_tile, 0);
    sched_free(&s);
}

Test(sched, a_suspect_tile_waits_for_an_idle_worker)
{
    struct sched *s = setup(3, 2, 4);
    give_one(s, 0); /* tile 0 -> w0 */
    struct sched_eviction ev;
    sched_evict(s, 0, SCHED_DIED, &ev);      /* tile 0 crashed once */
    sched_evict(s, 1, SCHED_LEFT, &ev);
    int32_t busy = sched_worker_join(s, 1, 0), idle = sched_worker_join(s, 1, 0);
    sched_worker_ready(s, busy, 4);
    /* busy is idle at first, so it takes tile 0 alone and nothing else. */
    struct sched_assignment a = give_one(s, 1);
    cr_assert_eq(a.tile, 0);
    cr_assert_eq(a.worker, busy);
    assert_none(s, 1);
    sched_worker_ready(s, idle, 4);
    a = give_one(s, 1);
    cr_assert_eq(a.tile, 1);
    cr_assert_eq(a.worker, idle);
    /* A valid result clears the isolation. */
    sched_result_valid(s, busy, 0);
    cr_assert_eq(s->workers[busy].isolated, 0);
    a = give_one(s, 2);
    cr_assert_eq(a.tile, 2);
    cr_assert_eq(a.worker, busy);
    sched_free(&s);
}

Test(sched, a_ban_after_three_invalid_results_in_a_row)
{
    struct sched *s = setup(4, 1, 4);
    for (int i = 0; i < 4; i++)
        give_one(s, 0);
    struct sched_eviction ev;
    cr_assert_eq(sched_result_invalid(s, 0, 0, &ev), 0);
    cr_assert_eq(sched_result_invalid(s, 0, 1, &ev), 0);
    sched_result_valid(s, 0, 2); /* a good one in between: the streak starts over */
    cr_assert_eq(s->workers[0].fail_streak, 0);
    cr_assert_eq(sched_kept_invalid(s, 0, &ev), 0, "a bad kept tile counts too");
    cr_assert_eq(sched_result_invalid(s, 0, 3, &ev), 0);
    cr_assert_eq(s->workers[0].gone, 0);
    sched_worker_credit(s, 0);
    struct sched_assignment a = give_one(s, 1);
    cr_assert_eq(sched_result_invalid(s, 0, a.tile, &ev), 1, "the third in a row bans");
    cr_assert_eq(s->workers[0].banned, 1);
    cr_assert_eq(s->workers[0].gone, 1);
    cr_assert_eq(s->workers[0].in_flight, 0);
    cr_assert_eq(ev.blamed_tile, -1, "a ban blames no tile");
    cr_assert_eq(s->q_count, 3, "its tiles are queued again");
    for (uint32_t t = 0; t < 4; t++)
        cr_assert_eq(s->tiles[t].crashes, 0);
    sched_free(&s);
}

/* A non-finite result blames nobody yet: the tile goes to another ready worker (the one
 * that returned it gets it again only when it is the only one, and after
 * SCHED_NONFINITE_WAIT_MS, so that a worker about to join settles it), and the streak is
 * untouched; sched_worker_invalid counts later, like an invalid result. */
Test(sched, a_nonfinite_tile_goes_to_another_worker_without_blame)
{
    struct sched *s = setup(3, 2, 1);
    struct sched_assignment a = give_one(s, 0), b = give_one(s, 0);
    cr_assert_eq(a.worker, 0);
    cr_assert_eq(b.worker, 1);
    sched_worker_credit(s, 0);
    sched_result_nonfinite(s, 0, a.tile, 0);
    cr_assert_eq(s->workers[0].fail_streak, 0);
    cr_assert_eq(s->tiles[a.tile].nonfinite_by, 1);
    struct sched_assignment c = give_one(s, 1);
    cr_assert_neq(c.tile, a.tile, "worker 0 does not get back the tile it returned non-finite");
    sched_result_valid(s, 1, b.tile);
    sched_worker_credit(s, 1);
    struct sched_assignment d = give_one(s, 2);
    cr_assert_eq(d.tile, a.tile);
    cr_assert_eq(d.worker, 1);
    struct sched_eviction ev;
    cr_assert_eq(sched_worker_invalid(s, 0, &ev), 0);
    cr_assert_eq(s->workers[0].fail_streak, 1);
    sched_free(&s);

    s = setup(1, 1, 1); /* the only worker gets it again, once nobody else came */
    a = give_one(s, 0);
    sched_worker_credit(s, 0);
    sched_result_nonfinite(s, 0, a.tile, 10);
    assert_none(s, 10 + SCHED_NONFINITE_WAIT_MS - 1);
    b = give_one(s, 10 + SCHED_NONFINITE_WAIT_MS);
    cr_assert_eq(b.tile, a.tile);
    cr_assert_eq(b.worker, 0);
    sched_free(&s);
}

/* A gone worker's slot taken by a new one starts afresh. */
Test(sched, a_rejoined_slot_starts_afresh)
{
    struct sched *s = setup(2, 2, 2);
    struct sched_eviction ev;
    sched_evict(s, 0, SCHED_LEFT, &ev);
    cr_assert(s->workers[0].gone && ev.requeued == 0);
    sched_worker_rejoin(s, 0, 3, 50);
    cr_assert_eq(s->workers[0].gone, 0);
    cr_assert_eq(s->workers[0].ready, 0);
    cr_assert_eq(s->workers[0].threads, 3);
    cr_assert_eq(s->workers[0].last_heard_ms, 50);
    cr_assert_eq(s->num_workers, 2);
    cr_assert_eq(sched_worker_ready(s, 0, 1), 0);
    sched_free(&s);
}

Test(sched, straggler_copies_only_when_the_queue_is_empty)
{
    struct sched *s = setup(3, 1, 2);
    give_one(s, 50); /* tile 0 at 50 */
    give_one(s, 10); /* tile 1 at 10: the oldest in flight */
    int32_t b = sched_worker_join(s, 1, 0);
    sched_worker_ready(s, b, 2);
    struct sched_assignment a = give_one(s, 60);
    cr_assert_eq(a.tile, 2, "a queued tile, not a copy");
    cr_assert_eq(a.straggler, 0);
    assert_none(s, 60); /* b is busy: no copies for a busy worker */
    sched_result_valid(s, b, 2);
    a = give_one(s, 70);
    cr_assert_eq(a.straggler, 1);
    cr_assert_eq(a.tile, 1, "the oldest in flight");
    cr_assert_eq(a.worker, b);
    assert_none(s, 70); /* at most two holders, and b is busy now */
    cr_assert_eq(s->workers[0].in_flight, 2, "never a copy of a worker's own tile");
    sched_free(&s);
}

/* A TILE the master could not queue (the worker's queue full, or it gone) is taken back:
 * the tile is queued again (first), the credit returned, and the worker gets nothing
 * until it is heard from, so the others take the tiles meanwhile; a straggler copy taken
 * back leaves the tile with its first holder. */
Test(sched, an_assignment_not_sent_is_taken_back)
{
    struct sched *s = setup(3, 2, 2);
    struct sched_assignment a = give_one(s, 10);
    cr_assert_eq(a.tile, 0);
    cr_assert_eq(a.worker, 0);
    sched_assign_undo(s, &a);
    cr_assert_eq(s->tiles[0].state, SCHED_QUEUED);
    cr_assert_eq(s->tiles[0].num_holders, 0);
    cr_assert_eq(s->workers[0].in_flight, 0);
    cr_assert_eq(s->workers[0].credits, 2);
    cr_assert_eq(s->q_count, 3);
    a = give_one(s, 10);
    cr_assert_eq(a.tile, 0, "the tile taken back goes first");
    cr_assert_eq(a.worker, 1, "to another worker: the blocked one waits");
    cr_assert_eq(a.reissue, 0, "it never went out");
    give_one(s, 10);
    assert_none(s, 10); /* worker 1 has no credit left, worker 0 is blocked */
    sched_worker_heard(s, 0, 20);
    a = give_one(s, 20);
    cr_assert_eq(a.worker, 0);
    cr_assert_eq(a.tile, 2);
    /* a straggler copy not sent: tile 0 stays with worker 1 */
    sched_result_valid(s, 0, 2);
    a = give_one(s, 30);
    cr_assert_eq(a.straggler, 1);
    cr_assert_eq(a.worker, 0);
    sched_assign_undo(s, &a);
    cr_assert_eq(s->tiles[a.tile].state, SCHED_ASSIGNED);
    cr_assert_eq(s->tiles[a.tile].num_holders, 1);
    cr_assert_eq(s->tiles[a.tile].holder[0], 1);
    cr_assert_eq(s->workers[0].in_flight, 0);
    cr_assert_eq(s->q_count, 0);
    sched_free(&s);
}

Test(sched, no_straggler_copy_of_a_suspect_tile)
{
    struct sched *s = setup(1, 1, 1);
    give_one(s, 0);
    struct sched_eviction ev;
    sched_evict(s, 0, SCHED_STALLED, &ev);
    int32_t b = sched_worker_join(s, 1, 0), c = sched_worker_join(s, 1, 0);
    sched_worker_ready(s, b, 1);
    sched_worker_ready(s, c, 1);
    give_one(s, 1);
    assert_none(s, 2);
    sched_free(&s);
}

Test(sched, eviction_for_silence_and_for_stall)
{
    struct sched *s = setup(2, 1, 2);
    uint64_t for_ms;
    cr_assert_eq(sched_worker_health(s, 0, 1000, 500, 300, &for_ms), SCHED_HEALTH_SILENT);
    cr_assert_eq(for_ms, 1000);
    sched_worker_heard(s, 0, 1000);
    cr_assert_eq(sched_worker_health(s, 0, 1400, 500, 300, &for_ms), SCHED_HEALTHY, "idle time is not a stall");
    give_one(s, 1400); /* giving work to an idle worker restarts its progress clock */
    sched_worker_heard(s, 0, 1500); /* heartbeats keep coming: not silent, only stalled */
    cr_assert_eq(sched_worker_health(s, 0, 1500, 500, 300, &for_ms), SCHED_HEALTHY);
    cr_assert_eq(sched_worker_health(s, 0, 1701, 500, 300, &for_ms), SCHED_HEALTH_STALLED);
    cr_assert_eq(for_ms, 301);
    sched_worker_heartbeat(s, 0, 5, 0, 1650); /* samples grew: progress */
    cr_assert_eq(sched_worker_health(s, 0, 1701, 500, 300, &for_ms), SCHED_HEALTHY);
    sched_worker_heartbeat(s, 0, 5, 0, 1900); /* no new samples: no progress */
    cr_assert_eq(sched_worker_health(s, 0, 1951, 500, 300, &for_ms), SCHED_HEALTH_STALLED);
    sched_worker_progress(s, 0, 1950);
    sched_worker_heartbeat(s, 0, 6, 301, 1950); /* one thread stuck, as the worker says */
    cr_assert_eq(sched_worker_health(s, 0, 1960, 500, 300, &for_ms), SCHED_HEALTH_STALL_REPORTED);
    cr_assert_eq(for_ms, 301);
    struct sched_eviction ev;
    sched_evict(s, 0, SCHED_STALLED, &ev);
    cr_assert_eq(ev.requeued, 1);
    cr_assert_eq(sched_worker_health(s, 0, 99999, 500, 300, &for_ms), SCHED_HEALTHY, "a gone worker is left alone");
    sched_evict(s, 0, SCHED_DIED, &ev); /* twice: nothing happens */
    cr_assert_eq(ev.requeued, 0);
    cr_assert_eq(s->tiles[0].crashes, 1);
    cr_assert_eq(sched_live_workers(s), 0);
    sched_free(&s);
}

Test(sched, kept_tiles_and_tiles_from_the_journal)
{
    struct sched *s = setup(4, 1, 1);
    cr_assert_eq(sched_tile_set_done(s, 3), 0);
    cr_assert_eq(sched_tile_set_done(s, 3), -1, "journaled twice: the first copy counts");
    give_one(s, 0); /* tile 0 */
    cr_assert_eq(sched_kept(s, 2), 0);
    sched_kept_valid(s, 0, 2); /* a queued tile */
    sched_kept_valid(s, 0, 0); /* a tile in flight: its holder's result becomes a duplicate */
    cr_assert_eq(sched_kept(s, 0), 1);
    cr_assert_eq(s->q_count, 1);
    cr_assert_eq(s->queue[0], 1);
    cr_assert_eq(s->workers[0].in_flight, 0);
    cr_assert_eq(sched_result(s, 0, 0, 1), SCHED_RESULT_DUPLICATE);
    cr_assert_eq(s->tiles_done, 3);
    sched_free(&s);
}

Test(sched, a_new_frame_keeps_bans_and_asks_for_ready_again)
{
    struct sched *s = setup(2, 2, 2);
    give_one(s, 0);
    struct sched_eviction ev;
    sched_evict(s, 1, SCHED_BANNED, &ev);
    s->workers[1].banned = 1;
    sched_evict(s, 0, SCHED_DIED, &ev);
    sched_frame_begin(s);
    cr_assert_eq(s->tiles[0].crashes, 0);
    cr_assert_eq(s->q_count, 2);
    cr_assert_eq(s->workers[1].banned, 1);
    int32_t c = sched_worker_join(s, 1, 0);
    assert_none(s, 0);
    sched_worker_ready(s, c, 1);
    cr_assert_eq(give_one(s, 0).attempt, 1);
    sched_free(&s);
}

/* ---- property test ---- */

static uint64_t prng_next(uint64_t *x) /* splitmix64: deterministic for a given seed */
{
    uint64_t z = (*x += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}
static uint32_t prng_below(uint64_t *x, uint32_t n) { return (uint32_t)(prng_next(x) % n); }

#define P_TILES 12
#define P_WORKERS 24
#define P_GIVEN 4096

/* The test's own model of who may answer: an assignment is held until its worker goes,
 * answers it, or the tile is done. */
struct given { uint32_t tile, attempt; int32_t worker; int answered; };
struct model {
    struct given g[P_GIVEN];
    uint32_t num_given;
    uint32_t done_count[P_TILES];
    int gone[P_WORKERS];
};

static int model_holds(const struct model *md, int32_t w, uint32_t tile, uint32_t attempt)
{
    if (md->gone[w] || md->done_count[tile] > 0)
        return 0;
    for (uint32_t i = 0; i < md->num_given; i++)
        if (md->g[i].worker == w && md->g[i].tile == tile && md->g[i].attempt == attempt && !md->g[i].answered)
            return 1;
    return 0;
}

static void straggler_expected(const struct sched *s, int32_t *worker, int32_t *tile);

static void drain_assignments(struct sched *s, struct model *md, uint64_t now)
{
    struct sched_assignment a;
    int32_t ew, et;
    while (md->num_given < P_GIVEN && (straggler_expected(s, &ew, &et), sched_assign_next(s, now, &a))) {
        if (a.straggler) /* the in-flight list gives the copy a scan of every tile would */
            cr_assert(a.worker == ew && (int32_t)a.tile == et, "straggler copy of tile %u to worker %d, expected %d to %d",
                      a.tile, a.worker, et, ew);
        cr_assert(!md->gone[a.worker] && s->workers[a.worker].ready);
        cr_assert_eq(md->done_count[a.tile], 0, "a done tile went out");
        md->g[md->num_given++] = (struct given){a.tile, a.attempt, a.worker, 0};
    }
}

/* Delivers the result of assignment i (valid or not) as the master would. */
static void deliver(struct sched *s, struct model *md, uint32_t i, int valid)
{
    struct given *g = &md->g[i];
    if (md->gone[g->worker])
        return; /* the master drops results of evicted workers before the scheduler */
    enum sched_result_verdict v = sched_result(s, g->worker, g->tile, g->attempt);
    int holds = model_holds(md, g->worker, g->tile, g->attempt);
    cr_assert_eq(v == SCHED_RESULT_CHECK, holds, "tile %u attempt %u worker %d: verdict %d, holder %d", g->tile,
                 g->attempt, g->worker, (int)v, holds);
    sched_worker_credit(s, g->worker);
    g->answered = 1;
    if (v != SCHED_RESULT_CHECK) {
        cr_assert(v == SCHED_RESULT_STALE || md->done_count[g->tile] > 0);
        return;
    }
    if (valid) {
        sched_result_valid(s, g->worker, g->tile);
        md->done_count[g->tile]++;
    } else {
        struct sched_eviction ev;
        if (sched_result_invalid(s, g->worker, g->tile, &ev))
            md->gone[g->worker] = 1;
    }
}

/* Whether a worker may take a unit now, restated here to check the scheduler against. */
static int may_take(const struct sched_worker *w)
{
    return !w->gone && w->ready && w->credits > 0 && !w->isolated && !w->blocked;
}

/* The takers bitmap holds exactly the workers that can take a unit, and live counts the
 * workers not gone. */
static void check_workers(const struct sched *s)
{
    uint32_t live = 0;
    cr_assert(s->takers_words * 64 >= s->num_workers);
    for (uint32_t w = 0; w < s->takers_words * 64; w++) {
        int bit = (int)((s->takers[w / 64] >> (w % 64)) & 1);
        int can = 0;
        if (w < s->num_workers) {
            can = may_take(&s->workers[w]);
            live += !s->workers[w].gone;
        }
        cr_assert_eq(bit, can, "worker %u's taker bit", w);
    }
    cr_assert_eq(s->live, live);
    cr_assert_eq(sched_live_workers(s), live);
    /* Each worker's held list names the tiles that list it as a holder, each at the place
     * the tile records. */
    for (uint32_t w = 0; w < s->num_workers; w++) {
        const struct sched_worker *k = &s->workers[w];
        for (uint32_t i = 0; i < k->in_flight; i++) {
            const struct sched_tile *t = &s->tiles[k->held[i]];
            int found = 0;
            for (uint32_t h = 0; h < t->num_holders; h++)
                found += t->holder[h] == (int32_t)w && t->holder_pos[h] == i;
            cr_assert_eq(found, 1, "worker %u's held[%u] = tile %u", w, i, k->held[i]);
        }
    }
    for (uint32_t t = 0; t < s->num_tiles; t++)
        for (uint32_t h = 0; h < s->tiles[t].num_holders; h++) {
            const struct sched_worker *k = &s->workers[s->tiles[t].holder[h]];
            cr_assert(s->tiles[t].holder_pos[h] < k->in_flight && k->held[s->tiles[t].holder_pos[h]] == t,
                      "tile %u's holder %u", t, h);
        }
}

static void check_invariants(const struct sched *s)
{
    uint32_t held[P_WORKERS] = {0}, done = 0;
    for (uint32_t t = 0; t < s->num_tiles; t++) {
        const struct sched_tile *st = &s->tiles[t];
        cr_assert(st->num_holders <= SCHED_MAX_HOLDERS);
        cr_assert(st->state == SCHED_ASSIGNED ? st->num_holders > 0 : st->num_holders == 0);
        for (uint32_t k = 0; k < st->num_holders; k++)
            held[st->holder[k]]++;
        done += st->state == SCHED_DONE;
        int queued = 0;
        for (uint32_t q = 0; q < s->q_count; q++)
            queued += s->queue[q] == t;
        cr_assert_eq(queued, st->state == SCHED_QUEUED, "tile %u in the queue %d times, state %d", t, queued, st->state);
    }
    cr_assert_eq(done, s->tiles_done);
    for (uint32_t w = 0; w < s->num_workers; w++)
        cr_assert_eq(held[w], s->workers[w].in_flight, "worker %u", w);
    /* The queue's window lies in its room and each queued tile knows its place there. */
    cr_assert(s->queue >= s->queue_buf && s->queue + s->q_count <= s->queue_buf + s->q_cap);
    for (uint32_t q = 0; q < s->q_count; q++)
        cr_assert_eq(s->qpos[s->queue[q]], (uint32_t)(s->queue - s->queue_buf) + q, "place of tile %u", s->queue[q]);
    for (uint32_t t = 0; t < s->num_tiles; t++)
        if (s->tiles[t].state != SCHED_QUEUED)
            cr_assert_eq(s->qpos[t], SCHED_NOT_QUEUED, "tile %u not queued", t);
    /* q_released counts the queued tiles below the release limit. */
    uint32_t rel = 0;
    for (uint32_t q = 0; q < s->q_count; q++)
        rel += s->queue[q] < s->released;
    cr_assert_eq(s->q_released, rel, "queued tiles released");
    /* The in-flight list: exactly the assigned tiles with one holder, linked both ways,
     * oldest first (assigned_ms, then tile). */
    uint32_t listed = 0, prev = SCHED_NONE;
    for (uint32_t t = s->fl_head; t != SCHED_NONE; prev = t, t = s->fl_next[t]) {
        cr_assert(t < s->num_tiles && listed < s->num_tiles, "the list's links");
        cr_assert(s->fl_in[t] && s->fl_prev[t] == prev, "tile %u's links", t);
        if (prev != SCHED_NONE)
            cr_assert(s->tiles[prev].assigned_ms < s->tiles[t].assigned_ms ||
                          (s->tiles[prev].assigned_ms == s->tiles[t].assigned_ms && prev < t),
                      "tiles %u, %u in order", prev, t);
        listed++;
    }
    cr_assert_eq(s->fl_tail, prev);
    check_workers(s);
    uint32_t one = 0;
    for (uint32_t t = 0; t < s->num_tiles; t++) {
        int want = s->tiles[t].state == SCHED_ASSIGNED && s->tiles[t].num_holders == 1;
        cr_assert_eq(s->fl_in[t], want, "tile %u in the in-flight list", t);
        one += want;
    }
    cr_assert_eq(listed, one);
}

/* The straggler copy sched_assign_next should make now, by a scan of every tile: for the
 * first idle worker that may take one, the oldest tile (then the lowest) in flight with
 * one holder, not its own, that crashed nobody. -1 worker: none is due. */
static void straggler_expected(const struct sched *s, int32_t *worker, int32_t *tile)
{
    *worker = *tile = -1;
    if (s->q_count > 0)
        return;
    for (uint32_t i = 0; i < s->num_workers; i++) {
        const struct sched_worker *w = &s->workers[i];
        if (!may_take(w) || w->in_flight > 0)
            continue;
        *worker = (int32_t)i;
        for (uint32_t t = 0; t < s->num_tiles; t++) {
            const struct sched_tile *st = &s->tiles[t];
            if (st->state != SCHED_ASSIGNED || st->num_holders != 1 || st->holder[0] == (int32_t)i || st->crashes > 0)
                continue;
            if (*tile < 0 || st->assigned_ms < s->tiles[*tile].assigned_ms)
                *tile = (int32_t)t;
        }
        return;
    }
}

/* The queue keeps its order whatever leaves it from where: the front (assignments), the
 * middle (tiles from the journal; tiles a worker may take behind ones it may not), both
 * ends coming back (unheld tiles to the back, re-issues to the front, past the start of
 * the queue's room, which moves the window), each queued tile knowing its place. */
Test(sched, the_queue_keeps_its_order)
{
    struct sched *s = sched_new(10);
    sched_frame_begin(s);
    const uint32_t journal[] = {7, 2, 5, 9};
    for (size_t i = 0; i < sizeof journal / sizeof *journal; i++)
        cr_assert_eq(sched_tile_set_done(s, journal[i]), 0);
    const uint32_t want1[] = {0, 1, 3, 4, 6, 8};
    cr_assert_eq(s->q_count, 6);
    for (uint32_t q = 0; q < 6; q++)
        cr_assert_eq(s->queue[q], want1[q], "place %u", q);
    check_invariants(s);
    /* A new frame, its units held and queued again in a chosen order; only 0-4 released,
     * so a worker takes them from behind 9-5, out of the middle. */
    sched_frame_begin(s);
    sched_hold_all(s);
    const uint32_t order[] = {9, 8, 7, 6, 5, 0, 1, 2, 3, 4};
    for (size_t i = 0; i < 10; i++)
        cr_assert_eq(sched_unhold(s, order[i]), 0);
    sched_release(s, 5);
    int32_t w = sched_worker_join(s, 1, 0);
    cr_assert_eq(sched_worker_ready(s, w, 4), 0);
    struct sched_assignment a[3];
    for (int i = 0; i < 3; i++) {
        a[i] = give_one(s, 1);
        cr_assert_eq(a[i].tile, (uint32_t)i);
    }
    const uint32_t want2[] = {9, 8, 7, 6, 5, 3, 4};
    cr_assert_eq(s->q_count, 7);
    for (uint32_t q = 0; q < 7; q++)
        cr_assert_eq(s->queue[q], want2[q], "place %u", q);
    check_invariants(s);
    /* Three back to the front, one by one: more than the one place left before it. */
    uint32_t *front = s->queue;
    for (int i = 0; i < 3; i++) {
        sched_assign_undo(s, &a[i]);
        cr_assert_eq(s->queue[0], a[i].tile);
        check_invariants(s);
    }
    cr_assert(s->queue > front, "the window moved into its room");
    const uint32_t want3[] = {2, 1, 0, 9, 8, 7, 6, 5, 3, 4};
    cr_assert_eq(s->q_count, 10);
    for (uint32_t q = 0; q < 10; q++)
        cr_assert_eq(s->queue[q], want3[q], "place %u", q);
    cr_assert_eq(sched_tile_set_done(s, 6), 0); /* from the middle */
    cr_assert_eq(s->queue[6], 5);
    cr_assert_eq(sched_tile_set_done(s, 6), -1);
    check_invariants(s);
    sched_free(&s);
}

static void run_sequence(uint64_t seed)
{
    uint64_t r = seed;
    uint32_t num_tiles = 1 + prng_below(&r, P_TILES);
    struct sched *s = sched_new(num_tiles);
    struct model md;
    memset(&md, 0, sizeof md);
    sched_frame_begin(s);
    for (uint32_t t = 0; t < num_tiles; t++)
        if (prng_below(&r, 8) == 0) { /* from the journal */
            cr_assert_eq(sched_tile_set_done(s, t), 0);
            md.done_count[t]++;
        }
    uint64_t now = 0;
    uint32_t steps = 20 + prng_below(&r, 60);
    for (uint32_t step = 0; step < steps && s->failed_tile < 0; step++) {
        now += prng_below(&r, 100);
        uint32_t e = prng_below(&r, 10);
        uint32_t nw = s->num_workers;
        if (e == 0 && nw < P_WORKERS - 2) {
            sched_worker_join(s, 1 + prng_below(&r, 3), now);
        } else if (e == 1 && nw > 0) {
            sched_worker_ready(s, (int32_t)prng_below(&r, nw), prng_below(&r, 6));
        } else if (e <= 4 && md.num_given > 0) {
            deliver(s, &md, prng_below(&r, md.num_given), prng_below(&r, 5) != 0);
        } else if (e == 5 && nw > 0) {
            /* A result nobody asked for: any worker, any tile, any attempt. */
            int32_t w = (int32_t)prng_below(&r, nw);
            uint32_t t = prng_below(&r, num_tiles), at = prng_below(&r, 4);
            if (!md.gone[w]) {
                enum sched_result_verdict v = sched_result(s, w, t, at);
                cr_assert_eq(v == SCHED_RESULT_CHECK, model_holds(&md, w, t, at));
            }
        } else if (e == 6 && nw > 0) {
            int32_t w = (int32_t)prng_below(&r, nw);
            enum sched_evict_kind k = (enum sched_evict_kind)prng_below(&r, SCHED_BANNED + 1);
            struct sched_eviction ev;
            sched_evict(s, w, k, &ev);
            md.gone[w] = 1;
        } else if (e == 7 && nw > 0) {
            int32_t w = (int32_t)prng_below(&r, nw);
            uint32_t t = prng_below(&r, num_tiles);
            if (!md.gone[w] && !sched_kept(s, t)) {
                cr_assert_eq(md.done_count[t], 0);
                if (prng_below(&r, 4)) {
                    sched_kept_valid(s, w, t);
                    md.done_count[t]++;
                } else {
                    struct sched_eviction ev;
                    if (sched_kept_invalid(s, w, &ev))
                        md.gone[w] = 1;
                }
            }
        } else if (e == 8 && prng_below(&r, 2) == 0) {
            /* The release limit moves (a pass's map published; a new one lower or higher). */
            sched_release(s, prng_below(&r, num_tiles + 2));
        } else if (nw > 0) {
            int32_t w = (int32_t)prng_below(&r, nw);
            sched_worker_heartbeat(s, w, prng_below(&r, 1000), 0, now);
        }
        drain_assignments(s, &md, now);
        check_invariants(s);
    }
    if (s->failed_tile >= 0) {
        cr_assert(s->tiles[s->failed_tile].crashes >= SCHED_CRASHES_TO_FAIL);
        sched_free(&s);
        return;
    }
    /* Drive to the end: every tile released, a healthy worker joins, everyone answers
     * everything validly. */
    sched_release(s, num_tiles);
    check_invariants(s);
    int32_t fresh = sched_worker_join(s, 2, now);
    for (uint32_t w = 0; w < s->num_workers; w++)
        if (!md.gone[w])
            sched_worker_ready(s, (int32_t)w, 8);
    for (uint32_t round = 0; round < 4 * P_TILES + 8 && s->tiles_done < num_tiles; round++) {
        drain_assignments(s, &md, ++now);
        for (uint32_t i = 0; i < md.num_given; i++)
            if (!md.g[i].answered)
                deliver(s, &md, i, 1);
        check_invariants(s);
    }
    (void)fresh;
    cr_assert_eq(s->tiles_done, num_tiles, "seed %llu: %u of %u tiles done", (unsigned long long)seed, s->tiles_done,
                 num_tiles);
    for (uint32_t t = 0; t < num_tiles; t++)
        cr_assert_eq(md.done_count[t], 1, "seed %llu: tile %u done %u times", (unsigned long long)seed, t,
                     md.done_count[t]);
    sched_free(&s);
}

Test(sched, property_every_tile_done_once_and_only_holders_count)
{
    for (uint64_t seed = 1; seed <= 3000; seed++)
        run_sequence(seed * 7919);
}

/* Many workers (the takers bitmap spans several words): every assignment goes to the
 * lowest-index worker that can take a unit, as a scan of every worker finds it, while
 * workers join late, run out of credits, get them back, are blocked and heard from, and
 * leave. */
Test(sched, many_workers_take_units_in_index_order)
{
    const uint32_t workers = 300, tiles = 4000;
    struct sched *s = sched_new(tiles);
    sched_frame_begin(s);
    uint64_t r = 12345;
    for (uint32_t i = 0; i < workers; i++)
        sched_worker_join(s, 1, 0);
    check_workers(s);
    struct sched_assignment held[4096];
    uint32_t nheld = 0, checked = 0;
    for (uint32_t step = 0; step < 20000 && s->tiles_done < tiles; step++) {
        r = r * 6364136223846793005ull + 1442695040888963407ull;
        uint32_t w = (uint32_t)(r >> 33) % workers, what = (uint32_t)(r >> 20) % 8;
        const struct sched_worker *k = &s->workers[w];
        if (what == 0 && !k->gone && !k->ready)
            sched_worker_ready(s, (int32_t)w, 1 + (uint32_t)(r >> 40) % 4);
        else if (what == 1 && !k->gone)
            sched_worker_heard(s, (int32_t)w, step);
        else if (what == 2 && nheld > 0) { /* an answer: its worker gets the credit back */
            uint32_t i = (uint32_t)(r >> 12) % nheld;
            struct sched_assignment a = held[i];
            held[i] = held[--nheld];
            if (sched_result(s, a.worker, a.tile, a.attempt) == SCHED_RESULT_CHECK)
                sched_result_valid(s, a.worker, a.tile);
            if (!s->workers[a.worker].gone)
                sched_worker_credit(s, a.worker);
        } else if (what == 3 && (r >> 50) % 40 == 0 && s->live > 8 && !k->gone) {
            struct sched_eviction ev;
            sched_evict(s, (int32_t)w, SCHED_LEFT, &ev);
        } else {
            /* the expected taker, by a scan */
            int32_t want = -1;
            for (uint32_t i = 0; i < s->num_workers && want < 0; i++)
                if (may_take(&s->workers[i]))
                    want = (int32_t)i;
            struct sched_assignment a;
            uint32_t queued = s->q_count;
            int got = sched_assign_next(s, step, &a);
            if (queued > 0) {
                cr_assert_eq(got ? a.worker : -1, want, "step %u", step);
                checked++;
            }
            if (got && what == 4) /* could not be queued: taken back, its worker blocked */
                sched_assign_undo(s, &a);
            else if (got) {
                cr_assert(nheld < 4096); /* at most the workers' credits are out */
                held[nheld++] = a;
            }
        }
        check_workers(s);
    }
    cr_assert(s->tiles_done > 1000 && checked > 2000 && s->live < workers, "%u done, %u checked, %u live", s->tiles_done,
              checked, s->live);
    sched_free(&s);
}
