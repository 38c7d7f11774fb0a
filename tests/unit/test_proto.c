/* Unit tests for the wire protocol (common/wire/proto.c): round trips of every message type,
 * the exact byte layout, and rejection of every malformed frame the network can deliver
 * (truncations, oversized counts, wrong magic or version, trailing bytes, bit flips).
 * Run by `make unit` with every other tests/unit/test_*.c. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "wire/proto.h"
#include "wire/fetch.h"

static const uint8_t k_blob_bytes[] = {1, 2, 3, 4, 5, 0, 255, 7};
static const uint8_t k_chunk_bytes[] = "not really an EXR chunk";
static struct proto_asset k_assets[3];
static uint8_t k_chunk_hashes[3 * BLOB_HASH_SIZE];

static struct blob_hash make_hash(uint8_t seed)
{
    struct blob_hash h;
    for (int i = 0; i < BLOB_HASH_SIZE; i++)
        h.bytes[i] = (uint8_t)(seed * 31 + i);
    return h;
}

/* One filled-in message of each type, with values that use every byte of their fields
 * so that a byte-order or offset mistake shows. */
static size_t make_samples(struct proto_msg out[MSG_TYPE_MAX_])
{
    size_t n = 0;
    memset(out, 0, sizeof(struct proto_msg) * MSG_TYPE_MAX_);

    out[n].type = MSG_HELLO;
    out[n].u.hello.threads = 0x01020304u;
    out[n].u.hello.pid = 0xfffffffeu;
    strcpy(out[n].u.hello.host, "node-17.cluster");
    n++;

    for (int i = 0; i < 3; i++) {
        memset(&k_assets[i], 0, sizeof k_assets[i]);
        strcpy(k_assets[i].path, i == 0 ? "scene.json" : i == 1 ? "meshes/bunny.obj" : "t/wood.png");
        k_assets[i].hash = make_hash((uint8_t)(i + 1));
        k_assets[i].size = 0xfedcba98ull - (uint64_t)i;
    }
    out[n].type = MSG_JOB;
    out[n].u.job.job_id = 0x1122334455667788ull;
    out[n].u.job.job_key = make_hash(77);
    out[n].u.job.frame = 42;
    out[n].u.job.width = 1920;
    out[n].u.job.height = 1080;
    out[n].u.job.spp = 256;
    out[n].u.job.max_depth = 0;
    out[n].u.job.tile_size = 32;
    out[n].u.job.seed = 0xdeadbeefcafef00dull;
    out[n].u.job.sampler = SAMPLER_SOBOL;
    out[n].u.job.aovs = AOV_ALL;
    out[n].u.job.filter = FILTER_GAUSSIAN;
    out[n].u.job.filter_width = 1.5f;
    out[n].u.job.photon_maps = 8;
    out[n].u.job.passes = 8;
    out[n].u.job.embree_isa = EMBREE_ISA_AVX512;
    strcpy(out[n].u.job.scene_path, "scene.json");
    out[n].u.job.num_assets = 3;
    out[n].u.job.assets = k_assets;
    n++;

    out[n].type = MSG_BLOB_REQ;
    out[n].u.blob_req.hash = make_hash(9);
    out[n].u.blob_req.offset = 3ull * BLOB_CHUNK_SIZE;
    out[n].u.blob_req.length = BLOB_CHUNK_SIZE;
    n++;

    out[n].type = MSG_BLOB_DATA;
    out[n].u.blob_data.hash = make_hash(10);
    out[n].u.blob_data.offset = BLOB_CHUNK_SIZE;
    out[n].u.blob_data.total_size = BLOB_CHUNK_SIZE + sizeof k_blob_bytes;
    out[n].u.blob_data.bytes = k_blob_bytes;
    out[n].u.blob_data.length = sizeof k_blob_bytes;
    n++;

    out[n].type = MSG_READY;
    out[n].u.ready.job_id = 7;
    out[n].u.ready.credits = 4;
    n++;

    out[n].type = MSG_TILE;
    out[n].u.tile.job_id = 0x8000000000000001ull;
    out[n].u.tile.frame = 3;
    out[n].u.tile.tile = 1234;
    out[n].u.tile.attempt = 2;
    out[n].u.tile.pass = 1023;
    out[n].u.tile.mask = 0x8000000000000001ull;
    out[n].u.tile.tag = make_hash(91);
    n++;

    out[n].type = MSG_RESULT;
    out[n].u.result.job_id = 99;
    out[n].u.result.frame = 5;
    out[n].u.result.tile = 77;
    out[n].u.result.attempt = 1;
    out[n].u.result.stats.samples = 1024ull * 1024;
    out[n].u.result.stats.rays = 0x0123456789abcdefull;
    out[n].u.result.stats.nan_samples = 3;
    out[n].u.result.stats.render_ns = 123456789;
    out[n].u.result.stats.sum_rel_stderr = 0.1234567890123;
    out[n].u.result.stats.rel_stderr_pixels = 1000;
    out[n].u.result.chunk = k_chunk_bytes;
    out[n].u.result.chunk_size = sizeof k_chunk_bytes;
    n++;

    out[n].type = MSG_ERROR;
    out[n].u.error.job_id = 12;
    strcpy(out[n].u.error.text, "scene.json:3:4: unknown material \"glas\"");
    n++;

    out[n].type = MSG_HEARTBEAT;
    out[n].u.heartbeat.job_id = 12;
    out[n].u.heartbeat.tiles_done = 400;
    out[n].u.heartbeat.samples_done = 0x0102030405060708ull;
    out[n].u.heartbeat.stalled_ms = 0x0a0b0c0du;
    out[n].u.heartbeat.map_wait_ms = 0x11223344u;
    n++;

    out[n].type = MSG_BYE;
    n++;

    out[n].type = MSG_MAP;
    out[n].u.map.job_id = 0x0102030405060708ull;
    out[n].u.map.pass = PROTO_MAX_PASSES - 1;
    out[n].u.map.published = PROTO_MAX_PASSES;
    out[n].u.map.hash = make_hash(33);
    out[n].u.map.size = 0x00000000f1e2d3c4ull;
    n++;

    out[n].type = MSG_ACK;
    out[n].u.ack.job_id = 0x0102030405060708ull;
    out[n].u.ack.frame = 6;
    out[n].u.ack.count = 3;
    out[n].u.ack.tiles[0] = 0;
    out[n].u.ack.tiles[1] = 0x01020304u;
    out[n].u.ack.tiles[2] = 1023;
    n++;

    out[n].type = MSG_KEPT;
    out[n].u.kept.job_id = 0x8877665544332211ull;
    out[n].u.kept.job_key = make_hash(78);
    out[n].u.kept.frame = 7;
    out[n].u.kept.tile = 0x0a0b0c0du;
    out[n].u.kept.tag = make_hash(92);
    out[n].u.kept.stats.samples = 5;
    out[n].u.kept.stats.rays = 0x0123456789abcdefull;
    out[n].u.kept.stats.nan_samples = 1;
    out[n].u.kept.stats.render_ns = 987654321;
    out[n].u.kept.stats.sum_rel_stderr = -0.5;
    out[n].u.kept.stats.rel_stderr_pixels = 3;
    out[n].u.kept.chunk = k_chunk_bytes;
    out[n].u.kept.chunk_size = sizeof k_chunk_bytes;
    n++;

    out[n].type = MSG_CHUNKS_REQ;
    out[n].u.chunks_req.hash = make_hash(44);
    n++;

    for (size_t i = 0; i < sizeof k_chunk_hashes; i++)
        k_chunk_hashes[i] = (uint8_t)(i * 7 + 1);
    out[n].type = MSG_CHUNKS;
    out[n].u.chunks.hash = make_hash(45);
    out[n].u.chunks.size = 2ull * BLOB_CHUNK_SIZE + 0x0102;
    out[n].u.chunks.flags = PROTO_CHUNKS_BCAST;
    out[n].u.chunks.bcast_port = 0xa1b2;
    out[n].u.chunks.count = 3;
    out[n].u.chunks.hashes = k_chunk_hashes;
    n++;
    return n;
}

