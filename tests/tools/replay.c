/* replay: a generated corpus of malformed and out-of-order messages, sent to a live master
 * by one DEALER peer, for integration tests (tests/integration/security.sh).
 *   replay ENDPOINT [SEED]
 * Before its HELLO it sends valid messages of every other type (a RESULT before HELLO),
 * prefixes of a HELLO, and multi-frame envelopes; after a valid HELLO (and the JOB it
 * brings) it sends every proper prefix of every message type, trailing bytes, wrong
 * magic, versions and types, length fields that lie, random mutations, a second HELLO,
 * messages only a master sends (TILE, JOB, BLOB_DATA), READY for another job, BLOB_REQ
 * for unknown hashes and bad ranges, and RESULTs with foreign ids or for tiles never
 * assigned, ACKs (only a master sends them) and KEPT tiles for another job key, frame,
 * job id or tile. Every generated frame is classified here with proto_decode first, so the
 * expected master counter of each is exact; the tool prints the sums as
 * "replay: expect COUNTER N" lines for the test to compare with the master's summary.
 * It ends with a BYE (so the master has read everything before it) and then sends one
 * frame over ZMQ_MAXMSGSIZE on a separate connection, which libzmq must refuse. */
#include "wire/net.h"
#include "wire/proto.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <zmq.h>

enum expect { EX_DECODE, EX_ENVELOPE, EX_UNKNOWN_PEER, EX_UNEXPECTED, EX_WRONG_JOB, EX_BLOB_REQ, EX_NOT_OURS,
              EX_STALE, EX_COUNT_ };
static const char *const k_counter[EX_COUNT_] = {
    "rejected_decode", "rejected_envelope", "rejected_unknown_peer", "rejected_unexpected",
    "rejected_wrong_job", "rejected_blob_req", "results_not_ours", "results_stale"};

static unsigned long long g_expect[EX_COUNT_];
static unsigned long long g_sent;
static uint64_t g_rng = 0x9e3779b97f4a7c15ull;

static uint32_t rnd(void)
{
    g_rng ^= g_rng << 13;
    g_rng ^= g_rng >> 7;
    g_rng ^= g_rng << 17;
    return (uint32_t)(g_rng >> 11);
}

static void *g_sock;

static void send_raw(const uint8_t *p, size_t n)
{
    if (zmq_send(g_sock, p, n, 0) < 0) {
        fprintf(stderr, "replay: send: %s\n", zmq_strerror(zmq_errno()));
        exit(1);
    }
    g_sent++;
    /* Paced: libzmq may drop what is still queued towards a master whose inbound pipe is
     * at its high-water mark when this peer closes; the corpus must arrive whole. */
    if (g_sent % 200 == 0)
        usleep(20000);
}

/* Sends a frame that must not decode (checked here: the corpus means what it says). */
static void send_malformed(const uint8_t *p, size_t n)
{
    struct proto_msg m;
    char err[256];
    if (proto_decode(p, n, &m, err, sizeof err) == 0) {
        if (m.type == MSG_JOB)
            proto_job_fini(&m.u.job);
        return; /* a mutation that happens to be a valid message: not part of this corpus */
    }
    send_raw(p, n);
    g_expect[EX_DECODE]++;
}

static void send_msg(const struct proto_msg *m, enum expect e)
{
    struct proto_buf b = {0};
    if (proto_encode(m, &b) != 0) {
        fprintf(stderr, "replay: cannot encode a %s\n", proto_type_name(m->type));
        exit(1);
    }
    send_raw(b.data, b.size);
    g_expect[e]++;
    proto_buf_fini(&b);
}

static uint8_t g_chunk[64];
static struct proto_asset g_asset;

