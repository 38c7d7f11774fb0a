/* The master's peers by routing identity: a hash of the ROUTER's routing id to the peer
 * slots that carry it, so that finding the sender of a message costs the same with four
 * workers as with four thousand (master.c's find_peer; it used to scan every slot).
 * A slot is in the index while it holds a peer (live or gone: a gone peer's late messages
 * are still recognised); the caller tells live from gone and compares the CurveZMQ key. */
#ifndef BRUME_PEERINDEX_H
#define BRUME_PEERINDEX_H
#include <stddef.h>
#include <stdint.h>

struct peer_index {
    int32_t *head;      /* per bucket: the first slot, or -1 */
    int32_t *next;      /* per slot: the next slot in its bucket, or -1 */
    uint32_t *hash;     /* per slot: the hash of its id (to unlink it) */
    uint8_t *linked;    /* per slot: in a bucket */
    uint32_t num_buckets;   /* a power of two */
    uint32_t num_slots;     /* slots addressable (next, hash, linked) */
};

/* An index for slots 0..max_slots-1 (at least 1). */
void peer_index_init(struct peer_index *x, uint32_t max_slots);
void peer_index_fini(struct peer_index *x);
/* Slot (< max_slots) now holds the peer with routing id id[0..len); a slot already in
 * the index is moved. */
void peer_index_add(struct peer_index *x, int32_t slot, const uint8_t *id, size_t len);
/* Slot no longer holds a peer (its slot is reused); no-op when it is not in the index. */
void peer_index_remove(struct peer_index *x, int32_t slot);
/* The slots whose id hashes like id[0..len) (a superset of those with that id; the caller
 * compares): the first, or -1, then peer_index_next of it, until -1. */
int32_t peer_index_first(const struct peer_index *x, const uint8_t *id, size_t len);
int32_t peer_index_next(const struct peer_index *x, int32_t slot);

#endif