static void assert_hash_eq(const struct blob_hash *a, const struct blob_hash *b)
{
    cr_assert(memcmp(a->bytes, b->bytes, BLOB_HASH_SIZE) == 0);
}

/* A RESULT's or KEPT's tile statistics and EXR chunk. */
static void assert_tile_eq(const struct tile_stats *x, const uint8_t *xc, uint32_t xn, const struct tile_stats *y,
                           const uint8_t *yc, uint32_t yn)
{
    cr_assert_eq(x->samples, y->samples);
    cr_assert_eq(x->rays, y->rays);
    cr_assert_eq(x->nan_samples, y->nan_samples);
    cr_assert_eq(x->render_ns, y->render_ns);
    cr_assert(memcmp(&x->sum_rel_stderr, &y->sum_rel_stderr, sizeof(double)) == 0);
    cr_assert_eq(x->rel_stderr_pixels, y->rel_stderr_pixels);
    cr_assert_eq(xn, yn);
    cr_assert(memcmp(xc, yc, xn) == 0);
}

static void assert_msg_eq(const struct proto_msg *a, const struct proto_msg *b)
{
    cr_assert_eq(a->type, b->type);
    switch (a->type) {
    case MSG_HELLO:
        cr_assert_eq(a->u.hello.threads, b->u.hello.threads);
        cr_assert_eq(a->u.hello.pid, b->u.hello.pid);
        cr_assert_str_eq(a->u.hello.host, b->u.hello.host);
        break;
    case MSG_JOB: {
        const struct msg_job *x = &a->u.job, *y = &b->u.job;
        cr_assert_eq(x->job_id, y->job_id);
        assert_hash_eq(&x->job_key, &y->job_key);
        cr_assert_eq(x->frame, y->frame);
        cr_assert_eq(x->width, y->width);
        cr_assert_eq(x->height, y->height);
        cr_assert_eq(x->spp, y->spp);
        cr_assert_eq(x->max_depth, y->max_depth);
        cr_assert_eq(x->tile_size, y->tile_size);
        cr_assert_eq(x->seed, y->seed);
        cr_assert_eq(x->sampler, y->sampler);
        cr_assert_eq(x->aovs, y->aovs);
        cr_assert_eq(x->filter, y->filter);
        cr_assert_eq(x->filter_width, y->filter_width);
        cr_assert_eq(x->photon_maps, y->photon_maps);
        cr_assert_eq(x->passes, y->passes);
        cr_assert_eq(x->embree_isa, y->embree_isa);
        cr_assert_str_eq(x->scene_path, y->scene_path);
        cr_assert_eq(x->num_assets, y->num_assets);
        for (uint32_t i = 0; i < x->num_assets; i++) {
            cr_assert_str_eq(x->assets[i].path, y->assets[i].path);
            assert_hash_eq(&x->assets[i].hash, &y->assets[i].hash);
            cr_assert_eq(x->assets[i].size, y->assets[i].size);
        }
        break;
    }
    case MSG_BLOB_REQ:
        assert_hash_eq(&a->u.blob_req.hash, &b->u.blob_req.hash);
        cr_assert_eq(a->u.blob_req.offset, b->u.blob_req.offset);
        cr_assert_eq(a->u.blob_req.length, b->u.blob_req.length);
        break;
    case MSG_BLOB_DATA:
        assert_hash_eq(&a->u.blob_data.hash, &b->u.blob_data.hash);
        cr_assert_eq(a->u.blob_data.offset, b->u.blob_data.offset);
        cr_assert_eq(a->u.blob_data.total_size, b->u.blob_data.total_size);
        cr_assert_eq(a->u.blob_data.length, b->u.blob_data.length);
        cr_assert(memcmp(a->u.blob_data.bytes, b->u.blob_data.bytes, a->u.blob_data.length) == 0);
        break;
    case MSG_READY:
        cr_assert_eq(a->u.ready.job_id, b->u.ready.job_id);
        cr_assert_eq(a->u.ready.credits, b->u.ready.credits);
        break;
    case MSG_TILE:
        cr_assert_eq(a->u.tile.job_id, b->u.tile.job_id);
        cr_assert_eq(a->u.tile.frame, b->u.tile.frame);
        cr_assert_eq(a->u.tile.tile, b->u.tile.tile);
        cr_assert_eq(a->u.tile.attempt, b->u.tile.attempt);
        cr_assert_eq(a->u.tile.pass, b->u.tile.pass);
        cr_assert_eq(a->u.tile.mask, b->u.tile.mask);
        assert_hash_eq(&a->u.tile.tag, &b->u.tile.tag);
        break;
    case MSG_RESULT: {
        const struct msg_result *x = &a->u.result, *y = &b->u.result;
        cr_assert_eq(x->job_id, y->job_id);
        cr_assert_eq(x->frame, y->frame);
        cr_assert_eq(x->tile, y->tile);
        cr_assert_eq(x->attempt, y->attempt);
        assert_tile_eq(&x->stats, x->chunk, x->chunk_size, &y->stats, y->chunk, y->chunk_size);
        break;
    }
    case MSG_ERROR:
        cr_assert_eq(a->u.error.job_id, b->u.error.job_id);
        cr_assert_str_eq(a->u.error.text, b->u.error.text);
        break;
    case MSG_HEARTBEAT:
        cr_assert_eq(a->u.heartbeat.job_id, b->u.heartbeat.job_id);
        cr_assert_eq(a->u.heartbeat.tiles_done, b->u.heartbeat.tiles_done);
        cr_assert_eq(a->u.heartbeat.samples_done, b->u.heartbeat.samples_done);
        cr_assert_eq(a->u.heartbeat.stalled_ms, b->u.heartbeat.stalled_ms);
        cr_assert_eq(a->u.heartbeat.map_wait_ms, b->u.heartbeat.map_wait_ms);
        break;
    case MSG_ACK:
        cr_assert_eq(a->u.ack.job_id, b->u.ack.job_id);
        cr_assert_eq(a->u.ack.frame, b->u.ack.frame);
        cr_assert_eq(a->u.ack.count, b->u.ack.count);
        for (uint32_t i = 0; i < a->u.ack.count; i++)
            cr_assert_eq(a->u.ack.tiles[i], b->u.ack.tiles[i]);
        break;
    case MSG_KEPT: {
        const struct msg_kept *x = &a->u.kept, *y = &b->u.kept;
        cr_assert_eq(x->job_id, y->job_id);
        assert_hash_eq(&x->job_key, &y->job_key);
        cr_assert_eq(x->frame, y->frame);
        cr_assert_eq(x->tile, y->tile);
        assert_hash_eq(&x->tag, &y->tag);
        assert_tile_eq(&x->stats, x->chunk, x->chunk_size, &y->stats, y->chunk, y->chunk_size);
        break;
    }
    case MSG_MAP:
        cr_assert_eq(a->u.map.job_id, b->u.map.job_id);
        cr_assert_eq(a->u.map.pass, b->u.map.pass);
        cr_assert_eq(a->u.map.published, b->u.map.published);
        assert_hash_eq(&a->u.map.hash, &b->u.map.hash);
        cr_assert_eq(a->u.map.size, b->u.map.size);
        break;
    case MSG_CHUNKS_REQ:
        assert_hash_eq(&a->u.chunks_req.hash, &b->u.chunks_req.hash);
        break;
    case MSG_CHUNKS:
        assert_hash_eq(&a->u.chunks.hash, &b->u.chunks.hash);
        cr_assert_eq(a->u.chunks.size, b->u.chunks.size);
        cr_assert_eq(a->u.chunks.flags, b->u.chunks.flags);
        cr_assert_eq(a->u.chunks.bcast_port, b->u.chunks.bcast_port);
        cr_assert_eq(a->u.chunks.count, b->u.chunks.count);
        cr_assert(memcmp(a->u.chunks.hashes, b->u.chunks.hashes, (size_t)a->u.chunks.count * BLOB_HASH_SIZE) == 0);
        break;
    case MSG_BYE:
    case MSG_TYPE_MAX_:
        break;
    }
}

