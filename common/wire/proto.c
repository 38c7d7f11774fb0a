/* Wire messages (see proto.h): encoding and bounds-checked decoding, little-endian by
 * explicit byte shifts so the format does not depend on the host. Encode and decode
 * accept exactly the same set of messages, so every decodable frame re-encodes to the
 * same bytes (the fuzz target checks this). Called by the master and worker loops. */
#include "wire/proto.h"
#include "base/bytes.h"
#include "base/log.h"
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void proto_buf_fini(struct proto_buf *b)
{
    free(b->data);
    b->data = NULL;
    b->size = b->cap = 0;
}

const char *proto_type_name(enum proto_type t)
{
    switch (t) {
    case MSG_HELLO: return "HELLO";
    case MSG_JOB: return "JOB";
    case MSG_BLOB_REQ: return "BLOB_REQ";
    case MSG_BLOB_DATA: return "BLOB_DATA";
    case MSG_READY: return "READY";
    case MSG_TILE: return "TILE";
    case MSG_RESULT: return "RESULT";
    case MSG_ERROR: return "ERROR";
    case MSG_HEARTBEAT: return "HEARTBEAT";
    case MSG_BYE: return "BYE";
    case MSG_ACK: return "ACK";
    case MSG_KEPT: return "KEPT";
    case MSG_MAP: return "MAP";
    case MSG_CHUNKS_REQ: return "CHUNKS_REQ";
    case MSG_CHUNKS: return "CHUNKS";
    case MSG_TYPE_MAX_: break;
    }
    return "UNKNOWN";
}

void proto_job_fini(struct msg_job *job)
{
    free(job->assets);
    job->assets = NULL;
    job->num_assets = 0;
}

/* ---- validation shared by encode and decode (keeps the two symmetric) ---- */

static int check_job_settings(const struct msg_job *j, char *err, size_t errlen)
{
    if (j->sampler >= SAMPLER_COUNT_) {
        str_fmt(err, errlen, "JOB: sampler %u unknown", j->sampler);
        return -1;
    }
    if (j->embree_isa >= EMBREE_ISA_COUNT_) {
        str_fmt(err, errlen, "JOB: Embree instruction set %u unknown", j->embree_isa);
        return -1;
    }
    if ((j->aovs & ~AOV_ALL) || j->filter >= FILTER_COUNT_ || !isfinite(j->filter_width) ||
        (j->filter != FILTER_BOX &&
         !(j->filter_width >= SCENE_FILTER_MIN_WIDTH && j->filter_width <= SCENE_FILTER_MAX_WIDTH))) {
        str_fmt(err, errlen, "JOB: aovs 0x%x, filter %u or filter width %g out of range", j->aovs, j->filter,
                (double)j->filter_width);
        return -1;
    }
    if (!j->width || !j->height || !j->spp || !j->tile_size) {
        str_fmt(err, errlen, "JOB: width %u, height %u, spp %u and tile_size %u must be > 0",
                j->width, j->height, j->spp, j->tile_size);
        return -1;
    }
    if (j->photon_maps > PROTO_MAX_PASSES || (j->photon_maps && j->spp % j->photon_maps != 0)) {
        str_fmt(err, errlen, "JOB: %u photon-map passes (at most %d, dividing spp %u)", j->photon_maps,
                PROTO_MAX_PASSES, j->spp);
        return -1;
    }
    if (j->passes > PROTO_MAX_PASSES || (j->passes > 1 && j->spp % j->passes != 0) ||
        (j->photon_maps && j->photon_maps != j->passes)) {
        str_fmt(err, errlen, "JOB: %u passes (at most %d, dividing spp %u, equal to the %u photon maps when there are any)",
                j->passes, PROTO_MAX_PASSES, j->spp, j->photon_maps);
        return -1;
    }
    return 0;
}

