/* Unit tests for the master's peer index (master/peerindex.c): every slot holding an id
 * is found by it (with libzmq-like 5-byte counter ids and with ids all in one bucket), a
 * removed or moved slot is not, and random adds, moves and removes agree with a plain
 * table scanned in full. Run by `make unit`. */
#include <criterion/criterion.h>
#include <stdlib.h>
#include <string.h>
#include "master/peerindex.h"

/* libzmq's generated routing id: a zero byte and a 32-bit counter. */
static void zmq_like_id(uint32_t n, uint8_t id[5])
{
    id[0] = 0;
    memcpy(id + 1, &n, 4);
}

/* Whether slot is among those peer_index_first/next give for id. */
static int listed(const struct peer_index *x, const uint8_t *id, size_t len, int32_t slot)
{
    for (int32_t s = peer_index_first(x, id, len); s >= 0; s = peer_index_next(x, s))
        if (s == slot)
            return 1;
    return 0;
}

static uint32_t chain_length(const struct peer_index *x, const uint8_t *id, size_t len)
{
    uint32_t n = 0;
    for (int32_t s = peer_index_first(x, id, len); s >= 0; s = peer_index_next(x, s))
        n++;
    return n;
}

Test(peerindex, finds_every_slot_by_its_id)
{
    struct peer_index x;
    peer_index_init(&x, 8192);
    uint8_t id[5];
    for (uint32_t i = 0; i < 8192; i++) {
        zmq_like_id(i + 1000, id);
        peer_index_add(&x, (int32_t)i, id, sizeof id);
    }
    uint32_t longest = 0;
    for (uint32_t i = 0; i < 8192; i++) {
        zmq_like_id(i + 1000, id);
        cr_assert(listed(&x, id, sizeof id, (int32_t)i), "slot %u not found", i);
        uint32_t n = chain_length(&x, id, sizeof id);
        longest = n > longest ? n : longest;
    }
    /* only slots whose id hashes the same are listed: a lookup is not a scan */
    cr_expect_leq(longest, 2, "%u slots listed for one id", longest);
    zmq_like_id(999, id);
    cr_expect_eq(peer_index_first(&x, id, sizeof id), -1);
    peer_index_fini(&x);
}

Test(peerindex, same_id_in_several_slots)
{
    /* a peer may choose its routing id: a gone peer's id comes back on a new slot */
    struct peer_index x;
    peer_index_init(&x, 16);
    const uint8_t id[] = "chosen";
    for (int32_t s = 0; s < 16; s += 3)
        peer_index_add(&x, s, id, sizeof id - 1);
    cr_expect_eq(chain_length(&x, id, sizeof id - 1), 6);
    peer_index_remove(&x, 9);
    peer_index_remove(&x, 9); /* not there: nothing */
    cr_expect_not(listed(&x, id, sizeof id - 1, 9));
    cr_expect_eq(chain_length(&x, id, sizeof id - 1), 5);
    const uint8_t other[] = "other";
    peer_index_add(&x, 3, other, sizeof other - 1); /* the slot is reused by another peer */
    cr_expect_not(listed(&x, id, sizeof id - 1, 3));
    cr_expect(listed(&x, other, sizeof other - 1, 3));
    cr_expect_eq(chain_length(&x, id, sizeof id - 1), 4);
    peer_index_fini(&x);
}

Test(peerindex, random_operations_match_a_scan)
{
    enum { SLOTS = 300, IDS = 40, STEPS = 20000 };
    struct peer_index x;
    peer_index_init(&x, SLOTS);
    int holds[SLOTS]; /* the id each slot holds, -1 for none */
    for (int i = 0; i < SLOTS; i++)
        holds[i] = -1;
    srand(7);
    for (int step = 0; step < STEPS; step++) {
        int32_t slot = rand() % SLOTS;
        uint8_t id[5];
        if (rand() % 3 == 0) {
            peer_index_remove(&x, slot);
            holds[slot] = -1;
        } else {
            int v = rand() % IDS;
            zmq_like_id((uint32_t)v, id);
            peer_index_add(&x, slot, id, sizeof id);
            holds[slot] = v;
        }
        if (step % 97 == 0)
            for (int v = 0; v < IDS; v++) {
                zmq_like_id((uint32_t)v, id);
                for (int32_t s = 0; s < SLOTS; s++)
                    cr_assert_eq(listed(&x, id, sizeof id, s), holds[s] == v, "step %d id %d slot %d", step, v, s);
            }
    }
    peer_index_fini(&x);
}