static void free_decoded(struct proto_msg *m)
{
    if (m->type == MSG_JOB)
        proto_job_fini(&m->u.job);
}

/* Decodes a frame that must be rejected; returns the reason for further checks. */
static const char *expect_reject(const uint8_t *frame, size_t size)
{
    static char err[512];
    struct proto_msg m;
    err[0] = '\0';
    int rc = proto_decode(frame, size, &m, err, sizeof err);
    if (rc == 0)
        free_decoded(&m);
    cr_assert_eq(rc, -1, "frame of %zu bytes accepted", size);
    cr_assert(err[0] != '\0', "rejected without a reason");
    return err;
}

/* A little-endian frame builder for hand-made (malformed) frames. */
struct fb { uint8_t *d; size_t n, cap; };

static void fb_bytes(struct fb *b, const void *p, size_t n)
{
    if (b->n + n > b->cap) {
        b->cap = (b->n + n) * 2 + 64;
        b->d = realloc(b->d, b->cap);
        cr_assert_not_null(b->d);
    }
    if (n)
        memcpy(b->d + b->n, p, n);
    b->n += n;
}

static void fb_u(struct fb *b, uint64_t v, int bytes)
{
    for (int i = 0; i < bytes; i++) {
        uint8_t x = (uint8_t)(v >> (8 * i));
        fb_bytes(b, &x, 1);
    }
}

static void fb_header(struct fb *b, uint16_t type)
{
    b->n = 0;
    fb_u(b, PROTO_MAGIC, 4);
    fb_u(b, PROTO_VERSION, 2);
    fb_u(b, type, 2);
}

static void fb_fill(struct fb *b, uint8_t c, size_t n)
{
    for (size_t i = 0; i < n; i++)
        fb_bytes(b, &c, 1);
}

/* JOB fields up to (not including) num_assets, with the given settings. */
static void fb_job_prefix(struct fb *b, uint32_t width, uint32_t height, uint32_t spp, uint32_t tile)
{
    fb_header(b, MSG_JOB);
    fb_u(b, 1, 8);
    fb_fill(b, 0x5a, BLOB_HASH_SIZE); /* job_key */
    fb_u(b, 0, 4);
    fb_u(b, width, 4);
    fb_u(b, height, 4);
    fb_u(b, spp, 4);
    fb_u(b, 5, 4);
    fb_u(b, tile, 4);
    fb_u(b, 1234, 8);
    fb_u(b, 0, 4); /* sampler */
    fb_u(b, 0, 4); /* aovs */
    fb_u(b, 0, 4); /* filter: box */
    fb_u(b, 0, 4); /* filter_width (float bits) */
    fb_u(b, 0, 4); /* photon_maps */
    fb_u(b, 0, 4); /* passes */
    fb_u(b, 0, 4); /* embree_isa: avx2 */
    fb_u(b, 10, 2);
    fb_bytes(b, "scene.json", 10);
}

static void fb_asset(struct fb *b, const char *path, uint64_t size)
{
    fb_u(b, strlen(path), 2);
    fb_bytes(b, path, strlen(path));
    fb_fill(b, 0xab, BLOB_HASH_SIZE);
    fb_u(b, size, 8);
}

static void expect_accept(const struct fb *b)
{
    char err[512] = "";
    struct proto_msg m;
    cr_assert_eq(proto_decode(b->d, b->n, &m, err, sizeof err), 0, "rejected: %s", err);
    free_decoded(&m);
}

Test(proto, round_trip_every_type)
{
    struct proto_msg in[MSG_TYPE_MAX_];
    size_t n = make_samples(in);
    cr_assert_eq(n, MSG_TYPE_MAX_ - 1, "a sample for every type");
    struct proto_buf b = {0};
    for (size_t i = 0; i < n; i++) {
        cr_assert_eq(proto_encode(&in[i], &b), 0, "encode %s", proto_type_name(in[i].type));
        struct proto_msg out;
        char err[256] = "";
        cr_assert_eq(proto_decode(b.data, b.size, &out, err, sizeof err), 0, "%s: %s",
                     proto_type_name(in[i].type), err);
        assert_msg_eq(&in[i], &out);
        free_decoded(&out);
    }
    proto_buf_fini(&b);
}

Test(proto, payloads_point_into_the_frame)
{
    struct proto_msg in[MSG_TYPE_MAX_];
    make_samples(in);
    struct proto_buf b = {0};
    char err[256];
    struct proto_msg out;
    cr_assert_eq(proto_encode(&in[3], &b), 0);
    cr_assert_eq(proto_decode(b.data, b.size, &out, err, sizeof err), 0);
    cr_assert(out.u.blob_data.bytes >= b.data && out.u.blob_data.bytes + out.u.blob_data.length <= b.data + b.size);
    proto_buf_fini(&b);
}

Test(proto, header_layout_is_little_endian)
{
    struct proto_msg m = {.type = MSG_READY};
    m.u.ready.job_id = 0x0102030405060708ull;
    m.u.ready.credits = 0x0a0b0c0du;
    struct proto_buf b = {0};
    cr_assert_eq(proto_encode(&m, &b), 0);
    static const uint8_t want[] = {'B', 'R', 'U', 'M', PROTO_VERSION, 0, MSG_READY, 0,
                                   8, 7, 6, 5, 4, 3, 2, 1, 0x0d, 0x0c, 0x0b, 0x0a};
    cr_assert_eq(b.size, sizeof want);
    cr_assert(memcmp(b.data, want, sizeof want) == 0);
    /* The buffer is reset, not appended to, by the next encode. */
    struct proto_msg bye = {.type = MSG_BYE};
    cr_assert_eq(proto_encode(&bye, &b), 0);
    cr_assert_eq(b.size, 8);
    proto_buf_fini(&b);
}

Test(proto, double_travels_as_ieee_bits)
{
    struct proto_msg in[MSG_TYPE_MAX_];
    make_samples(in);
    struct proto_msg *r = &in[6];
    const double values[] = {0.0, -0.0, 5e-324, 1.7976931348623157e308, 1.0 / 3.0};
    struct proto_buf b = {0};
    for (size_t i = 0; i < sizeof values / sizeof values[0]; i++) {
        r->u.result.stats.sum_rel_stderr = values[i];
        cr_assert_eq(proto_encode(r, &b), 0);
        struct proto_msg out;
        char err[256];
        cr_assert_eq(proto_decode(b.data, b.size, &out, err, sizeof err), 0, "%s", err);
        assert_msg_eq(r, &out);
    }
    proto_buf_fini(&b);
}

Test(proto, every_truncation_rejected)
{
    struct proto_msg in[MSG_TYPE_MAX_];
    size_t n = make_samples(in);
    struct proto_buf b = {0};
    for (size_t i = 0; i < n; i++) {
        cr_assert_eq(proto_encode(&in[i], &b), 0);
        for (size_t len = 0; len < b.size; len++) {
            /* A copy of exactly len bytes, so ASan sees any read past the end. */
            uint8_t *copy = malloc(len ? len : 1);
            memcpy(copy, b.data, len);
            expect_reject(copy, len);
            free(copy);
        }
    }
    proto_buf_fini(&b);
}

Test(proto, trailing_byte_rejected)
{
    struct proto_msg in[MSG_TYPE_MAX_];
    size_t n = make_samples(in);
    struct proto_buf b = {0};
    for (size_t i = 0; i < n; i++) {
        cr_assert_eq(proto_encode(&in[i], &b), 0);
        uint8_t *copy = malloc(b.size + 1);
        memcpy(copy, b.data, b.size);
        copy[b.size] = 0;
        const char *err = expect_reject(copy, b.size + 1);
        cr_assert(strstr(err, "trailing"), "%s", err);
        free(copy);
    }
    proto_buf_fini(&b);
}