/* A valid message of each type, with the given job id. */
static void sample(enum proto_type t, uint64_t job_id, uint32_t variant, struct proto_msg *m)
{
    memset(m, 0, sizeof *m);
    m->type = t;
    switch (t) {
    case MSG_HELLO:
        m->u.hello.threads = 1 + variant;
        m->u.hello.pid = 4242;
        snprintf(m->u.hello.host, sizeof m->u.hello.host, "replay%u", variant);
        break;
    case MSG_JOB:
        m->u.job.job_id = job_id;
        m->u.job.width = m->u.job.height = m->u.job.spp = m->u.job.tile_size = 8 + variant;
        m->u.job.max_depth = 2;
        snprintf(m->u.job.scene_path, sizeof m->u.job.scene_path, "x.json");
        m->u.job.num_assets = 1;
        m->u.job.assets = &g_asset;
        break;
    case MSG_BLOB_REQ:
        m->u.blob_req.hash.bytes[0] = (uint8_t)variant;
        m->u.blob_req.length = 16;
        break;
    case MSG_BLOB_DATA:
        m->u.blob_data.total_size = sizeof g_chunk;
        m->u.blob_data.bytes = g_chunk;
        m->u.blob_data.length = sizeof g_chunk;
        break;
    case MSG_READY:
        m->u.ready.job_id = job_id;
        m->u.ready.credits = 2;
        break;
    case MSG_TILE:
        m->u.tile.job_id = job_id;
        m->u.tile.tile = variant;
        m->u.tile.attempt = 1;
        m->u.tile.mask = TILE_MASK_ALL; /* a well-formed TILE (mask 0 does not decode) */
        break;
    case MSG_RESULT:
        m->u.result.job_id = job_id;
        m->u.result.tile = variant;
        m->u.result.chunk = g_chunk;
        m->u.result.chunk_size = sizeof g_chunk;
        break;
    case MSG_ERROR:
        m->u.error.job_id = job_id;
        snprintf(m->u.error.text, sizeof m->u.error.text, "replay");
        break;
    case MSG_HEARTBEAT:
        m->u.heartbeat.job_id = job_id;
        break;
    case MSG_ACK:
        m->u.ack.job_id = job_id;
        m->u.ack.count = 1 + variant % 3;
        for (uint32_t i = 0; i < m->u.ack.count; i++)
            m->u.ack.tiles[i] = variant + i;
        break;
    case MSG_KEPT:
        m->u.kept.job_id = job_id;
        m->u.kept.job_key.bytes[0] = (uint8_t)(0xa0 + variant);
        m->u.kept.tile = variant;
        m->u.kept.chunk = g_chunk;
        m->u.kept.chunk_size = sizeof g_chunk;
        break;
    case MSG_MAP:
        m->u.map.job_id = job_id;
        m->u.map.pass = variant % 4;
        m->u.map.published = 4;
        m->u.map.hash.bytes[0] = (uint8_t)variant;
        m->u.map.size = 64;
        break;
    case MSG_CHUNKS_REQ:
        m->u.chunks_req.hash.bytes[0] = (uint8_t)variant;
        break;
    case MSG_CHUNKS: {
        static const uint8_t hashes[BLOB_HASH_SIZE] = {7};
        m->u.chunks.hash.bytes[0] = (uint8_t)variant;
        m->u.chunks.size = 64;
        m->u.chunks.count = 1;
        m->u.chunks.hashes = hashes;
        break;
    }
    case MSG_BYE:
    case MSG_TYPE_MAX_:
        break;
    }
}

static void encode_sample(enum proto_type t, uint64_t job_id, uint32_t variant, struct proto_buf *b)
{
    struct proto_msg m;
    sample(t, job_id, variant, &m);
    if (proto_encode(&m, b) != 0) {
        fprintf(stderr, "replay: cannot encode a %s sample\n", proto_type_name(t));
        exit(1);
    }
}

static void put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

/* Waits for the master's JOB (it follows our HELLO); 0 or -1. */
static int wait_job(struct msg_job *job)
{
    for (int tries = 0; tries < 100; tries++) {
        zmq_pollitem_t it = {g_sock, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, 100) <= 0)
            continue;
        struct net_frame f;
        while (net_recv(g_sock, 0, &f) > 0) {
            struct proto_msg m;
            char err[256];
            int got = proto_decode(f.data, f.size, &m, err, sizeof err) == 0 && m.type == MSG_JOB;
            if (got) {
                *job = m.u.job;
                job->assets = malloc(sizeof *job->assets * (m.u.job.num_assets ? m.u.job.num_assets : 1));
                memcpy(job->assets, m.u.job.assets, sizeof *job->assets * m.u.job.num_assets);
                proto_job_fini(&m.u.job);
            } else if (m.type == MSG_JOB) {
                proto_job_fini(&m.u.job);
            }
            net_frame_fini(&f);
            if (got)
                return 0;
        }
    }
    return -1;
}

