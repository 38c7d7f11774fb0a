/* Content-addressed blobs (see blob.h): hashing, chunked receive and an in-memory store.
 * Invariants: a blob_recv never allocates before the announced size passed its limit,
 * stores only whole, aligned chunks, and hands out data only after the hash matched.
 * Called by the master (publishing scene files and the photon map) and by workers
 * (fetching and caching them). */
#include "wire/blob.h"
#include "base/log.h"
#include <pthread.h>
#include <sodium.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static pthread_once_t g_sodium_once = PTHREAD_ONCE_INIT;

static void sodium_init_once(void)
{
    /* Hashing works without sodium_init(), but the library asks for it before any use;
     * a failure means no usable RNG, which the hash does not need, so it is not fatal. */
    if (sodium_init() < 0)
        log_warn("sodium_init failed");
}

void blob_hash_compute(const void *data, size_t size, struct blob_hash *out)
{
    static const uint8_t empty[1] = {0};
    pthread_once(&g_sodium_once, sodium_init_once);
    /* libsodium wants a valid pointer even for zero bytes. */
    const void *in = size ? data : empty;
    crypto_generichash(out->bytes, BLOB_HASH_SIZE, in, size, NULL, 0);
}

void blob_mac_compute(const struct blob_hash *key, const void *data, size_t size, struct blob_hash *out)
{
    static const uint8_t empty[1] = {0};
    pthread_once(&g_sodium_once, sodium_init_once);
    crypto_generichash(out->bytes, BLOB_HASH_SIZE, size ? data : empty, size, key->bytes, BLOB_HASH_SIZE);
}

void blob_hash_hex(const struct blob_hash *h, char hex[65])
{
    static const char digits[] = "0123456789abcdef";
    for (int i = 0; i < BLOB_HASH_SIZE; i++) {
        hex[2 * i] = digits[h->bytes[i] >> 4];
        hex[2 * i + 1] = digits[h->bytes[i] & 15];
    }
    hex[64] = '\0';
}

int blob_hash_equal(const struct blob_hash *a, const struct blob_hash *b)
{
    return memcmp(a->bytes, b->bytes, BLOB_HASH_SIZE) == 0;
}

int blob_mac_equal(const struct blob_hash *a, const struct blob_hash *b)
{
    return sodium_memcmp(a->bytes, b->bytes, BLOB_HASH_SIZE) == 0;
}

/* ---- chunked receive ---- */

void blob_chunk_hashes(const uint8_t *data, uint64_t size, struct blob_hash **hashes, uint64_t *count)
{
    CHECK(size <= BLOB_MAX_SIZE);
    uint64_t n = blob_num_chunks(size);
    *hashes = mem_alloc((size_t)(n ? n : 1) * sizeof **hashes);
    for (uint64_t i = 0; i < n; i++) {
        uint64_t off = i * BLOB_CHUNK_SIZE, left = size - off;
        blob_hash_compute(data + off, (size_t)(left < BLOB_CHUNK_SIZE ? left : BLOB_CHUNK_SIZE), &(*hashes)[i]);
    }
    *count = n;
}

/* A blob's name from its chunk list as bytes (count hashes of BLOB_HASH_SIZE, back to back). */
static void name_of_list_bytes(const uint8_t *bytes, uint64_t count, struct blob_hash *name)
{
    blob_hash_compute(count ? bytes : NULL, (size_t)count * BLOB_HASH_SIZE, name);
}

void blob_name_of_chunks(const struct blob_hash *hashes, uint64_t count, struct blob_hash *name)
{
    name_of_list_bytes(count ? hashes[0].bytes : NULL, count, name);
}

void blob_name_compute(const void *data, uint64_t size, struct blob_hash *name)
{
    struct blob_hash *hashes;
    uint64_t count;
    blob_chunk_hashes(data, size, &hashes, &count);
    blob_name_of_chunks(hashes, count, name);
    free(hashes);
}

static size_t chunk_len(const struct blob_recv *r, uint64_t idx)
{
    uint64_t left = r->size - idx * BLOB_CHUNK_SIZE;
    return (size_t)(left < BLOB_CHUNK_SIZE ? left : BLOB_CHUNK_SIZE);
}