Test(proto, wrong_magic_and_version)
{
    struct proto_msg m = {.type = MSG_HEARTBEAT};
    struct proto_buf b = {0};
    cr_assert_eq(proto_encode(&m, &b), 0);
    b.data[0] ^= 0x20;
    const char *err = expect_reject(b.data, b.size);
    cr_assert(strstr(err, "magic"), "%s", err);
    b.data[0] ^= 0x20;
    b.data[4] = PROTO_VERSION + 1;
    err = expect_reject(b.data, b.size);
    char want_theirs[32], want_ours[48];
    snprintf(want_theirs, sizeof want_theirs, "version %d", PROTO_VERSION + 1);
    snprintf(want_ours, sizeof want_ours, "speaks version %d", PROTO_VERSION);
    cr_assert(strstr(err, want_theirs) && strstr(err, want_ours), "names both versions: %s", err);
    b.data[4] = 0;
    b.data[5] = 1;
    err = expect_reject(b.data, b.size);
    cr_assert(strstr(err, "256"), "%s", err);
    proto_buf_fini(&b);
}

Test(proto, unknown_type_rejected)
{
    const uint16_t types[] = {0, MSG_TYPE_MAX_, 200, 0xffff};
    struct fb f = {0};
    for (size_t i = 0; i < sizeof types / sizeof types[0]; i++) {
        fb_header(&f, types[i]);
        const char *err = expect_reject(f.d, f.n);
        cr_assert(strstr(err, "unknown message type"), "%s", err);
    }
    free(f.d);
}

Test(proto, type_names)
{
    cr_assert_str_eq(proto_type_name(MSG_HELLO), "HELLO");
    cr_assert_str_eq(proto_type_name(MSG_JOB), "JOB");
    cr_assert_str_eq(proto_type_name(MSG_BLOB_REQ), "BLOB_REQ");
    cr_assert_str_eq(proto_type_name(MSG_BLOB_DATA), "BLOB_DATA");
    cr_assert_str_eq(proto_type_name(MSG_READY), "READY");
    cr_assert_str_eq(proto_type_name(MSG_TILE), "TILE");
    cr_assert_str_eq(proto_type_name(MSG_RESULT), "RESULT");
    cr_assert_str_eq(proto_type_name(MSG_ERROR), "ERROR");
    cr_assert_str_eq(proto_type_name(MSG_HEARTBEAT), "HEARTBEAT");
    cr_assert_str_eq(proto_type_name(MSG_BYE), "BYE");
    cr_assert_str_eq(proto_type_name(MSG_ACK), "ACK");
    cr_assert_str_eq(proto_type_name(MSG_KEPT), "KEPT");
    cr_assert_str_eq(proto_type_name(MSG_CHUNKS_REQ), "CHUNKS_REQ");
    cr_assert_str_eq(proto_type_name(MSG_CHUNKS), "CHUNKS");
    cr_assert_str_eq(proto_type_name(MSG_TYPE_MAX_), "UNKNOWN");
    cr_assert_str_eq(proto_type_name((enum proto_type)0), "UNKNOWN");
}

Test(proto, string_limits)
{
    struct fb f = {0};
    /* 1023 bytes is the longest string that fits the fixed arrays with its NUL. */
    fb_header(&f, MSG_HELLO);
    fb_u(&f, 8, 4);
    fb_u(&f, 1, 4);
    fb_u(&f, PROTO_MAX_STRING - 1, 2);
    fb_fill(&f, 'h', PROTO_MAX_STRING - 1);
    expect_accept(&f);

    fb_header(&f, MSG_HELLO);
    fb_u(&f, 8, 4);
    fb_u(&f, 1, 4);
    fb_u(&f, PROTO_MAX_STRING, 2);
    fb_fill(&f, 'h', PROTO_MAX_STRING);
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "host") && strstr(err, "limit"), "%s", err);

    fb_header(&f, MSG_ERROR);
    fb_u(&f, 1, 8);
    fb_u(&f, 0xffff, 2);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "limit"), "checked before the bytes: %s", err);

    fb_header(&f, MSG_ERROR);
    fb_u(&f, 1, 8);
    fb_u(&f, 5, 2);
    fb_bytes(&f, "ab\0cd", 5);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "NUL"), "%s", err);
    free(f.d);

    /* Encode refuses a string that fills its array (no room for the NUL). */
    struct proto_msg m = {.type = MSG_ERROR};
    memset(m.u.error.text, 'x', sizeof m.u.error.text);
    struct proto_buf b = {0};
    cr_assert_eq(proto_encode(&m, &b), -1);
    m.u.error.text[PROTO_MAX_STRING - 1] = '\0';
    cr_assert_eq(proto_encode(&m, &b), 0);
    proto_buf_fini(&b);
}

/* A JOB naming an Embree instruction set that does not exist is refused both ways. */
Test(proto, job_embree_isa_checked)
{
    struct fb f = {0};
    fb_job_prefix(&f, 64, 64, 1, 16);
    f.d[f.n - 16] = EMBREE_ISA_COUNT_; /* embree_isa: before the path's length (2) and bytes (10) */
    fb_u(&f, 0, 4);
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "instruction set"), "%s", err);
    free(f.d);
    struct proto_msg m = {.type = MSG_JOB};
    m.u.job.width = m.u.job.height = m.u.job.spp = m.u.job.tile_size = 16;
    strcpy(m.u.job.scene_path, "scene.json");
    struct proto_buf b = {0};
    cr_assert_eq(proto_encode(&m, &b), 0);
    m.u.job.embree_isa = EMBREE_ISA_COUNT_;
    cr_assert_eq(proto_encode(&m, &b), -1);
    proto_buf_fini(&b);
}

Test(proto, job_asset_limits)
{
    struct fb f = {0};
    fb_job_prefix(&f, 64, 64, 1, 16);
    fb_u(&f, PROTO_MAX_ASSETS + 1, 4);
    for (int i = 0; i < PROTO_MAX_ASSETS + 1; i++)
        fb_asset(&f, "a", 1);
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "num_assets"), "%s", err);

    /* A huge count with no bytes behind it must fail before any allocation. */
    fb_job_prefix(&f, 64, 64, 1, 16);
    fb_u(&f, 0xffffffffu, 4);
    expect_reject(f.d, f.n);
    fb_job_prefix(&f, 64, 64, 1, 16);
    fb_u(&f, PROTO_MAX_ASSETS, 4);
    expect_reject(f.d, f.n);

    fb_job_prefix(&f, 64, 64, 1, 16);
    fb_u(&f, 2, 4);
    fb_asset(&f, "scene.json", 10);
    fb_asset(&f, "", 10);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "empty"), "%s", err);

    fb_job_prefix(&f, 64, 64, 1, 16);
    fb_u(&f, 1, 4);
    fb_asset(&f, "big.vdb", BLOB_MAX_SIZE + 1);
    expect_reject(f.d, f.n);

    fb_job_prefix(&f, 64, 64, 1, 16);
    fb_u(&f, 0, 4);
    expect_accept(&f);
    free(f.d);
}

Test(proto, job_with_max_assets_round_trips)
{
    struct proto_asset *assets = calloc(PROTO_MAX_ASSETS, sizeof *assets);
    for (int i = 0; i < PROTO_MAX_ASSETS; i++) {
        snprintf(assets[i].path, sizeof assets[i].path, "tex/%04d.png", i);
        assets[i].hash = make_hash((uint8_t)i);
        assets[i].size = (uint64_t)i;
    }
    struct proto_msg m = {.type = MSG_JOB};
    m.u.job.width = m.u.job.height = m.u.job.spp = m.u.job.tile_size = 1;
    m.u.job.num_assets = PROTO_MAX_ASSETS;
    m.u.job.assets = assets;
    struct proto_buf b = {0};
    cr_assert_eq(proto_encode(&m, &b), 0);
    struct proto_msg out;
    char err[256];
    cr_assert_eq(proto_decode(b.data, b.size, &out, err, sizeof err), 0, "%s", err);
    assert_msg_eq(&m, &out);
    proto_job_fini(&out.u.job);
    cr_assert_null(out.u.job.assets);

    m.u.job.num_assets = PROTO_MAX_ASSETS + 1;
    cr_assert_eq(proto_encode(&m, &b), -1);
    m.u.job.num_assets = 2;
    assets[1].path[0] = '\0';
    cr_assert_eq(proto_encode(&m, &b), -1, "encode refuses what decode refuses");
    proto_buf_fini(&b);
    free(assets);
}

