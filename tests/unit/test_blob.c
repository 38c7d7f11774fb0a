/* Unit tests for content-addressed blobs (common/wire/blob.c): the BLAKE2b-256 vectors, names
 * (the hash of the chunk list), chunked receive in any order with duplicates, rejection of
 * misplaced or mis-sized chunks and of oversize announcements before allocation, name
 * mismatches, chunk lists that do not fit the name, and the store.
 * Run by `make unit` with every other tests/unit/test_*.c. */
#include <criterion/criterion.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "wire/blob.h"

static void assert_hex(const struct blob_hash *h, const char *want)
{
    char hex[65];
    blob_hash_hex(h, hex);
    cr_assert_str_eq(hex, want);
}

static uint8_t *pattern(size_t size, uint32_t seed)
{
    uint8_t *p = malloc(size ? size : 1);
    uint32_t x = seed;
    for (size_t i = 0; i < size; i++) {
        x = x * 1664525u + 1013904223u;
        p[i] = (uint8_t)(x >> 24);
    }
    return p;
}

Test(blob, known_vectors)
{
    struct blob_hash h;
    blob_hash_compute("abc", 3, &h);
    assert_hex(&h, "bddd813c634239723171ef3fee98579b94964e3bb1cb3e427262c8c068d52319");
    blob_hash_compute(NULL, 0, &h);
    assert_hex(&h, "0e5751c026e543b2e8ab2eb06099daa1d1e5df47778f7787faab45cdf12fe3a8");
}

Test(blob, hash_equal)
{
    struct blob_hash a, b;
    blob_hash_compute("abc", 3, &a);
    blob_hash_compute("abc", 3, &b);
    cr_assert(blob_hash_equal(&a, &b));
    blob_hash_compute("abd", 3, &b);
    cr_assert(!blob_hash_equal(&a, &b));
}

Test(blob, shuffled_chunks_with_duplicates)
{
    const size_t size = 5 * (size_t)BLOB_CHUNK_SIZE + 1234;
    uint8_t *src = pattern(size, 7);
    struct blob_hash h;
    blob_name_compute(src, size, &h);

    struct blob_recv r;
    char err[256];
    cr_assert_eq(blob_recv_init(&r, &h, size, err, sizeof err), 0, "%s", err);
    cr_assert_eq(r.num_chunks, 6);
    /* Every chunk, some twice, in an order that is not the natural one. */
    const int order[] = {3, 5, 0, 3, 1, 5, 4, 0};
    for (size_t i = 0; i < sizeof order / sizeof order[0]; i++) {
        cr_assert(!blob_recv_complete(&r));
        uint64_t off = (uint64_t)order[i] * BLOB_CHUNK_SIZE;
        size_t len = size - off < BLOB_CHUNK_SIZE ? size - off : BLOB_CHUNK_SIZE;
        cr_assert_eq(blob_recv_put(&r, off, src + off, len, err, sizeof err), 0, "%s", err);
    }
    cr_assert(!blob_recv_complete(&r), "chunk 2 still missing");
    cr_assert_eq(blob_recv_finish(&r, &(uint8_t *){NULL}, err, sizeof err), -1);
    cr_assert(strstr(err, "incomplete"), "%s", err);
    cr_assert_eq(blob_recv_put(&r, 2ull * BLOB_CHUNK_SIZE, src + 2 * BLOB_CHUNK_SIZE, BLOB_CHUNK_SIZE, err, sizeof err), 0);
    cr_assert(blob_recv_complete(&r));
    cr_assert_eq(r.chunks_have, 6);

    uint8_t *data = NULL;
    cr_assert_eq(blob_recv_finish(&r, &data, err, sizeof err), 0, "%s", err);
    cr_assert(memcmp(data, src, size) == 0);
    blob_recv_fini(&r);   /* safe after finish: the data now belongs to the caller */
    free(data);
    free(src);
}

