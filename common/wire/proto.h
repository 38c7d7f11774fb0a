/* Wire protocol between master (ROUTER) and workers (DEALER). One ZeroMQ frame per
 * message (after the ROUTER's identity frame), little-endian, starting with a header:
 *   u32 magic "BRUM", u16 version, u16 type
 * then the message's fields. Everything is decoded with bounds checks; strings carry a
 * u16 length and must be valid (no NUL, within limits); counts and sizes are checked
 * against limits before anything is allocated from them. A frame that fails to decode
 * yields -1 and a reason; the caller logs it with the peer and drops it. */
#ifndef BRUME_PROTO_H
#define BRUME_PROTO_H
#include <stddef.h>
#include <stdint.h>
#include "wire/blob.h"
#include "render/tile.h"

#define PROTO_MAGIC 0x4d555242u /* "BRUM" little-endian */
#define PROTO_VERSION 13 /* 2: HEARTBEAT carries samples_done; 3: JOB carries job_key, ACK, KEPT; 4: photon-map passes (JOB photon_maps, MAP); 5: JOB passes (passes without photon maps); 6: TILE and KEPT carry the holder's tag; 7: JOB aovs, filter; 8: TILE pass and block mask; 9: CHUNKS_REQ, CHUNKS (broadcast blobs); 10: blocks of 4 px (a TILE mask names other pixels); 11: a blob is named by the hash of its chunk list; 12: JOB embree_isa; 13: MAP carries published */
#define PROTO_MAX_MESSAGE (64u * 1024u * 1024u) /* also ZMQ_MAXMSGSIZE */
#define PROTO_MAX_STRING 1024
#define PROTO_MAX_ASSETS 4096
#define PROTO_MAX_CHUNK (48u * 1024u * 1024u)   /* an EXR tile chunk */
#define PROTO_MAX_ACK_TILES 256                  /* tiles one ACK may list (more: several ACKs) */
#define PROTO_MAX_PASSES 1024                    /* photon-map passes of a job (VOLUME_BLOB_MAX_MAPS) */

enum proto_type {
    MSG_HELLO = 1,      /* w->m: I exist; my threads */
    MSG_JOB = 2,        /* m->w: what to render: settings and the blobs that describe it */
    MSG_BLOB_REQ = 3,   /* w->m: send me bytes [offset, offset+len) of blob hash */
    MSG_BLOB_DATA = 4,  /* m->w: those bytes */
    MSG_READY = 5,      /* w->m: job loaded; I can take `credits` more tiles */
    MSG_TILE = 6,       /* m->w: render this tile (job, frame, tile, attempt) */
    MSG_RESULT = 7,     /* w->m: the tile's EXR chunk and stats; returns one credit */
    MSG_ERROR = 8,      /* w->m: cannot do the job (message says why) */
    MSG_HEARTBEAT = 9,  /* both ways; the worker's proves its render threads progress */
    MSG_BYE = 10,       /* m->w: job over, exit; w->m: I am leaving */
    MSG_ACK = 11,       /* m->w: these tiles of (job, frame) are safe (journal synced): forget them */
    MSG_KEPT = 12,      /* w->m: a finished tile kept for a job of this job_key (a master that came back) */
    MSG_MAP = 13,       /* m->w: pass `pass`'s photon map is published as blob hash (size bytes) */
    MSG_CHUNKS_REQ = 14, /* w->m: the chunk list of blob hash, please */
    MSG_CHUNKS = 15,    /* m->w: its chunk hashes, and whether it is broadcast (where) */
    MSG_TYPE_MAX_ = 16
};

struct msg_hello {
    uint32_t threads;
    uint32_t pid;
    char host[PROTO_MAX_STRING];
};

struct proto_asset {
    char path[PROTO_MAX_STRING];   /* relative to the scene folder */
    struct blob_hash hash;
    uint64_t size;
};

