/* Peers by routing identity (see peerindex.h): separate chaining over a power-of-two
 * bucket array, each slot's link stored per slot, so adding and removing allocate nothing. */
#include "master/peerindex.h"
#include "base/log.h"
#include <stdlib.h>
#include <string.h>

/* 64-bit FNV-1a folded to 32 bits: libzmq's generated routing ids differ in a counter's
 * low bytes, which FNV-1a spreads over every bucket bit. A peer can choose its own routing
 * id, but ids collide only into longer chains, never into a wrong match (the caller
 * compares the id and the key). */
static uint32_t id_hash(const uint8_t *id, size_t len)
{
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < len; i++) {
        h ^= id[i];
        h *= 1099511628211ull;
    }
    return (uint32_t)(h ^ (h >> 32));
}

void peer_index_init(struct peer_index *x, uint32_t max_slots)
{
    CHECK(max_slots >= 1 && max_slots <= (1u << 30));
    memset(x, 0, sizeof *x);
    uint32_t nb = 1;
    while (nb < 2 * max_slots) /* load factor at most 1/2 */
        nb *= 2;
    x->num_buckets = nb;
    x->num_slots = max_slots;
    x->head = mem_alloc(sizeof *x->head * nb);
    for (uint32_t b = 0; b < nb; b++)
        x->head[b] = -1;
    x->next = mem_alloc(sizeof *x->next * max_slots);
    x->hash = mem_alloc(sizeof *x->hash * max_slots);
    x->linked = mem_calloc(max_slots, 1);
}

void peer_index_fini(struct peer_index *x)
{
    free(x->head);
    free(x->next);
    free(x->hash);
    free(x->linked);
    memset(x, 0, sizeof *x);
}

void peer_index_remove(struct peer_index *x, int32_t slot)
{
    CHECK(slot >= 0 && (uint32_t)slot < x->num_slots);
    if (!x->linked[slot])
        return;
    int32_t *link = &x->head[x->hash[slot] & (x->num_buckets - 1)];
    while (*link != slot) {
        CHECK(*link >= 0);
        link = &x->next[*link];
    }
    *link = x->next[slot];
    x->linked[slot] = 0;
}

void peer_index_add(struct peer_index *x, int32_t slot, const uint8_t *id, size_t len)
{
    peer_index_remove(x, slot);
    uint32_t h = id_hash(id, len);
    uint32_t b = h & (x->num_buckets - 1);
    x->hash[slot] = h;
    x->next[slot] = x->head[b];
    x->head[b] = slot;
    x->linked[slot] = 1;
}

int32_t peer_index_first(const struct peer_index *x, const uint8_t *id, size_t len)
{
    if (!x->head)
        return -1;
    uint32_t h = id_hash(id, len);
    int32_t s = x->head[h & (x->num_buckets - 1)];
    while (s >= 0 && x->hash[s] != h)
        s = x->next[s];
    return s;
}

int32_t peer_index_next(const struct peer_index *x, int32_t slot)
{
    uint32_t h = x->hash[slot];
    int32_t s = x->next[slot];
    while (s >= 0 && x->hash[s] != h)
        s = x->next[s];
    return s;
}
