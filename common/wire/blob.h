/* Content-addressed blobs: the scene file and every asset travel to workers as blobs
 * named by a BLAKE2b-256 hash (libsodium) of their bytes, fetched in chunks and cached by
 * name, so a worker needs no shared filesystem and never renders with data whose hash
 * differs from the master's. The same mechanism carries the photon maps. */
#ifndef BRUME_BLOB_H
#define BRUME_BLOB_H
#include <stddef.h>
#include <stdint.h>

#define BLOB_HASH_SIZE 32
#define BLOB_MAX_SIZE (1ull << 32)      /* 4 GiB: larger assets are refused */
#define BLOB_CHUNK_SIZE (256u * 1024u)  /* bytes per BLOB_DATA message */

struct blob_hash { uint8_t bytes[BLOB_HASH_SIZE]; };

void blob_hash_compute(const void *data, size_t size, struct blob_hash *out);
/* 64 lowercase hex digits and a NUL into hex[65]. */
void blob_hash_hex(const struct blob_hash *h, char hex[65]);
int blob_hash_equal(const struct blob_hash *a, const struct blob_hash *b);
/* Keyed BLAKE2b-256 (a MAC): out = H_key(data); the master ties kept tiles to the key
 * they were assigned to with it. Tags compare with blob_mac_equal (constant time). */
void blob_mac_compute(const struct blob_hash *key, const void *data, size_t size, struct blob_hash *out);
int blob_mac_equal(const struct blob_hash *a, const struct blob_hash *b);

/* The BLAKE2b-256 of every BLOB_CHUNK_SIZE chunk of a blob, in order (the chunk list):
 * *hashes is mem_alloc'd, *count = blob_num_chunks(size). A receiver checks each chunk
 * against it before keeping it (broadcast chunks come from a stream shared by every
 * worker). */
static inline uint64_t blob_num_chunks(uint64_t size) { return (size + BLOB_CHUNK_SIZE - 1) / BLOB_CHUNK_SIZE; }
void blob_chunk_hashes(const uint8_t *data, uint64_t size, struct blob_hash **hashes, uint64_t *count);
/* A blob's name: the BLAKE2b-256 of its chunk list (count hashes of 32 bytes, one after
 * the other; none for an empty blob). So the list is bound to the name: a receiver checks
 * the list once against the name, then each chunk against the list, and the blob it
 * assembled is the one named without a second pass over its bytes; the sender gets the
 * name and the list from one pass. */
void blob_name_of_chunks(const struct blob_hash *hashes, uint64_t count, struct blob_hash *name);
/* The name of data (blob_chunk_hashes, then blob_name_of_chunks). */
void blob_name_compute(const void *data, uint64_t size, struct blob_hash *name);

/* A blob being received in chunks: the buffer is allocated from the announced size
 * (checked against BLOB_MAX_SIZE first), chunks may arrive in any order and more than
 * once, and the blob is complete when every byte arrived; blob_recv_finish then checks
 * its name. With a chunk list (blob_recv_set_chunks: checked against the name) every
 * chunk is checked against its hash before it is kept, a chunk already kept is not
 * touched again, and blob_recv_finish has nothing left to hash. */
struct blob_recv {
    struct blob_hash hash;
    uint64_t size;
    uint8_t *data;
    uint8_t *have;          /* one flag per chunk */
    uint64_t num_chunks, chunks_have;
    struct blob_hash *chunk_hashes; /* NULL, or num_chunks hashes */
    uint64_t chunks_bad;    /* chunks refused by their hash */
};
int blob_recv_init(struct blob_recv *r, const struct blob_hash *hash, uint64_t size, char *err, size_t errlen);
/* Stores chunk bytes at offset; offset must be a multiple of BLOB_CHUNK_SIZE and the
 * length exactly the chunk's length. Returns 0, or -1 with a reason (nothing stored). */
int blob_recv_put(struct blob_recv *r, uint64_t offset, const uint8_t *bytes, size_t len, char *err, size_t errlen);
int blob_recv_complete(const struct blob_recv *r);
/* Sets the chunk list: count must be the blob's chunk count and the list must hash to
 * the blob's name (blob_name_of_chunks); hashes are copied (32 bytes each, as they came
 * off the wire). 0, or -1 with a reason (the list is not set). Chunks kept before are
 * checked again and dropped when they do not match. */
int blob_recv_set_chunks(struct blob_recv *r, const uint8_t *hashes, uint64_t count, char *err, size_t errlen);
/* The index of the first chunk at or after `from` that is missing (num_chunks: none). */
uint64_t blob_recv_next_missing(const struct blob_recv *r, uint64_t from);
/* Verifies the name of a complete blob (hashing it unless every chunk was checked against
 * a chunk list); on success hands the data to *data (caller owns) and returns 0. */
int blob_recv_finish(struct blob_recv *r, uint8_t **data, char *err, size_t errlen);
void blob_recv_fini(struct blob_recv *r);

/* An in-memory store of blobs by name (master: published files; worker: cache). */
struct blob_store {
    struct blob_entry {
        struct blob_hash hash;
        uint8_t *data;
        uint64_t size;
        struct blob_hash *chunks; /* its chunk list (blob_num_chunks(size) hashes), or NULL */
    } *entries;
    size_t count, cap;
};
/* Adds a copy of data with its chunk list, or does nothing if present; returns the entry. */
const struct blob_entry *blob_store_put(struct blob_store *s, const void *data, uint64_t size);
/* Takes ownership of data (already named *hash). */
const struct blob_entry *blob_store_adopt(struct blob_store *s, const struct blob_hash *hash, uint8_t *data, uint64_t size);
/* The same, with its chunk list (owned from here on; NULL: none), as the one pass that
 * named it left it. */
const struct blob_entry *blob_store_adopt_listed(struct blob_store *s, const struct blob_hash *hash, uint8_t *data,
                                                 uint64_t size, struct blob_hash *chunks);
const struct blob_entry *blob_store_get(const struct blob_store *s, const struct blob_hash *hash);
/* Removes the entry with that hash, if any (entries returned before may move). */
void blob_store_drop(struct blob_store *s, const struct blob_hash *hash);
void blob_store_fini(struct blob_store *s);

#endif