int main(int argc, char **argv)
{
    if (argc < 2 || argc > 3) {
        fprintf(stderr, "usage: replay ENDPOINT [SEED]\n");
        return 2;
    }
    if (argc == 3)
        g_rng ^= strtoull(argv[2], NULL, 10) * 0x2545f4914f6cdd1dull;
    for (size_t i = 0; i < sizeof g_chunk; i++)
        g_chunk[i] = (uint8_t)i;
    snprintf(g_asset.path, sizeof g_asset.path, "x.json");
    g_asset.size = 10;
    void *ctx = zmq_ctx_new();
    g_sock = zmq_socket(ctx, ZMQ_DEALER);
    int linger = -1, hwm = 0; /* wait for every frame to go: the test bounds the run with timeout */
    zmq_setsockopt(g_sock, ZMQ_LINGER, &linger, sizeof linger);
    zmq_setsockopt(g_sock, ZMQ_SNDHWM, &hwm, sizeof hwm); /* queue everything, drop nothing */
    if (zmq_connect(g_sock, argv[1]) != 0) {
        fprintf(stderr, "replay: cannot connect to %s\n", argv[1]);
        return 1;
    }
    struct proto_buf b = {0};
    struct proto_msg m;

    /* ---- before HELLO: a stranger ---- */
    for (int t = MSG_JOB; t < MSG_TYPE_MAX_; t++) /* every other type out of order, RESULT included */
        for (uint32_t v = 0; v < 5; v++) {
            sample((enum proto_type)t, 12345, v, &m);
            send_msg(&m, EX_UNKNOWN_PEER);
        }
    encode_sample(MSG_HELLO, 0, 0, &b);
    for (size_t n = 0; n < b.size; n++) /* every prefix of a HELLO, the empty frame too */
        send_malformed(b.data, n);
    for (uint32_t i = 0; i < 20; i++) { /* envelopes of 2 to 4 frames */
        uint32_t parts = 2 + i % 3;
        for (uint32_t k = 0; k < parts; k++)
            zmq_send(g_sock, b.data, b.size, k + 1 < parts ? ZMQ_SNDMORE : 0);
        g_sent++;
        g_expect[EX_ENVELOPE]++;
    }

    /* ---- HELLO: now a known peer; the JOB tells us the job id ---- */
    encode_sample(MSG_HELLO, 0, 0, &b);
    send_raw(b.data, b.size);
    g_sent--; /* the one valid HELLO is not part of the corpus */
    struct msg_job job;
    if (wait_job(&job) != 0) {
        fprintf(stderr, "replay: no JOB from the master after HELLO\n");
        return 1;
    }
    uint32_t tiles_x = (job.width + job.tile_size - 1) / job.tile_size;
    uint32_t tiles_y = (job.height + job.tile_size - 1) / job.tile_size, num_tiles = tiles_x * tiles_y;
    /* The job's units are (tile, pass) pairs: a unit at or past num_units is nobody's. */
    uint32_t num_units = num_tiles * (job.passes > 1 ? job.passes : 1);

    /* every proper prefix and one trailing byte, of every type */
    for (int t = MSG_HELLO; t < MSG_TYPE_MAX_; t++) {
        encode_sample((enum proto_type)t, job.job_id, 1, &b);
        for (size_t n = 0; n < b.size; n++)
            send_malformed(b.data, n);
        uint8_t *longer = malloc(b.size + 1);
        memcpy(longer, b.data, b.size);
        longer[b.size] = 0;
        send_malformed(longer, b.size + 1);
        free(longer);
        /* header: wrong magic, version and type */
        static const uint16_t versions[] = {0, 1, PROTO_VERSION - 1, PROTO_VERSION + 1, 0xffff};
        static const uint16_t types[] = {0, MSG_TYPE_MAX_, MSG_TYPE_MAX_ + 1, 0x7fff, 0xffff};
        uint8_t save[8];
        memcpy(save, b.data, 8);
        for (int k = 0; k < 4; k++) {
            b.data[k] ^= 0x20;
            send_malformed(b.data, b.size);
            memcpy(b.data, save, 8);
        }
        for (size_t k = 0; k < sizeof versions / sizeof versions[0]; k++) {
            if (versions[k] == PROTO_VERSION)
                continue;
            b.data[4] = (uint8_t)versions[k];
            b.data[5] = (uint8_t)(versions[k] >> 8);
            send_malformed(b.data, b.size);
            memcpy(b.data, save, 8);
        }
        for (size_t k = 0; k < sizeof types / sizeof types[0]; k++) {
            b.data[6] = (uint8_t)types[k];
            b.data[7] = (uint8_t)(types[k] >> 8);
            send_malformed(b.data, b.size);
            memcpy(b.data, save, 8);
        }
    }
    /* length fields that lie: every u32 / u16 position of each sample set to huge values */
    for (int t = MSG_HELLO; t < MSG_TYPE_MAX_; t++) {
        encode_sample((enum proto_type)t, job.job_id, 2, &b);
        uint8_t *copy = malloc(b.size);
        static const uint32_t lies[] = {0xffffffffu, PROTO_MAX_CHUNK + 1, PROTO_MAX_ASSETS + 1, 0x10000};
        for (size_t off = 8; off + 4 <= b.size; off++)
            for (size_t k = 0; k < sizeof lies / sizeof lies[0]; k++) {
                memcpy(copy, b.data, b.size);
                put32(copy + off, lies[k]);
                send_malformed(copy, b.size);
            }
        free(copy);
    }
    /* random mutations (flipped bytes, cuts, junk tails) of every type; only those that
     * do not decode are sent */
    for (uint32_t i = 0; i < 600; i++) {
        encode_sample((enum proto_type)(MSG_HELLO + i % (MSG_TYPE_MAX_ - 1)), job.job_id, i % 7, &b);
        size_t n = b.size;
        uint8_t *copy = malloc(n + 16);
        memcpy(copy, b.data, n);
        uint32_t kind = rnd() % 3, flips = 1 + rnd() % 3;
        if (kind == 0)
            for (uint32_t k = 0; k < flips; k++)
                copy[rnd() % n] ^= (uint8_t)(1u << (rnd() % 8));
        else if (kind == 1)
            n = 8 + rnd() % (n - 8 + 1);
        else
            for (uint32_t k = 0, extra = 1 + rnd() % 16; k < extra; k++)
                copy[n++] = (uint8_t)rnd();
        send_malformed(copy, n);
        free(copy);
    }
    /* random bytes */
    for (uint32_t i = 0; i < 50; i++) {
        uint8_t junk[300];
        size_t n = rnd() % sizeof junk;
        for (size_t k = 0; k < n; k++)
            junk[k] = (uint8_t)rnd();
        send_malformed(junk, n);
    }

    /* ---- well-formed but out of order or for the wrong ids ---- */
    for (uint32_t v = 0; v < 5; v++) { /* a second HELLO */
        sample(MSG_HELLO, 0, v, &m);
        send_msg(&m, EX_UNEXPECTED);
    }
    for (uint32_t v = 0; v < 12; v++) { /* what only a master sends */
        sample(v % 4 == 0 ? MSG_TILE : v % 4 == 1 ? MSG_JOB : v % 4 == 2 ? MSG_BLOB_DATA : MSG_ACK, job.job_id, v, &m);
        send_msg(&m, EX_UNEXPECTED);
    }
    for (uint32_t v = 0; v < 10; v++) { /* READY for another job */
        sample(MSG_READY, job.job_id + 1000 + v, 0, &m);
        send_msg(&m, EX_WRONG_JOB);
    }
    for (uint32_t v = 0; v < 10; v++) { /* BLOB_REQ for unknown hashes, and bad ranges of a real one */
        sample(MSG_BLOB_REQ, 0, 100 + v, &m);
        send_msg(&m, EX_BLOB_REQ);
        if (job.num_assets == 0)
            continue;
        const struct proto_asset *a = &job.assets[v % job.num_assets];
        m.u.blob_req.hash = a->hash;
        m.u.blob_req.offset = a->size + 1 + v;
        m.u.blob_req.length = 1;
        send_msg(&m, EX_BLOB_REQ);
        m.u.blob_req.offset = a->size;
        m.u.blob_req.length = 1 + v;
        send_msg(&m, EX_BLOB_REQ);
    }
    for (uint32_t v = 0; v < 10; v++) { /* RESULTs: foreign job, frame, tile */
        sample(MSG_RESULT, job.job_id ^ (0x40000000ull << v), v % num_tiles, &m);
        send_msg(&m, EX_NOT_OURS);
        sample(MSG_RESULT, job.job_id, v % num_tiles, &m);
        m.u.result.frame = job.frame + 1 + v;
        send_msg(&m, EX_NOT_OURS);
        sample(MSG_RESULT, job.job_id, num_units + v * 977, &m);
        m.u.result.frame = job.frame;
        send_msg(&m, EX_NOT_OURS);
    }
    for (uint32_t v = 0; v < 10; v++) { /* kept tiles of another job (key), frame, job id or tile */
        sample(MSG_KEPT, job.job_id, v % num_tiles, &m);
        m.u.kept.frame = job.frame;
        send_msg(&m, EX_NOT_OURS); /* a key that is not the job's */
        m.u.kept.job_key = job.job_key;
        m.u.kept.frame = job.frame + 1 + v;
        send_msg(&m, EX_NOT_OURS);
        m.u.kept.frame = job.frame;
        m.u.kept.job_id = job.job_id + 1 + v;
        send_msg(&m, EX_NOT_OURS);
        m.u.kept.job_id = job.job_id;
        m.u.kept.tile = num_units + v * 977;
        send_msg(&m, EX_NOT_OURS);
    }
    for (uint32_t v = 0; v < 10; v++) { /* a RESULT for a tile never given to us (attempt 0: never issued) */
        sample(MSG_RESULT, job.job_id, v % num_tiles, &m);
        m.u.result.frame = job.frame;
        m.u.result.attempt = 0;
        send_msg(&m, EX_STALE);
    }
    /* Leave: the master reads in order, so once it logs our BYE it has judged every frame. */
    sample(MSG_BYE, 0, 0, &m);
    struct proto_buf bye = {0};
    proto_encode(&m, &bye);
    send_raw(bye.data, bye.size);
    g_sent--; /* the BYE is not part of the corpus */
    proto_buf_fini(&bye);
    zmq_close(g_sock);

    /* One frame over ZMQ_MAXMSGSIZE on a connection of its own: libzmq drops it (and the
     * connection) before the master's code sees anything. */
    void *big = zmq_socket(ctx, ZMQ_DEALER);
    int big_linger = 1000;
    zmq_setsockopt(big, ZMQ_LINGER, &big_linger, sizeof big_linger);
    zmq_connect(big, argv[1]);
    size_t big_size = (size_t)PROTO_MAX_MESSAGE + 1;
    uint8_t *huge = calloc(1, big_size);
    if (huge) {
        zmq_send(big, huge, big_size, 0);
        free(huge);
    }
    zmq_close(big);
    zmq_ctx_term(ctx);

    unsigned long long total = 0;
    for (int e = 0; e < EX_COUNT_; e++) {
        printf("replay: expect %s %llu\n", k_counter[e], g_expect[e]);
        total += g_expect[e];
    }
    printf("replay: sent %llu messages, %llu to be rejected (plus 1 frame over ZMQ_MAXMSGSIZE)\n", g_sent, total);
    proto_job_fini(&job);
    proto_buf_fini(&b);
    return total == g_sent ? 0 : 1;
}
