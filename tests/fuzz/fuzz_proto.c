/* libFuzzer target for the wire decoder (common/wire/proto.c): arbitrary bytes must never crash
 * or read out of bounds, and whatever decodes must re-encode to the very same bytes and
 * decode again to equal fields (the format has exactly one encoding per message).
 * Built and run by tests/fuzz/run.sh; by hand: see the clang line in that script. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "wire/proto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int hash_eq(const struct blob_hash *a, const struct blob_hash *b)
{
    return memcmp(a->bytes, b->bytes, BLOB_HASH_SIZE) == 0;
}

static int bytes_eq(const uint8_t *a, const uint8_t *b, uint32_t n)
{
    return n == 0 || memcmp(a, b, n) == 0;
}

static int msg_eq(const struct proto_msg *a, const struct proto_msg *b)
{
    if (a->type != b->type)
        return 0;
    switch (a->type) {
    case MSG_HELLO:
        return a->u.hello.threads == b->u.hello.threads && a->u.hello.pid == b->u.hello.pid &&
               strcmp(a->u.hello.host, b->u.hello.host) == 0;
    case MSG_JOB: {
        const struct msg_job *x = &a->u.job, *y = &b->u.job;
        if (x->job_id != y->job_id || !hash_eq(&x->job_key, &y->job_key) || x->frame != y->frame || x->width != y->width ||
            x->height != y->height || x->spp != y->spp || x->max_depth != y->max_depth ||
            x->tile_size != y->tile_size || x->seed != y->seed || x->photon_maps != y->photon_maps || x->passes != y->passes ||
            strcmp(x->scene_path, y->scene_path) != 0 || x->num_assets != y->num_assets)
            return 0;
        for (uint32_t i = 0; i < x->num_assets; i++)
            if (strcmp(x->assets[i].path, y->assets[i].path) != 0 ||
                !hash_eq(&x->assets[i].hash, &y->assets[i].hash) || x->assets[i].size != y->assets[i].size)
                return 0;
        return 1;
    }
    case MSG_BLOB_REQ:
        return hash_eq(&a->u.blob_req.hash, &b->u.blob_req.hash) &&
               a->u.blob_req.offset == b->u.blob_req.offset && a->u.blob_req.length == b->u.blob_req.length;
    case MSG_BLOB_DATA:
        return hash_eq(&a->u.blob_data.hash, &b->u.blob_data.hash) &&
               a->u.blob_data.offset == b->u.blob_data.offset &&
               a->u.blob_data.total_size == b->u.blob_data.total_size &&
               a->u.blob_data.length == b->u.blob_data.length &&
               bytes_eq(a->u.blob_data.bytes, b->u.blob_data.bytes, a->u.blob_data.length);
    case MSG_READY:
        return a->u.ready.job_id == b->u.ready.job_id && a->u.ready.credits == b->u.ready.credits;
    case MSG_TILE:
        return a->u.tile.job_id == b->u.tile.job_id && a->u.tile.frame == b->u.tile.frame &&
               a->u.tile.tile == b->u.tile.tile && a->u.tile.attempt == b->u.tile.attempt &&
               a->u.tile.pass == b->u.tile.pass && a->u.tile.mask == b->u.tile.mask;
    case MSG_RESULT: {
        const struct msg_result *x = &a->u.result, *y = &b->u.result;
        return x->job_id == y->job_id && x->frame == y->frame && x->tile == y->tile &&
               x->attempt == y->attempt && x->stats.samples == y->stats.samples &&
               x->stats.rays == y->stats.rays && x->stats.nan_samples == y->stats.nan_samples &&
               x->stats.render_ns == y->stats.render_ns &&
               memcmp(&x->stats.sum_rel_stderr, &y->stats.sum_rel_stderr, sizeof(double)) == 0 &&
               x->stats.rel_stderr_pixels == y->stats.rel_stderr_pixels &&
               x->chunk_size == y->chunk_size && bytes_eq(x->chunk, y->chunk, x->chunk_size);
    }
    case MSG_ERROR:
        return a->u.error.job_id == b->u.error.job_id && strcmp(a->u.error.text, b->u.error.text) == 0;
    case MSG_HEARTBEAT:
        return a->u.heartbeat.job_id == b->u.heartbeat.job_id &&
               a->u.heartbeat.tiles_done == b->u.heartbeat.tiles_done &&
               a->u.heartbeat.samples_done == b->u.heartbeat.samples_done &&
               a->u.heartbeat.stalled_ms == b->u.heartbeat.stalled_ms &&
               a->u.heartbeat.map_wait_ms == b->u.heartbeat.map_wait_ms;
    case MSG_BYE:
        return 1;
    case MSG_ACK:
        if (a->u.ack.job_id != b->u.ack.job_id || a->u.ack.frame != b->u.ack.frame || a->u.ack.count != b->u.ack.count)
            return 0;
        for (uint32_t i = 0; i < a->u.ack.count; i++)
            if (a->u.ack.tiles[i] != b->u.ack.tiles[i])
                return 0;
        return 1;
    case MSG_KEPT: {
        const struct msg_kept *x = &a->u.kept, *y = &b->u.kept;
        return x->job_id == y->job_id && hash_eq(&x->job_key, &y->job_key) && x->frame == y->frame &&
               x->tile == y->tile && x->stats.samples == y->stats.samples && x->stats.rays == y->stats.rays &&
               x->stats.nan_samples == y->stats.nan_samples && x->stats.render_ns == y->stats.render_ns &&
               memcmp(&x->stats.sum_rel_stderr, &y->stats.sum_rel_stderr, sizeof(double)) == 0 &&
               x->stats.rel_stderr_pixels == y->stats.rel_stderr_pixels && x->chunk_size == y->chunk_size &&
               bytes_eq(x->chunk, y->chunk, x->chunk_size);
    }
    case MSG_MAP:
        return a->u.map.job_id == b->u.map.job_id && a->u.map.pass == b->u.map.pass &&
               a->u.map.published == b->u.map.published && hash_eq(&a->u.map.hash, &b->u.map.hash) && a->u.map.size == b->u.map.size;
    case MSG_CHUNKS_REQ:
        return hash_eq(&a->u.chunks_req.hash, &b->u.chunks_req.hash);
    case MSG_CHUNKS: {
        const struct msg_chunks *x = &a->u.chunks, *y = &b->u.chunks;
        return hash_eq(&x->hash, &y->hash) && x->size == y->size && x->flags == y->flags &&
               x->bcast_port == y->bcast_port && x->count == y->count &&
               bytes_eq(x->hashes, y->hashes, x->count * BLOB_HASH_SIZE);
    }
    case MSG_TYPE_MAX_:
        break;
    }
    return 0;
}

static void free_msg(struct proto_msg *m)
{
    if (m->type == MSG_JOB)
        proto_job_fini(&m->u.job);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    struct proto_msg m1, m2;
    char err[512];
    if (proto_decode(data, size, &m1, err, sizeof err) != 0) {
        if (err[0] == '\0' || !memchr(err, '\0', sizeof err))
            abort();   /* a rejection must say why */
        return 0;
    }
    struct proto_buf b = {0};
    if (proto_encode(&m1, &b) != 0)
        abort();   /* decode accepted what encode refuses */
    if (b.size != size || memcmp(b.data, data, size) != 0)
        abort();   /* two encodings of one message */
    if (proto_decode(b.data, b.size, &m2, err, sizeof err) != 0)
        abort();
    if (!msg_eq(&m1, &m2))
        abort();
    free_msg(&m2);
    free_msg(&m1);
    proto_buf_fini(&b);
    return 0;
}