Test(proto, job_zero_settings_rejected)
{
    const uint32_t bad[4][4] = {{0, 8, 1, 4}, {8, 0, 1, 4}, {8, 8, 0, 4}, {8, 8, 1, 0}};
    struct fb f = {0};
    struct proto_msg in[MSG_TYPE_MAX_];
    make_samples(in);
    struct proto_buf b = {0};
    for (int i = 0; i < 4; i++) {
        fb_job_prefix(&f, bad[i][0], bad[i][1], bad[i][2], bad[i][3]);
        fb_u(&f, 0, 4);
        expect_reject(f.d, f.n);
        struct msg_job *j = &in[1].u.job;
        j->width = bad[i][0];
        j->height = bad[i][1];
        j->spp = bad[i][2];
        j->tile_size = bad[i][3];
        cr_assert_eq(proto_encode(&in[1], &b), -1);
    }
    proto_buf_fini(&b);
    free(f.d);
}

Test(proto, blob_lengths_limited)
{
    struct fb f = {0};
    fb_header(&f, MSG_BLOB_REQ);
    fb_fill(&f, 1, BLOB_HASH_SIZE);
    fb_u(&f, 0, 8);
    fb_u(&f, BLOB_CHUNK_SIZE + 1, 4);
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "length"), "%s", err);

    /* A full chunk is fine, one byte more is not, even with the bytes present. */
    fb_header(&f, MSG_BLOB_DATA);
    fb_fill(&f, 1, BLOB_HASH_SIZE);
    fb_u(&f, 0, 8);
    fb_u(&f, 10ull * BLOB_CHUNK_SIZE, 8);
    fb_u(&f, BLOB_CHUNK_SIZE, 4);
    fb_fill(&f, 7, BLOB_CHUNK_SIZE);
    expect_accept(&f);

    fb_header(&f, MSG_BLOB_DATA);
    fb_fill(&f, 1, BLOB_HASH_SIZE);
    fb_u(&f, 0, 8);
    fb_u(&f, 10ull * BLOB_CHUNK_SIZE, 8);
    fb_u(&f, BLOB_CHUNK_SIZE + 1, 4);
    fb_fill(&f, 7, BLOB_CHUNK_SIZE + 1);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "limit"), "%s", err);

    /* Bytes beyond the announced blob, and a blob over the size limit. */
    fb_header(&f, MSG_BLOB_DATA);
    fb_fill(&f, 1, BLOB_HASH_SIZE);
    fb_u(&f, 8, 8);
    fb_u(&f, 10, 8);
    fb_u(&f, 4, 4);
    fb_fill(&f, 7, 4);
    expect_reject(f.d, f.n);
    fb_header(&f, MSG_BLOB_DATA);
    fb_fill(&f, 1, BLOB_HASH_SIZE);
    fb_u(&f, 0, 8);
    fb_u(&f, BLOB_MAX_SIZE + 1, 8);
    fb_u(&f, 0, 4);
    expect_reject(f.d, f.n);
    free(f.d);
}

Test(proto, result_limits)
{
    struct fb f = {0};
    fb_header(&f, MSG_RESULT);
    fb_fill(&f, 0, 8 + 4 * 3 + 8 * 4 + 8 + 4);
    fb_u(&f, PROTO_MAX_CHUNK + 1, 4);
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "chunk") && strstr(err, "limit"), "checked before the bytes: %s", err);
    free(f.d);

    struct proto_msg in[MSG_TYPE_MAX_];
    make_samples(in);
    struct proto_buf b = {0};
    struct proto_msg *r = &in[6];
    r->u.result.chunk_size = PROTO_MAX_CHUNK + 1;
    cr_assert_eq(proto_encode(r, &b), -1);
    r->u.result.chunk_size = sizeof k_chunk_bytes;

    const double bad[] = {NAN, INFINITY, -INFINITY};
    for (int i = 0; i < 3; i++) {
        r->u.result.stats.sum_rel_stderr = 1.0;
        cr_assert_eq(proto_encode(r, &b), 0);
        /* Patch the double in place: the encoder itself refuses non-finite values. */
        uint64_t bits;
        memcpy(&bits, &bad[i], sizeof bits);
        size_t at = 8 + 8 + 4 * 3 + 8 * 4;
        for (int k = 0; k < 8; k++)
            b.data[at + (size_t)k] = (uint8_t)(bits >> (8 * k));
        err = expect_reject(b.data, b.size);
        cr_assert(strstr(err, "finite"), "%s", err);
        r->u.result.stats.sum_rel_stderr = bad[i];
        cr_assert_eq(proto_encode(r, &b), -1);
    }
    proto_buf_fini(&b);
}

Test(proto, ack_and_kept_limits)
{
    struct fb f = {0};
    fb_header(&f, MSG_ACK);
    fb_u(&f, 1, 8);
    fb_u(&f, 0, 4);
    fb_u(&f, PROTO_MAX_ACK_TILES + 1, 4);
    fb_fill(&f, 0, 4 * (PROTO_MAX_ACK_TILES + 1));
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "count") && strstr(err, "limit"), "%s", err);
    /* A count the frame does not hold is a truncation. */
    fb_header(&f, MSG_ACK);
    fb_u(&f, 1, 8);
    fb_u(&f, 0, 4);
    fb_u(&f, 3, 4);
    fb_u(&f, 7, 4);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "truncated"), "%s", err);
    fb_header(&f, MSG_KEPT);
    fb_fill(&f, 0, 8 + BLOB_HASH_SIZE + 4 * 2 + BLOB_HASH_SIZE + 8 * 4 + 8 + 4); /* job, key, frame, tile, tag, stats */
    fb_u(&f, PROTO_MAX_CHUNK + 1, 4);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "chunk") && strstr(err, "limit"), "%s", err);
    free(f.d);

    struct proto_msg m = {.type = MSG_ACK};
    struct proto_buf b = {0};
    m.u.ack.count = PROTO_MAX_ACK_TILES + 1;
    cr_assert_eq(proto_encode(&m, &b), -1);
    m.u.ack.count = PROTO_MAX_ACK_TILES;
    cr_assert_eq(proto_encode(&m, &b), 0);
    cr_assert_eq(b.size, 8 + 8 + 4 + 4 + 4 * PROTO_MAX_ACK_TILES);
    proto_buf_fini(&b);
}

/* MAP: a pass, a published count or a size beyond the limits never reaches the worker;
 * JOB: photon_maps must be at most PROTO_MAX_PASSES and divide spp. */
Test(proto, map_and_passes_limits)
{
    struct fb f = {0};
    fb_header(&f, MSG_MAP);
    fb_u(&f, 1, 8);
    fb_u(&f, PROTO_MAX_PASSES, 4);
    fb_u(&f, PROTO_MAX_PASSES, 4);
    fb_fill(&f, 0, BLOB_HASH_SIZE);
    fb_u(&f, 10, 8);
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "pass") && strstr(err, "limit"), "%s", err);
    fb_header(&f, MSG_MAP);
    fb_u(&f, 1, 8);
    fb_u(&f, 3, 4);
    fb_u(&f, 4, 4);
    fb_fill(&f, 0, BLOB_HASH_SIZE);
    fb_u(&f, BLOB_MAX_SIZE + 1, 8);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "size") && strstr(err, "limit"), "%s", err);
    const uint32_t bad_published[] = {0, 3, PROTO_MAX_PASSES + 1}; /* not past pass 3, or past the limit */
    for (int i = 0; i < 3; i++) {
        fb_header(&f, MSG_MAP);
        fb_u(&f, 1, 8);
        fb_u(&f, 3, 4);
        fb_u(&f, bad_published[i], 4);
        fb_fill(&f, 0, BLOB_HASH_SIZE);
        fb_u(&f, 10, 8);
        err = expect_reject(f.d, f.n);
        cr_assert(strstr(err, "published"), "%s", err);
    }
    free(f.d);
    struct proto_msg m = {.type = MSG_JOB};
    struct proto_buf b = {0};
    m.u.job.width = m.u.job.height = m.u.job.tile_size = 8;
    m.u.job.spp = 12;
    m.u.job.photon_maps = m.u.job.passes = 8;
    cr_assert_eq(proto_encode(&m, &b), -1, "spp not a multiple of the passes");
    m.u.job.photon_maps = m.u.job.passes = 4;
    cr_assert_eq(proto_encode(&m, &b), 0);
    m.u.job.photon_maps = 0; /* passes without photon maps */
    cr_assert_eq(proto_encode(&m, &b), 0);
    m.u.job.passes = 5;
    cr_assert_eq(proto_encode(&m, &b), -1, "passes without maps must divide spp too");
    m.u.job.photon_maps = 2;
    m.u.job.passes = 4;
    cr_assert_eq(proto_encode(&m, &b), -1, "photon maps and passes disagree");
    m.u.job.spp = 2048;
    m.u.job.photon_maps = m.u.job.passes = PROTO_MAX_PASSES * 2;
    cr_assert_eq(proto_encode(&m, &b), -1, "too many passes");
    proto_buf_fini(&b);
}

