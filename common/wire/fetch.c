/* A blob fetch's phases (see fetch.h). Invariants: a chunk is kept only after its hash
 * matched the list (blob_recv_put); at most PROTO_FETCH_WINDOW requests are in flight; a
 * chunk that keeps coming back bad ends the fetch after PROTO_FETCH_MAX_ROUNDS rounds. */
#include "wire/fetch.h"
#include "base/log.h"
#include <stdio.h>
#include <string.h>

int proto_fetch_start(struct proto_fetch *f, const struct blob_hash *hash, uint64_t size, struct proto_msg *req,
                      char *err, size_t errlen)
{
    memset(f, 0, sizeof *f);
    if (blob_recv_init(&f->recv, hash, size, err, errlen) != 0)
        return -1;
    f->phase = FETCH_LIST;
    proto_fetch_list_req(f, req);
    return 0;
}

void proto_fetch_list_req(const struct proto_fetch *f, struct proto_msg *req)
{
    memset(req, 0, sizeof *req);
    req->type = MSG_CHUNKS_REQ;
    req->u.chunks_req.hash = f->recv.hash;
}

int proto_fetch_on_chunks(struct proto_fetch *f, const struct msg_chunks *c, uint64_t now_ms, char *err,
                          size_t errlen)
{
    if (f->phase != FETCH_LIST)
        return 0; /* a second answer (a repeated request): the first one counts */
    f->next_chunk = 0;
    f->last_bcast_ms = now_ms;
    if (c->size != f->recv.size) {
        str_fmt(err, errlen, "chunk list for %llu bytes, the blob has %llu", (unsigned long long)c->size,
                (unsigned long long)f->recv.size);
        f->phase = FETCH_P2P;
        return -1;
    }
    if (blob_recv_set_chunks(&f->recv, c->hashes, c->count, err, errlen) != 0) {
        f->phase = FETCH_P2P;
        return -1;
    }
    f->phase = (c->flags & PROTO_CHUNKS_BCAST) ? FETCH_BCAST : FETCH_P2P;
    return f->phase == FETCH_BCAST;
}

int proto_fetch_on_data(struct proto_fetch *f, const struct msg_blob_data *d, int via_bcast, uint64_t now_ms,
                        char *err, size_t errlen)
{
    if (via_bcast)
        f->last_bcast_ms = now_ms; /* the stream is alive, whatever this chunk is worth */
    else {
        if (f->in_flight)
            f->in_flight--; /* an answer, good or bad */
        f->asked_ms = now_ms;
    }
    if (d->total_size != f->recv.size) {
        str_fmt(err, errlen, "blob chunk says the blob has %llu bytes, not %llu", (unsigned long long)d->total_size,
                (unsigned long long)f->recv.size);
        return -1;
    }
    uint64_t had = f->recv.chunks_have;
    if (blob_recv_put(&f->recv, d->offset, d->bytes, d->length, err, errlen) != 0)
        return -1;
    if (f->recv.chunks_have > had) {
        if (via_bcast)
            f->chunks_bcast++;
        else
            f->chunks_p2p++;
    }
    return 0;
}

int proto_fetch_next_req(struct proto_fetch *f, uint64_t now_ms, struct proto_msg *req)
{
    if (!f->recv.data || blob_recv_complete(&f->recv) || f->phase == FETCH_LIST)
        return 0;
    if (f->phase == FETCH_BCAST) {
        if (now_ms - f->last_bcast_ms < PROTO_BCAST_IDLE_MS)
            return 0;
        f->phase = FETCH_P2P; /* the broadcast went quiet: ask for the rest (it may still bring some) */
        f->next_chunk = 0;
    }
    proto_fetch_expire(f, now_ms);
    if (f->in_flight >= PROTO_FETCH_WINDOW)
        return 0;
    uint64_t i = blob_recv_next_missing(&f->recv, f->next_chunk);
    if (i >= f->recv.num_chunks) {
        /* Every missing chunk was asked for: once the answers are in, ask again for those
         * still missing (an answer that failed its hash). */
        if (f->in_flight > 0)
            return 0;
        if (++f->rounds >= PROTO_FETCH_MAX_ROUNDS)
            return -1;
        i = blob_recv_next_missing(&f->recv, 0);
        if (i >= f->recv.num_chunks)
            return 0;
    }
    proto_blob_req_at(&f->recv.hash, f->recv.size, i * BLOB_CHUNK_SIZE, req);
    f->next_chunk = i + 1;
    f->in_flight++;
    f->asked_ms = now_ms;
    return 1;
}

void proto_fetch_bcast_alive(struct proto_fetch *f, uint64_t now_ms)
{
    if (f->phase == FETCH_BCAST)
        f->last_bcast_ms = now_ms;
}

int proto_fetch_lost(struct proto_fetch *f)
{
    int waiting = f->phase == FETCH_LIST ? f->list_asked : f->in_flight > 0;
    if (!f->recv.data || !waiting)
        return 0;
    /* ask again, from the first missing chunk (a late answer still counts) */
    f->list_asked = 0;
    f->in_flight = 0;
    f->next_chunk = 0;
    return 1;
}

int proto_fetch_expire(struct proto_fetch *f, uint64_t now_ms)
{
    if (now_ms < f->asked_ms + PROTO_FETCH_STALL_MS || !proto_fetch_lost(f))
        return 0;
    f->stalls++;
    return 1;
}

int proto_fetch_list_due(struct proto_fetch *f, uint64_t now_ms)
{
    proto_fetch_expire(f, now_ms);
    return f->recv.data && f->phase == FETCH_LIST && !f->list_asked;
}

void proto_fetch_list_sent(struct proto_fetch *f, uint64_t now_ms)
{
    f->list_asked = 1;
    f->asked_ms = now_ms;
}

void proto_fetch_fini(struct proto_fetch *f)
{
    blob_recv_fini(&f->recv); /* keeps the hash and size: callers look the blob up by them */
    f->phase = FETCH_LIST;
    f->next_chunk = 0;
    f->in_flight = 0;
    f->list_asked = 0;
    f->rounds = 0;
}

int proto_fetch_decode_bcast(const uint8_t *topic, size_t topic_len, const uint8_t *data, size_t size,
                             struct proto_msg *m, char *err, size_t errlen)
{
    if (errlen)
        err[0] = '\0';
    int decoded = proto_decode(data, size, m, err, errlen) == 0;
    if (decoded && m->type == MSG_BLOB_DATA && topic_len == BLOB_HASH_SIZE &&
        memcmp(topic, m->u.blob_data.hash.bytes, BLOB_HASH_SIZE) == 0)
        return 0;
    if (decoded && m->type == MSG_JOB)
        proto_job_fini(&m->u.job);
    if (decoded || !err[0])
        snprintf(err, errlen, "not a chunk of its topic");
    return -1;
}