Test(blob, misplaced_or_missized_chunks_rejected)
{
    const size_t size = 2 * (size_t)BLOB_CHUNK_SIZE + 100;
    uint8_t *src = pattern(size + BLOB_CHUNK_SIZE, 3);
    struct blob_hash h;
    blob_name_compute(src, size, &h);
    struct blob_recv r;
    char err[256];
    cr_assert_eq(blob_recv_init(&r, &h, size, err, sizeof err), 0);
    struct { uint64_t off; size_t len; } bad[] = {
        {1, BLOB_CHUNK_SIZE},                              /* unaligned */
        {BLOB_CHUNK_SIZE / 2, BLOB_CHUNK_SIZE},            /* unaligned */
        {0, BLOB_CHUNK_SIZE - 1},                          /* short full chunk */
        {0, BLOB_CHUNK_SIZE + 1},                          /* long full chunk */
        {0, 0},
        {2ull * BLOB_CHUNK_SIZE, 99},                      /* short last chunk */
        {2ull * BLOB_CHUNK_SIZE, 101},                     /* long last chunk */
        {2ull * BLOB_CHUNK_SIZE, BLOB_CHUNK_SIZE},         /* last chunk as a full one */
        {3ull * BLOB_CHUNK_SIZE, 100},                     /* past the end */
        {UINT64_MAX - (UINT64_MAX % BLOB_CHUNK_SIZE), 1},  /* far past the end */
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        err[0] = '\0';
        cr_assert_eq(blob_recv_put(&r, bad[i].off, src, bad[i].len, err, sizeof err), -1, "case %zu", i);
        cr_assert(err[0], "case %zu has a reason", i);
        cr_assert_eq(r.chunks_have, 0, "nothing stored for case %zu", i);
    }
    cr_assert_eq(blob_recv_put(&r, 2ull * BLOB_CHUNK_SIZE, src + 2 * BLOB_CHUNK_SIZE, 100, err, sizeof err), 0);
    cr_assert_eq(r.chunks_have, 1);
    blob_recv_fini(&r);
    free(src);
}

Test(blob, hash_mismatch_detected)
{
    const size_t size = (size_t)BLOB_CHUNK_SIZE + 10;
    uint8_t *src = pattern(size, 11);
    struct blob_hash h, got;
    blob_name_compute(src, size, &got);
    h = got;
    h.bytes[0] ^= 1;
    struct blob_recv r;
    char err[512];
    cr_assert_eq(blob_recv_init(&r, &h, size, err, sizeof err), 0);
    cr_assert_eq(blob_recv_put(&r, 0, src, BLOB_CHUNK_SIZE, err, sizeof err), 0);
    cr_assert_eq(blob_recv_put(&r, BLOB_CHUNK_SIZE, src + BLOB_CHUNK_SIZE, 10, err, sizeof err), 0);
    cr_assert(blob_recv_complete(&r));
    uint8_t *data = NULL;
    cr_assert_eq(blob_recv_finish(&r, &data, err, sizeof err), -1);
    cr_assert_null(data);
    char want_hex[65], got_hex[65], msg[256];
    blob_hash_hex(&h, want_hex);
    blob_hash_hex(&got, got_hex);
    snprintf(msg, sizeof msg, "hash mismatch: expected %s got %s", want_hex, got_hex);
    cr_assert_str_eq(err, msg);
    blob_recv_fini(&r);
    free(src);
}

Test(blob, oversize_refused_before_allocation)
{
    struct blob_hash h = {{0}};
    struct blob_recv r;
    char err[256] = "";
    /* Were these allocated, ASan or the OOM abort would end the test. */
    cr_assert_eq(blob_recv_init(&r, &h, BLOB_MAX_SIZE + 1, err, sizeof err), -1);
    cr_assert(strstr(err, "limit"), "%s", err);
    cr_assert_null(r.data);
    cr_assert_null(r.have);
    blob_recv_fini(&r);   /* safe after a failed init */
    cr_assert_eq(blob_recv_init(&r, &h, UINT64_MAX, err, sizeof err), -1);
    cr_assert_null(r.data);
}

Test(blob, zero_size_blob)
{
    struct blob_hash h;
    blob_name_compute("", 0, &h);
    struct blob_recv r;
    char err[256];
    cr_assert_eq(blob_recv_init(&r, &h, 0, err, sizeof err), 0, "%s", err);
    cr_assert(blob_recv_complete(&r), "complete with no chunks");
    cr_assert_eq(blob_recv_put(&r, 0, (const uint8_t *)"", 0, err, sizeof err), -1, "no chunk to put");
    uint8_t *data = NULL;
    cr_assert_eq(blob_recv_finish(&r, &data, err, sizeof err), 0, "%s", err);
    cr_assert_not_null(data);
    free(data);
    blob_recv_fini(&r);

    blob_name_compute("x", 1, &h);
    cr_assert_eq(blob_recv_init(&r, &h, 0, err, sizeof err), 0);
    cr_assert_eq(blob_recv_finish(&r, &data, err, sizeof err), -1);
    cr_assert(strstr(err, "hash mismatch"), "%s", err);
    blob_recv_fini(&r);
}