Test(proto, tile_pass_and_mask_limits)
{
    struct fb f = {0};
    fb_header(&f, MSG_TILE);
    fb_u(&f, 1, 8);
    fb_u(&f, 0, 4);
    fb_u(&f, 3, 4);
    fb_u(&f, 1, 4);
    fb_u(&f, PROTO_MAX_PASSES, 4);
    fb_u(&f, 1, 8);
    fb_fill(&f, 0, BLOB_HASH_SIZE);
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "pass"), "%s", err);
    fb_header(&f, MSG_TILE);
    fb_u(&f, 1, 8);
    fb_u(&f, 0, 4);
    fb_u(&f, 3, 4);
    fb_u(&f, 1, 4);
    fb_u(&f, 2, 4);
    fb_u(&f, 0, 8);
    fb_fill(&f, 0, BLOB_HASH_SIZE);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "block"), "%s", err);
    free(f.d);
}

/* CHUNKS: the count must be the blob's chunk count, the size within BLOB_MAX_SIZE (checked
 * before the count is used as a length), unknown flags refused. */
static void fb_chunks(struct fb *f, uint64_t size, uint32_t flags, uint32_t count, size_t hash_bytes)
{
    fb_header(f, MSG_CHUNKS);
    fb_fill(f, 5, BLOB_HASH_SIZE);
    fb_u(f, size, 8);
    fb_u(f, flags, 4);
    fb_u(f, 5556, 2);
    fb_u(f, count, 4);
    fb_fill(f, 9, hash_bytes);
}

Test(proto, chunks_limits)
{
    struct fb f = {0};
    fb_chunks(&f, BLOB_CHUNK_SIZE + 1, PROTO_CHUNKS_BCAST, 2, 2 * BLOB_HASH_SIZE);
    expect_accept(&f);
    fb_chunks(&f, 0, 0, 0, 0);
    expect_accept(&f);
    fb_chunks(&f, BLOB_CHUNK_SIZE + 1, 0, 1, BLOB_HASH_SIZE);
    const char *err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "chunk hashes"), "%s", err);
    fb_chunks(&f, BLOB_CHUNK_SIZE, 0, 0xffffffffu, 0);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "chunk hashes"), "a huge count is refused before it is read: %s", err);
    fb_chunks(&f, BLOB_MAX_SIZE + 1, 0, (uint32_t)(BLOB_MAX_SIZE / BLOB_CHUNK_SIZE + 1), 0);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "size") && strstr(err, "limit"), "%s", err);
    fb_chunks(&f, 10, 2, 1, BLOB_HASH_SIZE);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "flags"), "%s", err);
    fb_chunks(&f, 3 * BLOB_CHUNK_SIZE, 0, 3, 2 * BLOB_HASH_SIZE);
    err = expect_reject(f.d, f.n);
    cr_assert(strstr(err, "truncated"), "fewer hashes than the count: %s", err);
    free(f.d);
    struct proto_msg m = {.type = MSG_CHUNKS};
    struct proto_buf b = {0};
    m.u.chunks.size = 10;
    m.u.chunks.count = 2;
    m.u.chunks.hashes = k_chunk_hashes;
    cr_assert_eq(proto_encode(&m, &b), -1, "a count that does not fit the size");
    m.u.chunks.count = 1;
    m.u.chunks.hashes = NULL;
    cr_assert_eq(proto_encode(&m, &b), -1, "no hashes");
    proto_buf_fini(&b);
}

/* ---- proto_fetch: the chunk list, the broadcast, point to point for the rest ---- */

struct fetch_blob { uint8_t *data; uint64_t size; struct blob_hash hash, *chunks; uint64_t count; };

static struct fetch_blob fetch_blob_make(uint64_t size)
{
    struct fetch_blob fb = {.size = size};
    fb.data = malloc(size);
    for (uint64_t i = 0; i < size; i++)
        fb.data[i] = (uint8_t)(i * 2654435761u >> 13);
    blob_chunk_hashes(fb.data, size, &fb.chunks, &fb.count);
    blob_name_of_chunks(fb.chunks, fb.count, &fb.hash);
    return fb;
}

static struct msg_chunks fetch_chunks_msg(const struct fetch_blob *fb, uint32_t flags)
{
    struct msg_chunks c = {.hash = fb->hash, .size = fb->size, .flags = flags, .count = (uint32_t)fb->count};
    c.hashes = fb->chunks[0].bytes;
    return c;
}

static struct msg_blob_data fetch_chunk(const struct fetch_blob *fb, uint64_t i)
{
    uint64_t off = i * BLOB_CHUNK_SIZE, left = fb->size - off;
    struct msg_blob_data d = {.hash = fb->hash, .offset = off, .total_size = fb->size, .bytes = fb->data + off};
    d.length = (uint32_t)(left < BLOB_CHUNK_SIZE ? left : BLOB_CHUNK_SIZE);
    return d;
}

/* A broadcast message is kept only as a BLOB_DATA of the hash its topic names. */
Test(proto, fetch_decode_bcast_checks_the_topic)
{
    struct fetch_blob fb = fetch_blob_make(BLOB_CHUNK_SIZE + 5);
    struct proto_msg m = {.type = MSG_BLOB_DATA}, out;
    m.u.blob_data = fetch_chunk(&fb, 1);
    struct proto_buf b = {0};
    cr_assert_eq(proto_encode(&m, &b), 0);
    char err[256];
    cr_assert_eq(proto_fetch_decode_bcast(fb.hash.bytes, BLOB_HASH_SIZE, b.data, b.size, &out, err, sizeof err), 0,
                 "%s", err);
    cr_assert_eq(out.u.blob_data.offset, BLOB_CHUNK_SIZE);
    cr_assert_eq(out.u.blob_data.length, 5);
    uint8_t other[BLOB_HASH_SIZE];
    memcpy(other, fb.hash.bytes, sizeof other);
    other[0] ^= 1;
    cr_assert_eq(proto_fetch_decode_bcast(other, BLOB_HASH_SIZE, b.data, b.size, &out, err, sizeof err), -1);
    cr_assert(strstr(err, "topic"), "%s", err);
    cr_assert_eq(proto_fetch_decode_bcast(fb.hash.bytes, BLOB_HASH_SIZE - 1, b.data, b.size, &out, err, sizeof err), -1);
    cr_assert_eq(proto_fetch_decode_bcast(fb.hash.bytes, BLOB_HASH_SIZE, b.data, b.size - 1, &out, err, sizeof err), -1,
                 "a truncated message");
    cr_assert(err[0]);
    struct proto_msg hb = {.type = MSG_HEARTBEAT};
    cr_assert_eq(proto_encode(&hb, &b), 0);
    cr_assert_eq(proto_fetch_decode_bcast(fb.hash.bytes, BLOB_HASH_SIZE, b.data, b.size, &out, err, sizeof err), -1,
                 "not a BLOB_DATA");
    proto_buf_fini(&b);
    free(fb.data);
    free(fb.chunks);
}