static int check_blob_data(const struct msg_blob_data *d, char *err, size_t errlen)
{
    if (d->length > BLOB_CHUNK_SIZE) {
        str_fmt(err, errlen, "BLOB_DATA: length %u exceeds the chunk size %u", d->length, BLOB_CHUNK_SIZE);
        return -1;
    }
    if (d->total_size > BLOB_MAX_SIZE || d->offset > d->total_size ||
        d->length > d->total_size - d->offset) {
        str_fmt(err, errlen, "BLOB_DATA: bytes [%llu, +%u) outside a blob of %llu bytes (max %llu)",
                (unsigned long long)d->offset, d->length, (unsigned long long)d->total_size,
                (unsigned long long)BLOB_MAX_SIZE);
        return -1;
    }
    return 0;
}

/* ---- encoding ---- */

static void put_bytes(struct proto_buf *b, const void *p, size_t n)
{
    if (n > b->cap - b->size) {
        size_t cap = b->cap ? b->cap : 256;
        while (cap - b->size < n)
            cap *= 2;
        b->data = mem_realloc(b->data, cap);
        b->cap = cap;
    }
    if (n)
        memcpy(b->data + b->size, p, n);
    b->size += n;
}

static void put_u16(struct proto_buf *b, uint16_t v)
{
    uint8_t x[2];
    bytes_put_u16(x, v);
    put_bytes(b, x, 2);
}

static void put_u32(struct proto_buf *b, uint32_t v)
{
    uint8_t x[4];
    bytes_put_u32(x, v);
    put_bytes(b, x, 4);
}

static void put_u64(struct proto_buf *b, uint64_t v)
{
    uint8_t x[8];
    bytes_put_u64(x, v);
    put_bytes(b, x, 8);
}

static void put_f64(struct proto_buf *b, double v)
{
    uint8_t x[8];
    bytes_put_f64(x, v);
    put_bytes(b, x, 8);
}

/* A tile's statistics, as RESULT and KEPT carry them (get_stats reads them back). */
static void put_stats(struct proto_buf *b, const struct tile_stats *st)
{
    put_u64(b, st->samples);
    put_u64(b, st->rays);
    put_u64(b, st->nan_samples);
    put_u64(b, st->render_ns);
    put_f64(b, st->sum_rel_stderr);
    put_u32(b, st->rel_stderr_pixels);
}

static void put_hash(struct proto_buf *b, const struct blob_hash *h)
{
    put_bytes(b, h->bytes, BLOB_HASH_SIZE);
}

/* The fixed arrays must hold a NUL-terminated string; one filling its array is refused
 * rather than silently cut. */
static int put_str(struct proto_buf *b, const char *s)
{
    size_t n = strnlen(s, PROTO_MAX_STRING);
    if (n >= PROTO_MAX_STRING)
        return -1;
    put_u16(b, (uint16_t)n);
    put_bytes(b, s, n);
    return 0;
}

static int put_payload(struct proto_buf *b, const uint8_t *p, uint32_t n)
{
    if (n && !p)
        return -1;
    put_u32(b, n);
    put_bytes(b, p, n);
    return 0;
}