Test(blob, exact_multiple_of_chunk_size)
{
    const size_t size = 2 * (size_t)BLOB_CHUNK_SIZE;
    uint8_t *src = pattern(size, 5);
    struct blob_hash h;
    blob_name_compute(src, size, &h);
    struct blob_recv r;
    char err[256];
    cr_assert_eq(blob_recv_init(&r, &h, size, err, sizeof err), 0);
    cr_assert_eq(r.num_chunks, 2);
    cr_assert_eq(blob_recv_put(&r, BLOB_CHUNK_SIZE, src + BLOB_CHUNK_SIZE, BLOB_CHUNK_SIZE, err, sizeof err), 0);
    cr_assert_eq(blob_recv_put(&r, 0, src, BLOB_CHUNK_SIZE, err, sizeof err), 0);
    uint8_t *data;
    cr_assert_eq(blob_recv_finish(&r, &data, err, sizeof err), 0, "%s", err);
    free(data);
    blob_recv_fini(&r);
    free(src);
}

Test(blob, store_put_get_adopt)
{
    struct blob_store s = {0};
    const struct blob_entry *a = blob_store_put(&s, "hello", 5);
    cr_assert_eq(a->size, 5);
    cr_assert(memcmp(a->data, "hello", 5) == 0);
    struct blob_hash ha = a->hash;
    cr_assert_eq(blob_store_put(&s, "hello", 5), blob_store_get(&s, &ha), "no duplicate");
    cr_assert_eq(s.count, 1);

    const struct blob_entry *e = blob_store_put(&s, NULL, 0);
    cr_assert_eq(e->size, 0);
    cr_assert_eq(s.count, 2);

    /* Adopting data already present frees it (ASan's leak check would notice). */
    uint8_t *dup = malloc(5);
    memcpy(dup, "hello", 5);
    cr_assert_eq(blob_store_adopt(&s, &ha, dup, 5)->size, 5);
    cr_assert_eq(s.count, 2);

    struct blob_hash missing;
    blob_hash_compute("absent", 6, &missing);
    cr_assert_null(blob_store_get(&s, &missing));

    /* Growth keeps every entry findable by hash. */
    struct blob_hash hashes[300];
    for (uint32_t i = 0; i < 300; i++) {
        uint8_t *p = pattern(17 + i, i);
        const struct blob_entry *x = blob_store_put(&s, p, 17 + i);
        hashes[i] = x->hash;
        free(p);
    }
    cr_assert_eq(s.count, 302);
    for (uint32_t i = 0; i < 300; i++) {
        const struct blob_entry *x = blob_store_get(&s, &hashes[i]);
        cr_assert_not_null(x);
        cr_assert_eq(x->size, 17 + i);
    }
    uint8_t *own = pattern(64, 999);
    struct blob_hash ho;
    blob_name_compute(own, 64, &ho);
    cr_assert_eq(blob_store_adopt(&s, &ho, own, 64)->data, own);
    blob_store_fini(&s);
    cr_assert_eq(s.count, 0);
    cr_assert_null(s.entries);
}

/* A chunk list: every chunk checked before it is kept, a kept one never overwritten, and a
 * list that arrives after chunks drops those that do not match it. */