static int chunk_matches(const struct blob_recv *r, uint64_t idx, const uint8_t *bytes, size_t len)
{
    struct blob_hash h;
    blob_hash_compute(bytes, len, &h);
    return blob_hash_equal(&h, &r->chunk_hashes[idx]);
}

int blob_recv_set_chunks(struct blob_recv *r, const uint8_t *hashes, uint64_t count, char *err, size_t errlen)
{
    if (!r->data && r->size) {
        str_fmt(err, errlen, "chunk list for a blob not being received");
        return -1;
    }
    if (count != r->num_chunks) {
        str_fmt(err, errlen, "chunk list of %llu hashes for a blob of %llu chunks", (unsigned long long)count,
                (unsigned long long)r->num_chunks);
        return -1;
    }
    struct blob_hash name; /* from the list's bytes as they came, before any copy */
    name_of_list_bytes(hashes, count, &name);
    if (!blob_hash_equal(&name, &r->hash)) {
        str_fmt(err, errlen, "chunk list does not hash to the blob's name");
        return -1;
    }
    struct blob_hash *list = mem_alloc((size_t)(count ? count : 1) * sizeof *list);
    if (count)
        memcpy(list, hashes, (size_t)count * BLOB_HASH_SIZE);
    free(r->chunk_hashes);
    r->chunk_hashes = list;
    for (uint64_t i = 0; i < count; i++)
        if (r->have[i] && !chunk_matches(r, i, r->data + i * BLOB_CHUNK_SIZE, chunk_len(r, i))) {
            r->have[i] = 0;
            r->chunks_have--;
            r->chunks_bad++;
        }
    return 0;
}

uint64_t blob_recv_next_missing(const struct blob_recv *r, uint64_t from)
{
    uint64_t i = from;
    while (i < r->num_chunks && r->have[i])
        i++;
    return i < r->num_chunks ? i : r->num_chunks;
}

int blob_recv_init(struct blob_recv *r, const struct blob_hash *hash, uint64_t size, char *err, size_t errlen)
{
    memset(r, 0, sizeof *r);
    /* The size comes from the peer: check it before it becomes an allocation. */
    if (size > BLOB_MAX_SIZE || size > SIZE_MAX) {
        str_fmt(err, errlen, "blob size %llu exceeds the limit of %llu bytes",
                (unsigned long long)size, (unsigned long long)BLOB_MAX_SIZE);
        return -1;
    }
    r->hash = *hash;
    r->size = size;
    r->num_chunks = blob_num_chunks(size);
    r->data = mem_alloc((size_t)size);
    r->have = mem_calloc((size_t)r->num_chunks, 1);
    r->chunks_have = 0;
    return 0;
}

int blob_recv_put(struct blob_recv *r, uint64_t offset, const uint8_t *bytes, size_t len, char *err, size_t errlen)
{
    if (!r->data) {
        str_fmt(err, errlen, "blob chunk for a blob not being received");
        return -1;
    }
    if (offset % BLOB_CHUNK_SIZE != 0 || offset >= r->size) {
        str_fmt(err, errlen, "blob chunk offset %llu invalid (size %llu, chunks of %u)",
                (unsigned long long)offset, (unsigned long long)r->size, BLOB_CHUNK_SIZE);
        return -1;
    }
    uint64_t left = r->size - offset;
    uint64_t expect = left < BLOB_CHUNK_SIZE ? left : BLOB_CHUNK_SIZE;
    if ((uint64_t)len != expect) {
        str_fmt(err, errlen, "blob chunk at offset %llu has %zu bytes, expected %llu",
                (unsigned long long)offset, len, (unsigned long long)expect);
        return -1;
    }
    uint64_t idx = offset / BLOB_CHUNK_SIZE;
    if (r->chunk_hashes) {
        /* Checked chunks are final: a duplicate costs nothing, a bad chunk is dropped (the
         * caller fetches it again). */
        if (r->have[idx])
            return 0;
        if (!chunk_matches(r, idx, bytes, len)) {
            r->chunks_bad++;
            str_fmt(err, errlen, "blob chunk at offset %llu does not match its hash", (unsigned long long)offset);
            return -1;
        }
    }
    /* A duplicate (a re-sent request) overwrites with what must be the same bytes; if a
     * peer lied, the name check in blob_recv_finish catches it either way. */
    memcpy(r->data + offset, bytes, len);
    if (!r->have[idx]) {
        r->have[idx] = 1;
        r->chunks_have++;
    }
    return 0;
}