Test(proto, fetch_broadcast_then_point_to_point)
{
    struct fetch_blob fb = fetch_blob_make(5 * BLOB_CHUNK_SIZE + 77); /* 6 chunks */
    struct proto_fetch f;
    struct proto_msg req;
    char err[256];
    cr_assert_eq(proto_fetch_start(&f, &fb.hash, fb.size, &req, err, sizeof err), 0);
    cr_assert_eq(req.type, MSG_CHUNKS_REQ);
    cr_assert_eq(proto_fetch_next_req(&f, 0, &req), 0, "nothing before the list");
    struct msg_chunks c = fetch_chunks_msg(&fb, PROTO_CHUNKS_BCAST);
    cr_assert_eq(proto_fetch_on_chunks(&f, &c, 1000, err, sizeof err), 1, "subscribe");
    /* the broadcast brings chunks 0, 2 (twice) and a corrupted 3 */
    struct msg_blob_data d = fetch_chunk(&fb, 0);
    cr_assert_eq(proto_fetch_on_data(&f, &d, 1, 1010, err, sizeof err), 0);
    d = fetch_chunk(&fb, 2);
    cr_assert_eq(proto_fetch_on_data(&f, &d, 1, 1020, err, sizeof err), 0);
    cr_assert_eq(proto_fetch_on_data(&f, &d, 1, 1030, err, sizeof err), 0, "a duplicate is harmless");
    uint8_t bad[BLOB_CHUNK_SIZE];
    d = fetch_chunk(&fb, 3);
    memcpy(bad, d.bytes, d.length);
    bad[100] ^= 1;
    d.bytes = bad;
    cr_assert_eq(proto_fetch_on_data(&f, &d, 1, 1040, err, sizeof err), -1, "a chunk off its hash is refused");
    cr_assert(strstr(err, "hash"), "%s", err);
    cr_assert_eq(f.recv.chunks_have, 2);
    cr_assert_eq(f.recv.chunks_bad, 1);
    /* quiet for less than PROTO_BCAST_IDLE_MS: no request; the socket still has data: none either */
    cr_assert_eq(proto_fetch_next_req(&f, 1040 + PROTO_BCAST_IDLE_MS - 1, &req), 0, "the last chunk came at 1040");
    proto_fetch_bcast_alive(&f, 1040 + PROTO_BCAST_IDLE_MS - 1);
    cr_assert_eq(proto_fetch_next_req(&f, 1040 + PROTO_BCAST_IDLE_MS + 10, &req), 0);
    /* then quiet: the missing chunks 1, 3, 4, 5 point to point, each once */
    uint64_t t = 1040 + 2 * PROTO_BCAST_IDLE_MS, want[] = {1, 3, 4, 5};
    for (int i = 0; i < 4; i++) {
        cr_assert_eq(proto_fetch_next_req(&f, t, &req), 1);
        cr_assert_eq(req.type, MSG_BLOB_REQ);
        cr_assert_eq(req.u.blob_req.offset, want[i] * BLOB_CHUNK_SIZE);
        cr_assert_eq(req.u.blob_req.length, want[i] == 5 ? 77u : BLOB_CHUNK_SIZE);
    }
    cr_assert_eq(proto_fetch_next_req(&f, t, &req), 0, "all asked for, answers pending");
    cr_assert_eq(f.in_flight, 4);
    /* answers: 1 and 4 good, 3 bad again, 5 good; then 3 is asked for again */
    uint64_t answer[] = {1, 4, 5};
    for (int i = 0; i < 3; i++) {
        d = fetch_chunk(&fb, answer[i]);
        cr_assert_eq(proto_fetch_on_data(&f, &d, 0, t, err, sizeof err), 0);
    }
    d = fetch_chunk(&fb, 3);
    d.bytes = bad;
    cr_assert_eq(proto_fetch_on_data(&f, &d, 0, t, err, sizeof err), -1);
    cr_assert_eq(f.in_flight, 0);
    cr_assert_eq(proto_fetch_next_req(&f, t, &req), 1);
    cr_assert_eq(req.u.blob_req.offset, 3ull * BLOB_CHUNK_SIZE);
    d = fetch_chunk(&fb, 3);
    cr_assert_eq(proto_fetch_on_data(&f, &d, 0, t, err, sizeof err), 0);
    cr_assert(blob_recv_complete(&f.recv));
    cr_assert_eq(f.chunks_bcast, 2);
    cr_assert_eq(f.chunks_p2p, 4);
    cr_assert_eq(proto_fetch_next_req(&f, t, &req), 0);
    uint8_t *data;
    cr_assert_eq(blob_recv_finish(&f.recv, &data, err, sizeof err), 0, "%s", err);
    cr_assert(memcmp(data, fb.data, fb.size) == 0);
    free(data);
    proto_fetch_fini(&f);
    cr_assert(blob_hash_equal(&f.recv.hash, &fb.hash), "the hash stays for look-ups after fini");
    free(fb.data);
    free(fb.chunks);
}

/* Requests whose answers never come (a connection libzmq made again, a full queue at the
 * master) are given up after PROTO_FETCH_STALL_MS with nothing heard, and the missing
 * chunks asked for again, the chunk list too; an answer in time keeps the window waiting. */
Test(proto, fetch_asks_again_after_a_stall)
{
    struct fetch_blob fb = fetch_blob_make(3 * BLOB_CHUNK_SIZE + 9); /* 4 chunks */
    struct proto_fetch f;
    struct proto_msg req;
    char err[256];
    cr_assert_eq(proto_fetch_start(&f, &fb.hash, fb.size, &req, err, sizeof err), 0);
    cr_assert_eq(proto_fetch_list_due(&f, 0), 1, "the list is asked for first");
    proto_fetch_list_sent(&f, 100);
    cr_assert_eq(proto_fetch_list_due(&f, 100 + PROTO_FETCH_STALL_MS - 1), 0, "its answer may still come");
    cr_assert_eq(proto_fetch_list_due(&f, 100 + PROTO_FETCH_STALL_MS), 1, "the list's request was lost");
    cr_assert_eq(f.stalls, 1);
    uint64_t t = 200 + PROTO_FETCH_STALL_MS;
    proto_fetch_list_sent(&f, t);
    struct msg_chunks c = fetch_chunks_msg(&fb, 0);
    cr_assert_eq(proto_fetch_on_chunks(&f, &c, t, err, sizeof err), 0);
    cr_assert_eq(proto_fetch_list_due(&f, t + 10 * PROTO_FETCH_STALL_MS), 0, "the list is in");
    for (uint64_t i = 0; i < 4; i++) {
        cr_assert_eq(proto_fetch_next_req(&f, t, &req), 1);
        cr_assert_eq(req.u.blob_req.offset, i * BLOB_CHUNK_SIZE);
    }
    /* chunk 2's answer comes a while later; nothing else does */
    struct msg_blob_data d = fetch_chunk(&fb, 2);
    uint64_t t2 = t + PROTO_FETCH_STALL_MS / 2;
    cr_assert_eq(proto_fetch_on_data(&f, &d, 0, t2, err, sizeof err), 0);
    cr_assert_eq(proto_fetch_expire(&f, t + PROTO_FETCH_STALL_MS), 0, "an answer came since");
    cr_assert_eq(proto_fetch_next_req(&f, t2 + PROTO_FETCH_STALL_MS - 1, &req), 0, "three still in flight");
    cr_assert_eq(f.in_flight, 3);
    /* then the three are given up and asked for again, each once */
    uint64_t t3 = t2 + PROTO_FETCH_STALL_MS, want[] = {0, 1, 3};
    for (int i = 0; i < 3; i++) {
        cr_assert_eq(proto_fetch_next_req(&f, t3, &req), 1);
        cr_assert_eq(req.u.blob_req.offset, want[i] * BLOB_CHUNK_SIZE);
    }
    cr_assert_eq(proto_fetch_next_req(&f, t3, &req), 0);
    cr_assert_eq(f.stalls, 2);
    cr_assert_eq(f.rounds, 0, "a stall is not a bad chunk: the fetch does not give up for it");
    for (int i = 0; i < 3; i++) {
        d = fetch_chunk(&fb, want[i]);
        cr_assert_eq(proto_fetch_on_data(&f, &d, 0, t3, err, sizeof err), 0);
    }
    d = fetch_chunk(&fb, 0); /* a late answer to a request given up: a harmless duplicate */
    cr_assert_eq(proto_fetch_on_data(&f, &d, 0, t3, err, sizeof err), 0);
    cr_assert(blob_recv_complete(&f.recv));
    cr_assert_eq(proto_fetch_expire(&f, t3 + 10 * PROTO_FETCH_STALL_MS), 0, "nothing is in flight");
    uint8_t *data;
    cr_assert_eq(blob_recv_finish(&f.recv, &data, err, sizeof err), 0, "%s", err);
    cr_assert(memcmp(data, fb.data, fb.size) == 0);
    free(data);
    proto_fetch_fini(&f);
    free(fb.data);
    free(fb.chunks);
}