Test(blob, chunk_list_checks_every_chunk)
{
    size_t size = 3 * BLOB_CHUNK_SIZE + 10;
    uint8_t *data = pattern(size, 5);
    struct blob_hash h, *list;
    uint64_t count;
    blob_name_compute(data, size, &h);
    blob_chunk_hashes(data, size, &list, &count);
    cr_assert_eq(count, 4);
    cr_assert_eq(blob_num_chunks(size), 4);
    cr_assert_eq(blob_num_chunks(0), 0);
    cr_assert_eq(blob_num_chunks(BLOB_CHUNK_SIZE), 1);
    struct blob_hash one;
    blob_hash_compute(data + 3 * BLOB_CHUNK_SIZE, 10, &one);
    cr_assert(blob_hash_equal(&one, &list[3]), "the last chunk's hash covers its 10 bytes");

    struct blob_recv r;
    char err[256];
    cr_assert_eq(blob_recv_init(&r, &h, size, err, sizeof err), 0);
    uint8_t *bad = pattern(BLOB_CHUNK_SIZE, 9);
    /* before the list: chunk 1 arrives corrupted, chunk 0 fine */
    cr_assert_eq(blob_recv_put(&r, BLOB_CHUNK_SIZE, bad, BLOB_CHUNK_SIZE, err, sizeof err), 0);
    cr_assert_eq(blob_recv_put(&r, 0, data, BLOB_CHUNK_SIZE, err, sizeof err), 0);
    cr_assert_eq(blob_recv_set_chunks(&r, list[0].bytes, 3, err, sizeof err), -1, "a count that does not fit");
    cr_assert_eq(blob_recv_set_chunks(&r, list[0].bytes, count, err, sizeof err), 0, "%s", err);
    cr_assert_eq(r.chunks_have, 1, "the bad chunk kept before the list is dropped");
    cr_assert_eq(r.chunks_bad, 1);
    cr_assert_eq(blob_recv_next_missing(&r, 0), 1);
    cr_assert_eq(blob_recv_put(&r, BLOB_CHUNK_SIZE, bad, BLOB_CHUNK_SIZE, err, sizeof err), -1);
    cr_assert(strstr(err, "hash"), "%s", err);
    cr_assert_eq(r.chunks_bad, 2);
    cr_assert_eq(blob_recv_next_missing(&r, 0), 1, "nothing kept");
    for (uint64_t i = 1; i < count; i++) {
        uint64_t off = i * BLOB_CHUNK_SIZE;
        size_t len = i == 3 ? 10 : BLOB_CHUNK_SIZE;
        cr_assert_eq(blob_recv_put(&r, off, data + off, len, err, sizeof err), 0, "%s", err);
    }
    cr_assert_eq(blob_recv_next_missing(&r, 0), 4);
    /* a kept chunk is final: a later bad copy changes nothing */
    cr_assert_eq(blob_recv_put(&r, 0, bad, BLOB_CHUNK_SIZE, err, sizeof err), 0);
    cr_assert(blob_recv_complete(&r));
    uint8_t *out;
    cr_assert_eq(blob_recv_finish(&r, &out, err, sizeof err), 0, "%s", err);
    cr_assert(memcmp(out, data, size) == 0);
    free(out);
    blob_recv_fini(&r);
    free(bad);
    free(list);
    free(data);
}

/* A name is the BLAKE2b-256 of the chunk list: one pass over the bytes gives both, and the
 * store keeps the list it was named by. */
Test(blob, name_is_the_hash_of_the_chunk_list)
{
    struct blob_hash name, want, one;
    blob_name_compute(NULL, 0, &name);
    assert_hex(&name, "0e5751c026e543b2e8ab2eb06099daa1d1e5df47778f7787faab45cdf12fe3a8"); /* no chunk: BLAKE2b("") */
    blob_name_compute("abc", 3, &name);
    blob_hash_compute("abc", 3, &one);
    blob_hash_compute(one.bytes, BLOB_HASH_SIZE, &want);
    cr_assert(blob_hash_equal(&name, &want), "one chunk: the hash of its hash");
    blob_hash_compute("abc", 3, &want);
    cr_assert(!blob_hash_equal(&name, &want), "not the hash of the bytes");

    size_t size = 2 * BLOB_CHUNK_SIZE + 7;
    uint8_t *data = pattern(size, 21);
    struct blob_hash *list;
    uint64_t count;
    blob_chunk_hashes(data, size, &list, &count);
    cr_assert_eq(count, 3);
    blob_hash_compute(list[0].bytes, 3 * BLOB_HASH_SIZE, &want);
    blob_name_compute(data, size, &name);
    cr_assert(blob_hash_equal(&name, &want));
    struct blob_hash of_list;
    blob_name_of_chunks(list, count, &of_list);
    cr_assert(blob_hash_equal(&of_list, &name));

    struct blob_store s = {0};
    const struct blob_entry *e = blob_store_put(&s, data, size);
    cr_assert(blob_hash_equal(&e->hash, &name));
    cr_assert_not_null(e->chunks);
    cr_assert(memcmp(e->chunks, list, 3 * sizeof *list) == 0, "the store keeps the list it named the blob by");
    blob_store_fini(&s);
    free(list);
    free(data);
}