int proto_encode(const struct proto_msg *msg, struct proto_buf *b)
{
    char err[256];
    b->size = 0;
    put_u32(b, PROTO_MAGIC);
    put_u16(b, PROTO_VERSION);
    put_u16(b, (uint16_t)msg->type);
    switch (msg->type) {
    case MSG_HELLO: {
        const struct msg_hello *m = &msg->u.hello;
        put_u32(b, m->threads);
        put_u32(b, m->pid);
        return put_str(b, m->host);
    }
    case MSG_JOB: {
        const struct msg_job *m = &msg->u.job;
        if (check_job_settings(m, err, sizeof err) < 0 || m->num_assets > PROTO_MAX_ASSETS ||
            (m->num_assets && !m->assets))
            return -1;
        put_u64(b, m->job_id);
        put_hash(b, &m->job_key);
        put_u32(b, m->frame);
        put_u32(b, m->width);
        put_u32(b, m->height);
        put_u32(b, m->spp);
        put_u32(b, m->max_depth);
        put_u32(b, m->tile_size);
        put_u64(b, m->seed);
        put_u32(b, m->sampler);
        put_u32(b, m->aovs);
        put_u32(b, m->filter);
        uint32_t fw;
        memcpy(&fw, &m->filter_width, 4); /* the float's bits: decoding and encoding again gives the same bytes */
        put_u32(b, fw);
        put_u32(b, m->photon_maps);
        put_u32(b, m->passes);
        put_u32(b, m->embree_isa);
        if (put_str(b, m->scene_path) < 0)
            return -1;
        put_u32(b, m->num_assets);
        for (uint32_t i = 0; i < m->num_assets; i++) {
            const struct proto_asset *a = &m->assets[i];
            if (!a->path[0] || a->size > BLOB_MAX_SIZE || put_str(b, a->path) < 0)
                return -1;
            put_hash(b, &a->hash);
            put_u64(b, a->size);
        }
        return 0;
    }
    case MSG_BLOB_REQ: {
        const struct msg_blob_req *m = &msg->u.blob_req;
        if (m->length > BLOB_CHUNK_SIZE)
            return -1;
        put_hash(b, &m->hash);
        put_u64(b, m->offset);
        put_u32(b, m->length);
        return 0;
    }
    case MSG_BLOB_DATA: {
        const struct msg_blob_data *m = &msg->u.blob_data;
        if (check_blob_data(m, err, sizeof err) < 0)
            return -1;
        put_hash(b, &m->hash);
        put_u64(b, m->offset);
        put_u64(b, m->total_size);
        return put_payload(b, m->bytes, m->length);
    }
    case MSG_READY:
        put_u64(b, msg->u.ready.job_id);
        put_u32(b, msg->u.ready.credits);
        return 0;
    case MSG_TILE:
        put_u64(b, msg->u.tile.job_id);
        put_u32(b, msg->u.tile.frame);
        put_u32(b, msg->u.tile.tile);
        put_u32(b, msg->u.tile.attempt);
        put_u32(b, msg->u.tile.pass);
        put_u64(b, msg->u.tile.mask);
        put_hash(b, &msg->u.tile.tag);
        return 0;
    case MSG_RESULT: {
        const struct msg_result *m = &msg->u.result;
        if (m->chunk_size > PROTO_MAX_CHUNK || !isfinite(m->stats.sum_rel_stderr))
            return -1;
        put_u64(b, m->job_id);
        put_u32(b, m->frame);
        put_u32(b, m->tile);
        put_u32(b, m->attempt);
        put_stats(b, &m->stats);
        return put_payload(b, m->chunk, m->chunk_size);
    }
    case MSG_ERROR:
        put_u64(b, msg->u.error.job_id);
        return put_str(b, msg->u.error.text);
    case MSG_HEARTBEAT:
        put_u64(b, msg->u.heartbeat.job_id);
        put_u32(b, msg->u.heartbeat.tiles_done);
        put_u64(b, msg->u.heartbeat.samples_done);
        put_u32(b, msg->u.heartbeat.stalled_ms);
        put_u32(b, msg->u.heartbeat.map_wait_ms);
        return 0;
    case MSG_BYE:
        return 0;
    case MSG_ACK: {
        const struct msg_ack *m = &msg->u.ack;
        if (m->count > PROTO_MAX_ACK_TILES)
            return -1;
        put_u64(b, m->job_id);
        put_u32(b, m->frame);
        put_u32(b, m->count);
        for (uint32_t i = 0; i < m->count; i++)
            put_u32(b, m->tiles[i]);
        return 0;
    }
    case MSG_KEPT: {
        const struct msg_kept *m = &msg->u.kept;
        if (m->chunk_size > PROTO_MAX_CHUNK || !isfinite(m->stats.sum_rel_stderr))
            return -1;
        put_u64(b, m->job_id);
        put_hash(b, &m->job_key);
        put_u32(b, m->frame);
        put_u32(b, m->tile);
        put_hash(b, &m->tag);
        put_stats(b, &m->stats);
        return put_payload(b, m->chunk, m->chunk_size);
    }
    case MSG_MAP: {
        const struct msg_map *m = &msg->u.map;
        if (m->pass >= PROTO_MAX_PASSES || m->size > BLOB_MAX_SIZE || m->published <= m->pass ||
            m->published > PROTO_MAX_PASSES)
            return -1;
        put_u64(b, m->job_id);
        put_u32(b, m->pass);
        put_u32(b, m->published);
        put_hash(b, &m->hash);
        put_u64(b, m->size);
        return 0;
    }
    case MSG_CHUNKS_REQ:
        put_hash(b, &msg->u.chunks_req.hash);
        return 0;
    case MSG_CHUNKS: {
        const struct msg_chunks *m = &msg->u.chunks;
        if (m->size > BLOB_MAX_SIZE || m->count != blob_num_chunks(m->size) || (m->flags & ~PROTO_CHUNKS_BCAST) ||
            (m->count && !m->hashes))
            return -1;
        put_hash(b, &m->hash);
        put_u64(b, m->size);
        put_u32(b, m->flags);
        put_u16(b, m->bcast_port);
        put_u32(b, m->count);
        put_bytes(b, m->hashes, (size_t)m->count * BLOB_HASH_SIZE);
        return 0;
    }
    case MSG_TYPE_MAX_:
        break;
    }
    return -1;
}