struct msg_job {
    uint64_t job_id;
    /* What fixes the frame's pixels (scene, assets, settings, frame, tile layout): the same
     * for a master restarted on the same job, whose job_id differs. Kept tiles are matched
     * against it. */
    struct blob_hash job_key;
    uint32_t frame;
    /* settings after command-line overrides; the worker applies them over the scene's */
    uint32_t width, height, spp, max_depth, tile_size;
    uint64_t seed;
    uint32_t sampler;                    /* enum sampler_type, < SAMPLER_COUNT_ */
    uint32_t aovs;                       /* bit set of enum aov, within AOV_ALL */
    uint32_t filter;                     /* enum pixel_filter, < FILTER_COUNT_ */
    float filter_width;                  /* pixels, in [SCENE_FILTER_MIN_WIDTH, SCENE_FILTER_MAX_WIDTH] (box: any, ignored) */
    /* Photon maps: 0 (none; one pass) or P (1..PROTO_MAX_PASSES, spp a multiple of P): the
     * frame renders in P passes, pass p with map p, announced by MAP. With P >= 1 the
     * `tile` of TILE, RESULT, KEPT and ACK is a unit u = p * tiles + tile. */
    uint32_t photon_maps;
    /* Passes: 0 or 1 (one pass: a unit is a tile) or P (2..PROTO_MAX_PASSES, spp a multiple
     * of P): units u = p * tiles + tile, each pass spp / P samples with its own scramble.
     * photon_maps is 0 or equal to it. */
    uint32_t passes;
    /* enum embree_isa (scene.h), < EMBREE_ISA_COUNT_: the Embree kernels every worker's rays
     * use, so that pixels do not depend on which CPU rendered a tile */
    uint32_t embree_isa;
    char scene_path[PROTO_MAX_STRING];   /* one of the assets: the scene file */
    uint32_t num_assets;                 /* <= PROTO_MAX_ASSETS */
    struct proto_asset *assets;          /* decode allocates; free with proto_job_free */
};

struct msg_blob_req {
    struct blob_hash hash;
    uint64_t offset;
    uint32_t length;
};

struct msg_blob_data {
    struct blob_hash hash;
    uint64_t offset;
    uint64_t total_size;
    const uint8_t *bytes;   /* points into the decoded frame */
    uint32_t length;
};

struct msg_chunks_req {
    struct blob_hash hash;
};

/* The chunk list of blob hash (size bytes): the BLAKE2b-256 of each BLOB_CHUNK_SIZE chunk
 * (the list hashes to the blob's name, blob_name_of_chunks),
 * count = blob_num_chunks(size) of them (checked on decode). With PROTO_CHUNKS_BCAST the
 * master streams the blob's chunks on its broadcast socket (net_bcast_endpoint: beside the
 * ROUTER's ipc socket, or on bcast_port of the same tcp host) to subscribers of the
 * hash; a worker takes them (each checked against its hash) and fetches what it lacks
 * point to point. */
#define PROTO_CHUNKS_BCAST 1u
#define PROTO_MAX_CHUNK_LIST (BLOB_MAX_SIZE / BLOB_CHUNK_SIZE)
struct msg_chunks {
    struct blob_hash hash;
    uint64_t size;
    uint32_t flags;             /* PROTO_CHUNKS_BCAST or 0 */
    uint16_t bcast_port;        /* tcp: the broadcast socket's port (0: none) */
    uint32_t count;             /* == blob_num_chunks(size) */
    const uint8_t *hashes;      /* count * BLOB_HASH_SIZE bytes, points into the frame */
};

struct msg_ready {
    uint64_t job_id;
    uint32_t credits;
};

struct msg_tile {
    uint64_t job_id;
    uint32_t frame;
    uint32_t tile;      /* index: ty * tiles_x + tx; with photon maps the unit pass * tiles + tile */
    uint32_t attempt;
    /* The sample pass the unit renders (< the JOB's passes, or 0 with one pass) and the
     * pixel blocks of the tile it renders (bit b: block b of tile_block_size pixels, in
     * rows of tile_blocks_side, render/tile.h); the other pixels are zero. A plain render
     * sends every bit; an adaptive one renders a tile's blocks with their own pass counts,
     * so its unit u = slot * tiles + tile names a slot whose pass and mask the master chose. */
    uint32_t pass;
    uint64_t mask;
    /* The master's MAC over (job key, tile, the holder's public key): the worker keeps it
     * with the finished tile and returns it in KEPT, so that a master that comes back
     * takes a kept tile only from the identity it was assigned to. */
    struct blob_hash tag;
};

struct msg_result {
    uint64_t job_id;
    uint32_t frame;
    uint32_t tile;
    uint32_t attempt;
    struct tile_stats stats;
    const uint8_t *chunk;   /* points into the decoded frame */
    uint32_t chunk_size;    /* <= PROTO_MAX_CHUNK */
};