int blob_recv_complete(const struct blob_recv *r)
{
    return r->data != NULL && r->chunks_have == r->num_chunks;
}

int blob_recv_finish(struct blob_recv *r, uint8_t **data, char *err, size_t errlen)
{
    if (!blob_recv_complete(r)) {
        str_fmt(err, errlen, "blob incomplete: %llu of %llu chunks",
                (unsigned long long)r->chunks_have, (unsigned long long)r->num_chunks);
        return -1;
    }
    /* With a chunk list, the list matched the name and every kept chunk its hash: the
     * bytes are the named ones, no need to hash them again. */
    struct blob_hash got = r->hash;
    if (!r->chunk_hashes)
        blob_name_compute(r->data, r->size, &got);
    if (!blob_hash_equal(&got, &r->hash)) {
        char want_hex[65], got_hex[65];
        blob_hash_hex(&r->hash, want_hex);
        blob_hash_hex(&got, got_hex);
        str_fmt(err, errlen, "hash mismatch: expected %s got %s", want_hex, got_hex);
        return -1;
    }
    *data = r->data;
    r->data = NULL;
    free(r->have);
    r->have = NULL;
    free(r->chunk_hashes);
    r->chunk_hashes = NULL;
    return 0;
}

void blob_recv_fini(struct blob_recv *r)
{
    free(r->data);
    free(r->have);
    free(r->chunk_hashes);
    r->data = NULL;
    r->have = NULL;
    r->chunk_hashes = NULL;
    r->num_chunks = r->chunks_have = 0;
}

/* ---- store ---- */

const struct blob_entry *blob_store_get(const struct blob_store *s, const struct blob_hash *hash)
{
    /* A few hundred entries at most (a scene's files and a photon map per frame), so a
     * linear scan costs nothing next to one network round trip. */
    for (size_t i = 0; i < s->count; i++)
        if (blob_hash_equal(&s->entries[i].hash, hash))
            return &s->entries[i];
    return NULL;
}

const struct blob_entry *blob_store_adopt_listed(struct blob_store *s, const struct blob_hash *hash, uint8_t *data,
                                                 uint64_t size, struct blob_hash *chunks)
{
    const struct blob_entry *have = blob_store_get(s, hash);
    if (have) {
        free(data);   /* ownership was handed over; the stored copy is identical */
        free(chunks);
        return have;
    }
    if (s->count == s->cap) {
        size_t cap = s->cap ? s->cap * 2 : 16;
        s->entries = mem_realloc(s->entries, cap * sizeof *s->entries);
        s->cap = cap;
    }
    struct blob_entry *e = &s->entries[s->count++];
    e->hash = *hash;
    e->data = data;
    e->size = size;
    e->chunks = chunks;
    return e;
}

const struct blob_entry *blob_store_adopt(struct blob_store *s, const struct blob_hash *hash, uint8_t *data, uint64_t size)
{
    return blob_store_adopt_listed(s, hash, data, size, NULL);
}

const struct blob_entry *blob_store_put(struct blob_store *s, const void *data, uint64_t size)
{
    CHECK(size <= SIZE_MAX);
    struct blob_hash h, *chunks;
    uint64_t count;
    blob_chunk_hashes(data, size, &chunks, &count);
    blob_name_of_chunks(chunks, count, &h);
    const struct blob_entry *have = blob_store_get(s, &h);
    if (have) {
        free(chunks);
        return have;
    }
    uint8_t *copy = mem_alloc((size_t)size);
    if (size)
        memcpy(copy, data, (size_t)size);
    return blob_store_adopt_listed(s, &h, copy, size, chunks);
}

void blob_store_drop(struct blob_store *s, const struct blob_hash *hash)
{
    for (size_t i = 0; i < s->count; i++)
        if (blob_hash_equal(&s->entries[i].hash, hash)) {
            free(s->entries[i].data);
            free(s->entries[i].chunks);
            s->entries[i] = s->entries[--s->count];
            return;
        }
}

void blob_store_fini(struct blob_store *s)
{
    for (size_t i = 0; i < s->count; i++) {
        free(s->entries[i].data);
        free(s->entries[i].chunks);
    }
    free(s->entries);
    s->entries = NULL;
    s->count = s->cap = 0;
}