/* ---- decoding ---- */

/* A cursor over the frame. Every get_* checks the bytes left first; the first failure
 * writes the reason and later calls fail without overwriting it. */
struct reader {
    const uint8_t *p;
    size_t size, pos;
    const char *msg;    /* message type name, for errors */
    char *err;
    size_t errlen;
    int failed;
};

static int need(struct reader *r, size_t n, const char *field)
{
    if (r->failed)
        return -1;
    if (n > r->size - r->pos) {
        str_fmt(r->err, r->errlen, "%s: truncated at %s (offset %zu needs %zu bytes, frame has %zu)",
                r->msg, field, r->pos, n, r->size);
        r->failed = 1;
        return -1;
    }
    return 0;
}

/* The next n bytes, consumed; NULL when the message ends first (need() records why). */
static const uint8_t *take(struct reader *r, size_t n, const char *field)
{
    if (need(r, n, field) < 0)
        return NULL;
    r->pos += n;
    return r->p + r->pos - n;
}

/* Each reads its width if the message holds it, else 0. */
static uint16_t get_u16(struct reader *r, const char *field)
{
    const uint8_t *q = take(r, 2, field);
    return q ? bytes_get_u16(q) : 0;
}

static uint32_t get_u32(struct reader *r, const char *field)
{
    const uint8_t *q = take(r, 4, field);
    return q ? bytes_get_u32(q) : 0;
}

static uint64_t get_u64(struct reader *r, const char *field)
{
    const uint8_t *q = take(r, 8, field);
    return q ? bytes_get_u64(q) : 0;
}

static double get_f64(struct reader *r, const char *field)
{
    const uint8_t *q = take(r, 8, field);
    return q ? bytes_get_f64(q) : 0;
}

static void get_hash(struct reader *r, struct blob_hash *h, const char *field)
{
    const uint8_t *q = take(r, BLOB_HASH_SIZE, field);
    if (q)
        memcpy(h->bytes, q, BLOB_HASH_SIZE);
    else
        memset(h, 0, sizeof *h);
}