/* A blob named once by its sender (blob_store_adopt_listed: the photon tracer's one pass)
 * is still checked on receipt: a chunk list that does not hash to the name is refused, a
 * corrupted chunk is refused against the list, and without a list a corrupted blob fails
 * its name at the end. */
Test(blob, named_once_still_checked_on_receipt)
{
    size_t size = 3 * BLOB_CHUNK_SIZE + 99;
    uint8_t *data = pattern(size, 17);
    struct blob_hash name, *list;
    uint64_t count;
    blob_chunk_hashes(data, size, &list, &count);
    blob_name_of_chunks(list, count, &name);
    struct blob_store s = {0};
    uint8_t *copy = malloc(size);
    memcpy(copy, data, size);
    struct blob_hash *owned = malloc(count * sizeof *owned);
    memcpy(owned, list, count * sizeof *owned);
    const struct blob_entry *e = blob_store_adopt_listed(&s, &name, copy, size, owned);
    cr_assert_eq(e->chunks, owned);

    char err[256];
    struct blob_recv r;
    cr_assert_eq(blob_recv_init(&r, &e->hash, size, err, sizeof err), 0, "%s", err);
    struct blob_hash swapped[4];
    memcpy(swapped, e->chunks, sizeof swapped);
    swapped[1] = e->chunks[2];
    swapped[2] = e->chunks[1];
    cr_assert_eq(blob_recv_set_chunks(&r, swapped[0].bytes, count, err, sizeof err), -1, "a list out of order");
    cr_assert(strstr(err, "name"), "%s", err);
    cr_assert_null(r.chunk_hashes, "a refused list is not kept");
    swapped[1] = e->chunks[1];
    swapped[2] = e->chunks[2];
    swapped[3].bytes[0] ^= 1;
    cr_assert_eq(blob_recv_set_chunks(&r, swapped[0].bytes, count, err, sizeof err), -1, "a list with a changed hash");
    cr_assert_eq(blob_recv_set_chunks(&r, e->chunks[0].bytes, count, err, sizeof err), 0, "%s", err);
    uint8_t *bad = malloc(BLOB_CHUNK_SIZE);
    memcpy(bad, data + BLOB_CHUNK_SIZE, BLOB_CHUNK_SIZE);
    bad[12345] ^= 0x40;
    cr_assert_eq(blob_recv_put(&r, BLOB_CHUNK_SIZE, bad, BLOB_CHUNK_SIZE, err, sizeof err), -1, "one flipped bit");
    for (uint64_t i = 0; i < count; i++) {
        uint64_t off = i * BLOB_CHUNK_SIZE;
        size_t len = i + 1 < count ? BLOB_CHUNK_SIZE : 99;
        cr_assert_eq(blob_recv_put(&r, off, data + off, len, err, sizeof err), 0, "%s", err);
    }
    uint8_t *out = NULL;
    cr_assert_eq(blob_recv_finish(&r, &out, err, sizeof err), 0, "%s", err);
    cr_assert(memcmp(out, data, size) == 0);
    free(out);
    blob_recv_fini(&r);

    /* no list: the flipped bit is kept, and the name check at the end refuses the blob */
    cr_assert_eq(blob_recv_init(&r, &e->hash, size, err, sizeof err), 0, "%s", err);
    for (uint64_t i = 0; i < count; i++) {
        uint64_t off = i * BLOB_CHUNK_SIZE;
        size_t len = i + 1 < count ? BLOB_CHUNK_SIZE : 99;
        cr_assert_eq(blob_recv_put(&r, off, i == 1 ? bad : data + off, len, err, sizeof err), 0, "%s", err);
    }
    out = NULL;
    cr_assert_eq(blob_recv_finish(&r, &out, err, sizeof err), -1);
    cr_assert(strstr(err, "hash mismatch"), "%s", err);
    cr_assert_null(out);
    blob_recv_fini(&r);
    free(bad);
    blob_store_fini(&s);
    free(list);
    free(data);
}