Test(proto, fetch_without_broadcast_and_giving_up)
{
    struct fetch_blob fb = fetch_blob_make(BLOB_CHUNK_SIZE + 5); /* 2 chunks */
    struct proto_fetch f;
    struct proto_msg req;
    char err[256];
    cr_assert_eq(proto_fetch_start(&f, &fb.hash, fb.size, &req, err, sizeof err), 0);
    struct msg_chunks c = fetch_chunks_msg(&fb, 0);
    c.count = 1;
    cr_assert_eq(proto_fetch_on_chunks(&f, &c, 0, err, sizeof err), -1, "a list that does not fit the blob");
    cr_assert_eq(f.phase, FETCH_P2P);
    proto_fetch_fini(&f);
    cr_assert_eq(proto_fetch_start(&f, &fb.hash, fb.size, &req, err, sizeof err), 0);
    c = fetch_chunks_msg(&fb, 0);
    cr_assert_eq(proto_fetch_on_chunks(&f, &c, 0, err, sizeof err), 0, "no broadcast: point to point at once");
    /* a master that answers chunk 1 wrongly every time: the fetch gives up */
    int rc = 0, rounds = 0;
    uint8_t bad[8] = {0};
    while ((rc = proto_fetch_next_req(&f, 0, &req)) > 0 && rounds < 100) {
        struct msg_blob_data d = fetch_chunk(&fb, req.u.blob_req.offset / BLOB_CHUNK_SIZE);
        if (d.offset)
            d.bytes = bad;
        proto_fetch_on_data(&f, &d, 0, 0, err, sizeof err);
        rounds++;
    }
    cr_assert_eq(rc, -1, "gives up");
    cr_assert_eq(rounds, PROTO_FETCH_MAX_ROUNDS + 1, "chunks 0 and 1, then chunk 1 again in each later round: %d",
                 rounds);
    struct msg_blob_data d = fetch_chunk(&fb, 0);
    d.total_size = 1;
    cr_assert_eq(proto_fetch_on_data(&f, &d, 0, 0, err, sizeof err), -1, "another size");
    proto_fetch_fini(&f);
    free(fb.data);
    free(fb.chunks);
}

Test(proto, oversized_frame_rejected)
{
    /* calloc'd pages are not touched, so this costs no real memory. */
    size_t size = (size_t)PROTO_MAX_MESSAGE + 1;
    uint8_t *big = calloc(size, 1);
    cr_assert_not_null(big);
    static const uint8_t hdr[8] = {'B', 'R', 'U', 'M', PROTO_VERSION, 0, MSG_BYE, 0};
    memcpy(big, hdr, sizeof hdr);
    const char *err = expect_reject(big, size);
    cr_assert(strstr(err, "limit"), "%s", err);
    free(big);
}

/* xorshift64*: deterministic, so a failure reproduces. */
static uint64_t rnd(uint64_t *s)
{
    *s ^= *s >> 12;
    *s ^= *s << 25;
    *s ^= *s >> 27;
    return *s * 0x2545f4914f6cdd1dull;
}

/* A frame that decodes must re-encode to the same bytes: the format has one encoding. */
static void decode_reencode(const uint8_t *frame, size_t size, struct proto_buf *b2)
{
    struct proto_msg m;
    char err[512];
    if (proto_decode(frame, size, &m, err, sizeof err) != 0)
        return;
    cr_assert_eq(proto_encode(&m, b2), 0, "a decoded %s must encode", proto_type_name(m.type));
    cr_assert_eq(b2->size, size);
    cr_assert(memcmp(b2->data, frame, size) == 0);
    free_decoded(&m);
}

Test(proto, random_bit_flips_never_crash, .timeout = 60)
{
    struct proto_msg in[MSG_TYPE_MAX_];
    size_t n = make_samples(in);
    struct proto_buf b = {0}, b2 = {0};
    uint64_t seed = 0x9e3779b97f4a7c15ull;
    int accepted = 0, total = 0;
    for (size_t i = 0; i < n; i++) {
        cr_assert_eq(proto_encode(&in[i], &b), 0);
        uint8_t *copy = malloc(b.size);
        for (int iter = 0; iter < 3000; iter++) {
            memcpy(copy, b.data, b.size);
            int flips = 1 + (int)(rnd(&seed) % 4);
            for (int k = 0; k < flips; k++) {
                /* Bias towards the header and length fields near the start. */
                size_t limit = (rnd(&seed) & 1) ? b.size : (b.size < 24 ? b.size : 24);
                size_t at = (size_t)(rnd(&seed) % limit);
                copy[at] ^= (uint8_t)(1u << (rnd(&seed) % 8));
            }
            size_t len = (rnd(&seed) % 8 == 0) ? (size_t)(rnd(&seed) % (b.size + 1)) : b.size;
            struct proto_msg m;
            char err[512];
            if (proto_decode(copy, len, &m, err, sizeof err) == 0) {
                accepted++;
                free_decoded(&m);
                decode_reencode(copy, len, &b2);
            }
            total++;
        }
        free(copy);
    }
    /* Most single flips land in payload bytes and still decode; both paths are exercised. */
    cr_assert(accepted > 0 && accepted < total, "accepted %d of %d", accepted, total);
    proto_buf_fini(&b);
    proto_buf_fini(&b2);
}

Test(proto, random_bodies_never_crash, .timeout = 60)
{
    uint64_t seed = 12345;
    struct proto_buf b2 = {0};
    uint8_t buf[256];
    for (int iter = 0; iter < 50000; iter++) {
        size_t len = 8 + (size_t)(rnd(&seed) % (sizeof buf - 8));
        for (size_t k = 0; k < len; k++)
            buf[k] = (uint8_t)rnd(&seed);
        /* A valid header so the bodies, not the magic check, get exercised; small
         * counts and lengths so that some frames are accepted. */
        buf[0] = 'B', buf[1] = 'R', buf[2] = 'U', buf[3] = 'M', buf[4] = 1, buf[5] = 0;
        buf[6] = (uint8_t)(1 + rnd(&seed) % 10), buf[7] = 0;
        uint8_t *copy = malloc(len);
        memcpy(copy, buf, len);
        decode_reencode(copy, len, &b2);
        free(copy);
    }
    proto_buf_fini(&b2);
}

Test(proto, failed_decode_leaves_nothing_to_free)
{
    struct proto_msg in[MSG_TYPE_MAX_];
    make_samples(in);
    struct proto_buf b = {0};
    cr_assert_eq(proto_encode(&in[1], &b), 0);
    struct proto_msg out;
    char err[256];
    /* Cut inside the last asset: the assets array was allocated and must be released. */
    cr_assert_eq(proto_decode(b.data, b.size - 3, &out, err, sizeof err), -1);
    cr_assert_null(out.u.job.assets);
    cr_assert_eq(out.u.job.num_assets, 0);
    proto_buf_fini(&b);
}