static void fail(struct reader *r, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void fail(struct reader *r, const char *fmt, ...)
{
    if (r->failed)
        return;
    r->failed = 1;
    int n = snprintf(r->err, r->errlen, "%s: ", r->msg);
    if (n < 0 || (size_t)n >= r->errlen)
        return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(r->err + n, r->errlen - (size_t)n, fmt, ap);
    va_end(ap);
}

/* Copies a u16-length string into out[PROTO_MAX_STRING], NUL-terminated. */
static void get_str(struct reader *r, char *out, const char *field)
{
    out[0] = '\0';
    uint16_t n = get_u16(r, field);
    if (r->failed)
        return;
    if (n > PROTO_MAX_STRING - 1) {
        fail(r, "%s: string of %u bytes exceeds the limit of %d", field, (unsigned)n, PROTO_MAX_STRING - 1);
        return;
    }
    const uint8_t *q = take(r, n, field);
    if (!q)
        return;
    if (memchr(q, 0, n)) {
        fail(r, "%s: string of %u bytes contains a NUL", field, (unsigned)n);
        return;
    }
    memcpy(out, q, n);
    out[n] = '\0';
}

/* A u32-length payload that stays in the frame; max is checked before the bytes. */
static const uint8_t *get_payload(struct reader *r, uint32_t *len, uint32_t max, const char *field)
{
    *len = get_u32(r, field);
    if (r->failed)
        return NULL;
    if (*len > max) {
        fail(r, "%s: length %u exceeds the limit of %u", field, *len, max);
        return NULL;
    }
    return take(r, *len, field);
}

/* Tile statistics of RESULT and KEPT; a non-finite error sum is refused. */
static void get_stats(struct reader *r, struct tile_stats *st)
{
    st->samples = get_u64(r, "samples");
    st->rays = get_u64(r, "rays");
    st->nan_samples = get_u64(r, "nan_samples");
    st->render_ns = get_u64(r, "render_ns");
    st->sum_rel_stderr = get_f64(r, "sum_rel_stderr");
    st->rel_stderr_pixels = get_u32(r, "rel_stderr_pixels");
    if (!r->failed && !isfinite(st->sum_rel_stderr))
        fail(r, "sum_rel_stderr is not finite");
}

static void decode_job(struct reader *r, struct msg_job *m)
{
    m->job_id = get_u64(r, "job_id");
    get_hash(r, &m->job_key, "job_key");
    m->frame = get_u32(r, "frame");
    m->width = get_u32(r, "width");
    m->height = get_u32(r, "height");
    m->spp = get_u32(r, "spp");
    m->max_depth = get_u32(r, "max_depth");
    m->tile_size = get_u32(r, "tile_size");
    m->seed = get_u64(r, "seed");
    m->sampler = get_u32(r, "sampler");
    m->aovs = get_u32(r, "aovs");
    m->filter = get_u32(r, "filter");
    uint32_t fw = get_u32(r, "filter_width");
    memcpy(&m->filter_width, &fw, 4);
    m->photon_maps = get_u32(r, "photon_maps");
    m->passes = get_u32(r, "passes");
    m->embree_isa = get_u32(r, "embree_isa");
    get_str(r, m->scene_path, "scene_path");
    uint32_t n = get_u32(r, "num_assets");
    if (r->failed)
        return;
    if (check_job_settings(m, r->err, r->errlen) < 0) {
        r->failed = 1;
        return;
    }
    if (n > PROTO_MAX_ASSETS) {
        fail(r, "num_assets %u exceeds the limit of %d", n, PROTO_MAX_ASSETS);
        return;
    }
    /* Each asset takes at least 2 + 1 + 32 + 8 bytes: a count the frame cannot hold is
     * refused before it becomes an allocation. */
    size_t min_asset = 2 + 1 + BLOB_HASH_SIZE + 8;
    if ((size_t)n > (r->size - r->pos) / min_asset) {
        fail(r, "truncated: %u assets announced, %zu bytes left", n, r->size - r->pos);
        return;
    }
    m->assets = n ? mem_calloc(n, sizeof *m->assets) : NULL;
    m->num_assets = n;
    for (uint32_t i = 0; i < n && !r->failed; i++) {
        struct proto_asset *a = &m->assets[i];
        get_str(r, a->path, "asset path");
        if (!r->failed && !a->path[0]) {
            fail(r, "asset %u has an empty path", i);
            break;
        }
        get_hash(r, &a->hash, "asset hash");
        a->size = get_u64(r, "asset size");
        if (!r->failed && a->size > BLOB_MAX_SIZE)
            fail(r, "asset %u size %llu exceeds the limit of %llu", i, (unsigned long long)a->size, (unsigned long long)BLOB_MAX_SIZE);
    }
}

int proto_decode(const uint8_t *frame, size_t size, struct proto_msg *msg, char *err, size_t errlen)
{
    memset(msg, 0, sizeof *msg);
    struct reader rd = {.p = frame, .size = size, .msg = "header", .err = err, .errlen = errlen};
    struct reader *r = &rd;
    if (size > PROTO_MAX_MESSAGE) {
        str_fmt(err, errlen, "message of %zu bytes exceeds the limit of %u", size, PROTO_MAX_MESSAGE);
        return -1;
    }
    uint32_t magic = get_u32(r, "magic");
    uint16_t version = get_u16(r, "version");
    uint16_t type = get_u16(r, "type");
    if (r->failed)
        return -1;
    if (magic != PROTO_MAGIC) {
        str_fmt(err, errlen, "bad magic 0x%08x (expected 0x%08x \"BRUM\")", magic, PROTO_MAGIC);
        return -1;
    }
    if (version != PROTO_VERSION) {
        str_fmt(err, errlen, "protocol version %u, this build speaks version %u", version, PROTO_VERSION);
        return -1;
    }
    if (type == 0 || type >= MSG_TYPE_MAX_) {
        str_fmt(err, errlen, "unknown message type %u", type);
        return -1;
    }
    msg->type = (enum proto_type)type;
    rd.msg = proto_type_name(msg->type);
    switch (msg->type) {
    case MSG_HELLO: {
        struct msg_hello *m = &msg->u.hello;
        m->threads = get_u32(r, "threads");
        m->pid = get_u32(r, "pid");
        get_str(r, m->host, "host");
        break;
    }
    case MSG_JOB:
        decode_job(r, &msg->u.job);
        break;
    case MSG_BLOB_REQ: {
        struct msg_blob_req *m = &msg->u.blob_req;
        get_hash(r, &m->hash, "hash");
        m->offset = get_u64(r, "offset");
        m->length = get_u32(r, "length");
        if (!r->failed && m->length > BLOB_CHUNK_SIZE)
            fail(r, "length %u exceeds the chunk size %u", m->length, BLOB_CHUNK_SIZE);
        break;
    }
    case MSG_BLOB_DATA: {
        struct msg_blob_data *m = &msg->u.blob_data;
        get_hash(r, &m->hash, "hash");
        m->offset = get_u64(r, "offset");
        m->total_size = get_u64(r, "total_size");
        m->bytes = get_payload(r, &m->length, BLOB_CHUNK_SIZE, "bytes");
        if (!r->failed && check_blob_data(m, err, errlen) < 0)
            r->failed = 1;
        break;
    }
    case MSG_READY:
        msg->u.ready.job_id = get_u64(r, "job_id");
        msg->u.ready.credits = get_u32(r, "credits");
        break;
    case MSG_TILE:
        msg->u.tile.job_id = get_u64(r, "job_id");
        msg->u.tile.frame = get_u32(r, "frame");
        msg->u.tile.tile = get_u32(r, "tile");
        msg->u.tile.attempt = get_u32(r, "attempt");
        msg->u.tile.pass = get_u32(r, "pass");
        msg->u.tile.mask = get_u64(r, "mask");
        if (!r->failed && msg->u.tile.pass >= PROTO_MAX_PASSES)
            fail(r, "pass %u exceeds the %u passes a job may have", msg->u.tile.pass, PROTO_MAX_PASSES);
        if (!r->failed && msg->u.tile.mask == 0)
            fail(r, "a tile with no pixel block to render");
        get_hash(r, &msg->u.tile.tag, "tag");
        break;
    case MSG_RESULT: {
        struct msg_result *m = &msg->u.result;
        m->job_id = get_u64(r, "job_id");
        m->frame = get_u32(r, "frame");
        m->tile = get_u32(r, "tile");
        m->attempt = get_u32(r, "attempt");
        get_stats(r, &m->stats);
        m->chunk = get_payload(r, &m->chunk_size, PROTO_MAX_CHUNK, "chunk");
        break;
    }
    case MSG_KEPT: {
        struct msg_kept *m = &msg->u.kept;
        m->job_id = get_u64(r, "job_id");
        get_hash(r, &m->job_key, "job_key");
        m->frame = get_u32(r, "frame");
        m->tile = get_u32(r, "tile");
        get_hash(r, &m->tag, "tag");
        get_stats(r, &m->stats);
        m->chunk = get_payload(r, &m->chunk_size, PROTO_MAX_CHUNK, "chunk");
        break;
    }
    case MSG_ACK: {
        struct msg_ack *m = &msg->u.ack;
        m->job_id = get_u64(r, "job_id");
        m->frame = get_u32(r, "frame");
        uint32_t n = get_u32(r, "count");
        if (r->failed)
            break;
        if (n > PROTO_MAX_ACK_TILES) {
            fail(r, "count %u exceeds the limit of %d", n, PROTO_MAX_ACK_TILES);
            break;
        }
        m->count = n;
        for (uint32_t i = 0; i < n && !r->failed; i++)
            m->tiles[i] = get_u32(r, "tiles");
        break;
    }
    case MSG_ERROR:
        msg->u.error.job_id = get_u64(r, "job_id");
        get_str(r, msg->u.error.text, "text");
        break;
    case MSG_HEARTBEAT:
        msg->u.heartbeat.job_id = get_u64(r, "job_id");
        msg->u.heartbeat.tiles_done = get_u32(r, "tiles_done");
        msg->u.heartbeat.samples_done = get_u64(r, "samples_done");
        msg->u.heartbeat.stalled_ms = get_u32(r, "stalled_ms");
        msg->u.heartbeat.map_wait_ms = get_u32(r, "map_wait_ms");
        break;
    case MSG_MAP: {
        struct msg_map *m = &msg->u.map;
        m->job_id = get_u64(r, "job_id");
        m->pass = get_u32(r, "pass");
        m->published = get_u32(r, "published");
        get_hash(r, &m->hash, "hash");
        m->size = get_u64(r, "size");
        if (!r->failed && m->pass >= PROTO_MAX_PASSES)
            fail(r, "pass %u exceeds the limit of %d passes", m->pass, PROTO_MAX_PASSES);
        else if (!r->failed && (m->published <= m->pass || m->published > PROTO_MAX_PASSES))
            fail(r, "published %u is not past pass %u and within the limit of %d passes", m->published, m->pass,
                 PROTO_MAX_PASSES);
        else if (!r->failed && m->size > BLOB_MAX_SIZE)
            fail(r, "size %llu exceeds the limit of %llu", (unsigned long long)m->size,
                 (unsigned long long)BLOB_MAX_SIZE);
        break;
    }
    case MSG_CHUNKS_REQ:
        get_hash(r, &msg->u.chunks_req.hash, "hash");
        break;
    case MSG_CHUNKS: {
        struct msg_chunks *m = &msg->u.chunks;
        get_hash(r, &m->hash, "hash");
        m->size = get_u64(r, "size");
        m->flags = get_u32(r, "flags");
        m->bcast_port = get_u16(r, "bcast_port");
        m->count = get_u32(r, "count");
        m->hashes = NULL;
        if (r->failed)
            break;
        if (m->size > BLOB_MAX_SIZE)
            fail(r, "size %llu exceeds the limit of %llu", (unsigned long long)m->size,
                 (unsigned long long)BLOB_MAX_SIZE);
        else if (m->flags & ~PROTO_CHUNKS_BCAST)
            fail(r, "unknown flags 0x%x", m->flags);
        else if (m->count != blob_num_chunks(m->size))
            fail(r, "%u chunk hashes for a blob of %llu bytes", m->count, (unsigned long long)m->size);
        else
            m->hashes = take(r, (size_t)m->count * BLOB_HASH_SIZE, "hashes");
        break;
    }
    case MSG_BYE:
    case MSG_TYPE_MAX_:
        break;
    }
    if (!r->failed && r->pos != size) {
        str_fmt(err, errlen, "%s: %zu trailing bytes after the message", rd.msg, size - r->pos);
        r->failed = 1;
    }
    if (r->failed) {
        /* On failure nothing is left for the caller to free. */
        if (msg->type == MSG_JOB)
            proto_job_fini(&msg->u.job);
        return -1;
    }
    return 0;
}

void proto_blob_req_at(const struct blob_hash *hash, uint64_t size, uint64_t offset, struct proto_msg *out)
{
    memset(out, 0, sizeof *out);
    out->type = MSG_BLOB_REQ;
    out->u.blob_req.hash = *hash;
    out->u.blob_req.offset = offset;
    uint64_t left = size - offset;
    out->u.blob_req.length = (uint32_t)(left < BLOB_CHUNK_SIZE ? left : BLOB_CHUNK_SIZE);
}