/* The master has synced these tiles of (job_id, frame) to its journal (or has them done
 * already): the worker may drop its copies. */
struct msg_ack {
    uint64_t job_id;
    uint32_t frame;
    uint32_t count;                         /* <= PROTO_MAX_ACK_TILES */
    uint32_t tiles[PROTO_MAX_ACK_TILES];
};

/* A finished tile the worker kept (not acknowledged by the master it rendered it for),
 * offered to the master now connected: job_id is the current master's JOB, job_key the
 * key of the job the tile was rendered for. The master accepts it only when job_key is
 * its own. */
struct msg_kept {
    uint64_t job_id;
    struct blob_hash job_key;
    uint32_t frame;
    uint32_t tile;
    struct blob_hash tag;   /* the TILE's tag, as the assigning master sent it */
    struct tile_stats stats;
    const uint8_t *chunk;   /* points into the decoded frame */
    uint32_t chunk_size;    /* <= PROTO_MAX_CHUNK */
};

/* Pass `pass` (< the JOB's photon_maps) of job job_id renders with the map in blob hash,
 * of `size` bytes (<= BLOB_MAX_SIZE): a worker fetches it like any blob before it renders
 * a unit of that pass. Sent to every worker when the master has traced the map, and after
 * a JOB for every map published so far (late workers), in pass order. published: how
 * many maps the master had published when it sent this one (pass < published <=
 * PROTO_MAX_PASSES), so that a worker whose MAPs came in pieces knows a newer one is on
 * its way and prefetches that one, not this. */
struct msg_map {
    uint64_t job_id;
    uint32_t pass;
    uint32_t published;
    struct blob_hash hash;
    uint64_t size;
};

struct msg_error {
    uint64_t job_id;
    char text[PROTO_MAX_STRING];
};

/* samples_done: camera samples the worker's render threads finished since it started, a
 * counter that only grows; stalled_ms: how long the slowest busy render thread has not
 * finished a row. The master evicts a worker holding tiles whose counter stops moving or
 * that reports a stalled thread (its main thread may answer while render threads hang).
 * map_wait_ms: how long, in the job so far, the worker had units waiting for their photon
 * map's fetch and nothing to render (a statistic). */
struct msg_heartbeat { uint64_t job_id; uint32_t tiles_done; uint64_t samples_done; uint32_t stalled_ms; uint32_t map_wait_ms; };

/* A decoded message. Pointers inside refer to the frame's bytes, which must outlive it. */
struct proto_msg {
    enum proto_type type;
    union {
        struct msg_hello hello;
        struct msg_job job;
        struct msg_blob_req blob_req;
        struct msg_blob_data blob_data;
        struct msg_ready ready;
        struct msg_tile tile;
        struct msg_result result;
        struct msg_error error;
        struct msg_heartbeat heartbeat;
        struct msg_ack ack;
        struct msg_kept kept;
        struct msg_map map;
        struct msg_chunks_req chunks_req;
        struct msg_chunks chunks;
    } u;
};

/* The BLOB_REQ for the chunk of blob (hash, size) at offset (< size): at most
 * BLOB_CHUNK_SIZE bytes. Fetchers (worker, tests/tools/loadpeers) keep a window of them. */
void proto_blob_req_at(const struct blob_hash *hash, uint64_t size, uint64_t offset, struct proto_msg *out);

/* A growable output buffer for encoding. */
struct proto_buf { uint8_t *data; size_t size, cap; };
void proto_buf_fini(struct proto_buf *b);

/* Encodes msg into b (b->size reset first). Returns 0, or -1 if a field is out of its
 * limits (e.g. a string too long), in which case nothing should be sent. */
int proto_encode(const struct proto_msg *msg, struct proto_buf *b);

/* Decodes one frame. Checks magic, version, type, every length and that the frame has no
 * trailing bytes. Returns 0, or -1 with the reason in err. On success with MSG_JOB the
 * caller frees with proto_job_free. */
int proto_decode(const uint8_t *frame, size_t size, struct proto_msg *msg, char *err, size_t errlen);
void proto_job_fini(struct msg_job *job);
const char *proto_type_name(enum proto_type t);

#endif
