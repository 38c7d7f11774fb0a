/* Fetching one blob from the master (docs/cluster.md, "Delivering blobs to many
 * workers"): the chunk list, the broadcast, point to point for the rest; every chunk
 * checked against the list, the blob's hash at the end. Pure (no sockets, no clock): the
 * caller sends what it is told and passes the time. Used by worker/worker.c and
 * tests/tools/loadpeers.c. */
#ifndef BRUME_FETCH_H
#define BRUME_FETCH_H
#include <stdint.h>
#include "wire/blob.h"
#include "wire/proto.h"

/* Fetching one blob, shared by the worker and tests/tools/loadpeers: CHUNKS_REQ first;
 * with the chunk list, the broadcast (when the master has one: the caller subscribes to
 * the hash) and, for what it did not bring within PROTO_BCAST_IDLE_MS of the last chunk
 * (a late join, a full queue, a bad chunk), point-to-point BLOB_REQs, a window of
 * PROTO_FETCH_WINDOW. Every chunk is checked against the list; the blob's hash at the end
 * (blob_recv_finish). Pure: the caller sends what it is told and passes the time. */
#define PROTO_FETCH_WINDOW 16       /* BLOB_REQs in flight */
#define PROTO_BCAST_IDLE_MS 3000    /* no broadcast chunk for this long: fetch the rest point to point */
#define PROTO_FETCH_MAX_ROUNDS 8    /* passes over the missing chunks before a fetch gives up */
/* Requests in flight with no answer for this long were lost (a connection libzmq made
 * again drops what its old pipe held; a master whose queue for us was full dropped them):
 * the fetch asks again for what it lacks, the chunk list included. */
#define PROTO_FETCH_STALL_MS 20000
enum proto_fetch_phase { FETCH_LIST, FETCH_BCAST, FETCH_P2P };
struct proto_fetch {
    struct blob_recv recv;
    enum proto_fetch_phase phase;
    uint64_t next_chunk;            /* point to point: the next chunk index to look at */
    uint32_t in_flight;
    int list_asked;                 /* the caller sent the CHUNKS_REQ (FETCH_LIST: its answer is awaited) */
    uint32_t rounds;
    uint64_t last_bcast_ms;         /* when the broadcast last brought a chunk (or it began) */
    uint64_t asked_ms;              /* when a request last went out or an answer last came */
    uint32_t stalls;                /* times the requests in flight were given up as lost */
    uint64_t chunks_bcast, chunks_p2p; /* chunks kept from each path */
};
/* Starts a fetch of (hash, size) and fills *req with the CHUNKS_REQ to send. 0, or -1
 * (the size is past the limit). */
int proto_fetch_start(struct proto_fetch *f, const struct blob_hash *hash, uint64_t size, struct proto_msg *req,
                      char *err, size_t errlen);
/* The CHUNKS for this fetch: 1 when the caller should subscribe to the broadcast, 0 when
 * not, -1 when the list does not fit the blob (the fetch goes on point to point). */
int proto_fetch_on_chunks(struct proto_fetch *f, const struct msg_chunks *c, uint64_t now_ms, char *err,
                          size_t errlen);
/* A BLOB_DATA for this fetch (the caller matched the hash), from the broadcast (which
 * counts as the stream being alive, whatever the chunk is worth) or as an
 * answer to a BLOB_REQ. 0 when kept (or a duplicate), -1 when refused (bad size, offset,
 * hash: nothing kept, the chunk will be fetched again). */
int proto_fetch_on_data(struct proto_fetch *f, const struct msg_blob_data *d, int via_bcast, uint64_t now_ms,
                        char *err, size_t errlen);
/* The next BLOB_REQ to send, if any (1), else 0; -1 when the missing chunks were asked
 * for PROTO_FETCH_MAX_ROUNDS times in vain. Requests unanswered for PROTO_FETCH_STALL_MS
 * are given up (stalls) and the missing chunks asked for again. */
int proto_fetch_next_req(struct proto_fetch *f, uint64_t now_ms, struct proto_msg *req);
/* The broadcast socket has messages waiting (the caller's poll said so): the stream is not
 * quiet, however slowly the caller reads it. */
void proto_fetch_bcast_alive(struct proto_fetch *f, uint64_t now_ms);
/* Requests (the CHUNKS_REQ, or BLOB_REQs) in flight with nothing heard for
 * PROTO_FETCH_STALL_MS: given up (stalls counts it), so that the fetch asks again; 1 then,
 * else 0. proto_fetch_next_req and proto_fetch_list_due call it; a caller whose own window
 * is full calls it before counting what is in flight. */
int proto_fetch_expire(struct proto_fetch *f, uint64_t now_ms);
/* The requests in flight are lost for sure (the caller's connection was closed): given up
 * at once, as proto_fetch_expire does after the stall; 1 when there were any. */
int proto_fetch_lost(struct proto_fetch *f);
/* The chunk list: 1 when its CHUNKS_REQ is to be sent now (not sent yet, or sent
 * PROTO_FETCH_STALL_MS ago without an answer), else 0; proto_fetch_list_sent once it went. */
int proto_fetch_list_due(struct proto_fetch *f, uint64_t now_ms);
/* The fetch's CHUNKS_REQ (the one proto_fetch_start gives), into *req. */
void proto_fetch_list_req(const struct proto_fetch *f, struct proto_msg *req);
void proto_fetch_list_sent(struct proto_fetch *f, uint64_t now_ms);
void proto_fetch_fini(struct proto_fetch *f);
/* One message off the broadcast: its topic (topic_len bytes) and its payload. 0 when it is
 * a BLOB_DATA of the hash its topic names (in *m, pointing into data), else -1 with the
 * reason in err (anything else decoded is freed). */
int proto_fetch_decode_bcast(const uint8_t *topic, size_t topic_len, const uint8_t *data, size_t size,
                             struct proto_msg *m, char *err, size_t errlen);

#endif
