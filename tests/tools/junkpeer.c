/* junkpeer: a misbehaving client for integration tests. Connects a DEALER to a master and
 * sends what a broken or hostile peer might. The master must log and drop all of it.
 *
 *   junkpeer [--key KEYFILE MASTER.pub] ENDPOINT [MODE]
 *
 * --key: authenticate with CurveZMQ (a key pair on the master's allow-list, or not).
 * MODE:
 *   (none)             random bytes, a truncated frame, a frame of another protocol version,
 *                      a multi-frame envelope, and (after a valid HELLO) results for tiles
 *                      it was never given and a request for a blob that does not exist
 *   rogue              HELLO, then with the JOB's job key: KEPT for every unit and RESULT
 *                      for every unit (attempts 1..3), all of pixels 7.0, and a request
 *                      for every asset of the manifest; prints what came back:
 *                        junkpeer: job yes|no, blob bytes N
 *   hello-as HOST PID  a HELLO claiming to be HOST:PID, then silence for 3 s
 *   flood N            N connections, each a HELLO, closed after a moment
 *   error              HELLO, then an ERROR whose text holds a newline, a forged log
 *                      line, terminal escapes and bytes that are not UTF-8
 *   hoard K N S        K connections that take 1 message into their queue and a few KB
 *                      into their socket buffer, each a HELLO, then after the JOB N
 *                      requests for chunks of the manifest's largest asset, then S
 *                      seconds reading nothing; prints
 *                        junkpeer: hoard K connections, N requests each
 */
#include "image/imgio.h"
#include "render/tile.h"
#include "scene/scene.h"
#include "wire/blob.h"
#include "wire/net.h"
#include "wire/proto.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <zmq.h>

static struct net_key g_pub, g_sec, g_server;
static int g_curve, g_tiny_queue;

static void *peer_socket(void *ctx, const char *endpoint)
{
    void *s = zmq_socket(ctx, ZMQ_DEALER);
    for (int i = 0; !s && i < 500; i++) { /* closed sockets are reaped in the background */
        usleep(10000);
        s = zmq_socket(ctx, ZMQ_DEALER);
    }
    if (!s) {
        fprintf(stderr, "junkpeer: no socket: %s\n", zmq_strerror(zmq_errno()));
        exit(1);
    }
    int linger = 2000;
    zmq_setsockopt(s, ZMQ_LINGER, &linger, sizeof linger);
    if (g_tiny_queue) {
        int one = 1, buf = 4096;
        zmq_setsockopt(s, ZMQ_RCVHWM, &one, sizeof one);
        zmq_setsockopt(s, ZMQ_RCVBUF, &buf, sizeof buf);
    }
    if (g_curve && net_curve_client(s, &g_server, &g_pub, &g_sec) != 0) {
        fprintf(stderr, "junkpeer: cannot set the CurveZMQ keys\n");
        exit(1);
    }
    if (zmq_connect(s, endpoint) != 0) {
        fprintf(stderr, "junkpeer: cannot connect to %s\n", endpoint);
        exit(1);
    }
    return s;
}

static void send_msg(void *s, const struct proto_msg *m, struct proto_buf *b)
{
    if (proto_encode(m, b) == 0)
        zmq_send(s, b->data, b->size, ZMQ_DONTWAIT); /* no connection (refused): dropped */
}

static void send_hello(void *s, const char *host, uint32_t pid, struct proto_buf *b)
{
    struct proto_msg m = {.type = MSG_HELLO};
    m.u.hello.threads = 1;
    m.u.hello.pid = pid;
    snprintf(m.u.hello.host, sizeof m.u.hello.host, "%s", host);
    send_msg(s, &m, b);
}

/* Waits up to ms for one message; 1 with it decoded into *m (a JOB owns its assets). */
static int recv_msg(void *s, int ms, struct proto_msg *m, struct net_payload **frame)
{
    zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
    if (zmq_poll(&it, 1, ms) <= 0)
        return 0;
    struct net_frame f;
    if (net_recv(s, 0, &f) != 1)
        return 0;
    char err[256];
    if (proto_decode(f.data, f.size, m, err, sizeof err) != 0) {
        net_frame_fini(&f);
        return 0;
    }
    *frame = net_frame_take(&f);
    return 1;
}

static void junk(void *s, struct proto_buf *b)
{
    uint8_t bytes[512];
    srand(1);
    for (size_t i = 0; i < sizeof bytes; i++)
        bytes[i] = (uint8_t)rand();
    zmq_send(s, bytes, sizeof bytes, 0);                /* random bytes */
    zmq_send(s, "", 0, 0);                              /* empty frame */
    zmq_send(s, bytes, 10, ZMQ_SNDMORE);                /* multi-frame envelope */
    zmq_send(s, bytes, 10, 0);

    struct proto_msg m = {.type = MSG_HELLO};
    m.u.hello.threads = 1;
    m.u.hello.pid = 1;
    snprintf(m.u.hello.host, sizeof m.u.hello.host, "junk\x01peer");
    proto_encode(&m, b);
    zmq_send(s, b->data, b->size - 3, 0);               /* truncated HELLO */
    b->data[4] = 99;                                    /* another protocol version */
    zmq_send(s, b->data, b->size, 0);
    b->data[4] = PROTO_VERSION & 0xff;
    zmq_send(s, b->data, b->size, 0);                   /* a valid HELLO: now a known peer */
    usleep(200000);

    static uint8_t chunk[4096];
    for (uint32_t tile = 0; tile < 64; tile++) {        /* results for tiles never assigned */
        struct proto_msg r = {.type = MSG_RESULT};
        r.u.result.job_id = tile;                       /* wrong job ids */
        r.u.result.tile = tile;
        r.u.result.attempt = 1;
        r.u.result.chunk = chunk;
        r.u.result.chunk_size = sizeof chunk;
        send_msg(s, &r, b);
    }
    struct proto_msg q = {.type = MSG_BLOB_REQ};        /* a blob that does not exist */
    q.u.blob_req.length = 100;
    send_msg(s, &q, b);
}

/* An authenticated (or not) peer that tries to poison the image and read the scene. */
static int rogue(void *s, struct proto_buf *b)
{
    send_hello(s, "rogue", 4242, b);
    struct proto_msg job;
    struct net_payload *frame = NULL;
    int have_job = 0;
    for (int i = 0; i < 20 && !have_job; i++) {
        if (!recv_msg(s, 100, &job, &frame))
            continue;
        have_job = job.type == MSG_JOB;
        if (!have_job)
            net_payload_free(&frame);
    }
    uint64_t blob_bytes = 0;
    if (have_job) {
        struct render_settings rs;
        memset(&rs, 0, sizeof rs);
        rs.width = job.u.job.width;
        rs.height = job.u.job.height;
        rs.tile_size = job.u.job.tile_size;
        struct image_desc desc;
        tile_image_desc(&desc, &rs);
        char err[256];
        struct imgio_encoder *enc = imgio_encoder_new(&desc, err, sizeof err);
        uint32_t tx = imgio_tiles_x(&desc), ntiles = tx * imgio_tiles_y(&desc);
        uint32_t units = ntiles * (job.u.job.passes > 1 ? job.u.job.passes : 1);
        float *px = malloc(sizeof(float) * rs.tile_size * rs.tile_size * TILE_NUM_CHANNELS);
        for (size_t i = 0; i < (size_t)rs.tile_size * rs.tile_size * TILE_NUM_CHANNELS; i++)
            px[i] = 7.0f;
        for (uint32_t u = 0; u < units && enc; u++) {
            uint8_t *chunk = NULL;
            size_t size = 0;
            if (imgio_encode_tile(enc, (u % ntiles) % tx, (u % ntiles) / tx, px, &chunk, &size, err, sizeof err) != 0)
                break;
            struct proto_msg k = {.type = MSG_KEPT};
            k.u.kept.job_id = job.u.job.job_id;
            k.u.kept.job_key = job.u.job.job_key;
            k.u.kept.frame = job.u.job.frame;
            k.u.kept.tile = u;
            k.u.kept.chunk = chunk;
            k.u.kept.chunk_size = (uint32_t)size;
            send_msg(s, &k, b);
            for (uint32_t a = 1; a <= 3; a++) {
                struct proto_msg r = {.type = MSG_RESULT};
                r.u.result.job_id = job.u.job.job_id;
                r.u.result.frame = job.u.job.frame;
                r.u.result.tile = u;
                r.u.result.attempt = a;
                r.u.result.chunk = chunk;
                r.u.result.chunk_size = (uint32_t)size;
                send_msg(s, &r, b);
            }
            free(chunk);
        }
        free(px);
        imgio_encoder_free(&enc);
        for (uint32_t i = 0; i < job.u.job.num_assets; i++) {
            struct proto_msg q = {.type = MSG_BLOB_REQ};
            q.u.blob_req.hash = job.u.job.assets[i].hash;
            q.u.blob_req.length = job.u.job.assets[i].size < BLOB_CHUNK_SIZE ? (uint32_t)job.u.job.assets[i].size
                                                                               : BLOB_CHUNK_SIZE;
            send_msg(s, &q, b);
        }
        proto_job_fini(&job.u.job);
        net_payload_free(&frame);
    } else {
        /* Without a JOB there is no job key; ask for blobs blindly all the same. */
        struct proto_msg q = {.type = MSG_BLOB_REQ};
        q.u.blob_req.length = 100;
        send_msg(s, &q, b);
    }
    struct proto_msg m;
    for (int i = 0; i < 10; i++)
        while (recv_msg(s, 100, &m, &frame)) {
            if (m.type == MSG_BLOB_DATA)
                blob_bytes += m.u.blob_data.length;
            if (m.type == MSG_JOB)
                proto_job_fini(&m.u.job);
            net_payload_free(&frame);
        }
    printf("junkpeer: job %s, blob bytes %llu\n", have_job ? "yes" : "no", (unsigned long long)blob_bytes);
    fflush(stdout);
    return 0;
}

/* hoard: peers that ask for blob chunks and do not read the answers. */
static int hoard(void *ctx, const char *endpoint, long k, long n, long secs, struct proto_buf *b)
{
    g_tiny_queue = 1;
    void **socks = calloc((size_t)k, sizeof *socks);
    for (long c = 0; c < k; c++) {
        socks[c] = peer_socket(ctx, endpoint);
        send_hello(socks[c], "hoard", (uint32_t)c, b);
        struct proto_msg job;
        struct net_payload *frame = NULL;
        int have_job = 0;
        for (int i = 0; i < 50 && !have_job; i++) {
            if (!recv_msg(socks[c], 100, &job, &frame))
                continue;
            have_job = job.type == MSG_JOB;
            if (!have_job)
                net_payload_free(&frame);
        }
        if (!have_job || job.u.job.num_assets == 0) {
            fprintf(stderr, "junkpeer: no JOB with assets\n");
            return 1;
        }
        const struct proto_asset *big = &job.u.job.assets[0];
        for (uint32_t i = 1; i < job.u.job.num_assets; i++)
            if (job.u.job.assets[i].size > big->size)
                big = &job.u.job.assets[i];
        uint64_t chunks = (big->size + BLOB_CHUNK_SIZE - 1) / BLOB_CHUNK_SIZE;
        for (long i = 0; i < n; i++) {
            struct proto_msg q = {.type = MSG_BLOB_REQ};
            q.u.blob_req.hash = big->hash;
            q.u.blob_req.offset = (uint64_t)(i % (long)chunks) * BLOB_CHUNK_SIZE;
            uint64_t left = big->size - q.u.blob_req.offset;
            q.u.blob_req.length = left < BLOB_CHUNK_SIZE ? (uint32_t)left : BLOB_CHUNK_SIZE;
            if (proto_encode(&q, b) == 0)
                zmq_send(socks[c], b->data, b->size, 0);
        }
        proto_job_fini(&job.u.job);
        net_payload_free(&frame);
    }
    printf("junkpeer: hoard %ld connections, %ld requests each\n", k, n);
    fflush(stdout);
    sleep((unsigned)secs);
    for (long c = 0; c < k; c++) {
        int linger = 0;
        zmq_setsockopt(socks[c], ZMQ_LINGER, &linger, sizeof linger);
        zmq_close(socks[c]);
    }
    free(socks);
    return 0;
}

int main(int argc, char **argv)
{
    int a = 1;
    if (argc > 4 && !strcmp(argv[1], "--key")) {
        char err[512];
        if (net_key_pair_load(argv[2], &g_pub, &g_sec, err, sizeof err) != 0 ||
            net_key_public_load(argv[3], &g_server, err, sizeof err) != 0) {
            fprintf(stderr, "junkpeer: %s\n", err);
            return 2;
        }
        g_curve = 1;
        a = 4;
    }
    if (argc < a + 1) {
        fprintf(stderr, "usage: junkpeer [--key KEYFILE MASTER.pub] ENDPOINT [rogue | hello-as HOST PID | flood N | error | hoard K N S]\n");
        return 2;
    }
    const char *endpoint = argv[a], *mode = argc > a + 1 ? argv[a + 1] : "";
    void *ctx = zmq_ctx_new();
    zmq_ctx_set(ctx, ZMQ_MAX_SOCKETS, 8192);
    struct proto_buf b = {0};
    int rc = 0;
    if (!strcmp(mode, "hoard") && argc > a + 4) {
        rc = hoard(ctx, endpoint, atol(argv[a + 2]), atol(argv[a + 3]), atol(argv[a + 4]), &b);
    } else if (!strcmp(mode, "flood") && argc > a + 2) {
        /* Many connections, each with a HELLO; a few hundred open at once. */
        long n = atol(argv[a + 2]);
        enum { OPEN = 200 };
        void *open_socks[OPEN] = {0};
        for (long i = 0; i < n; i++) {
            void *s = peer_socket(ctx, endpoint);
            char host[32];
            snprintf(host, sizeof host, "flood%ld", i);
            send_hello(s, host, (uint32_t)i, &b);
            if (open_socks[i % OPEN]) {
                /* closed once the master answered (its JOB) or refused: the HELLO was read */
                zmq_pollitem_t it = {open_socks[i % OPEN], 0, ZMQ_POLLIN, 0};
                zmq_poll(&it, 1, 1000);
                int linger = 0;
                zmq_setsockopt(open_socks[i % OPEN], ZMQ_LINGER, &linger, sizeof linger);
                zmq_close(open_socks[i % OPEN]);
            }
            open_socks[i % OPEN] = s;
        }
        usleep(500000);
        for (int i = 0; i < OPEN; i++)
            if (open_socks[i])
                zmq_close(open_socks[i]);
        printf("junkpeer: %ld hellos sent\n", n);
    } else {
        void *s = peer_socket(ctx, endpoint);
        if (!strcmp(mode, "rogue")) {
            rc = rogue(s, &b);
        } else if (!strcmp(mode, "error")) {
            send_hello(s, "liar", 4243, &b);
            usleep(300000);
            struct proto_msg e = {.type = MSG_ERROR};
            snprintf(e.u.error.text, sizeof e.u.error.text,
                     "bad\nbrume: info: forged line\x1b[2J\x7f\xff\xfe end");
            send_msg(s, &e, &b);
            usleep(300000);
        } else if (!strcmp(mode, "hello-as") && argc > a + 3) {
            send_hello(s, argv[a + 2], (uint32_t)strtoul(argv[a + 3], NULL, 10), &b);
            sleep(3);
        } else if (!mode[0]) {
            junk(s, &b);
        } else {
            fprintf(stderr, "junkpeer: unknown mode \"%s\"\n", mode);
            rc = 2;
        }
        if (!mode[0] || !strcmp(mode, "rogue")) {
            struct proto_msg bye = {.type = MSG_BYE};
            send_msg(s, &bye, &b);
        }
        zmq_close(s);
    }
    proto_buf_fini(&b);
    zmq_ctx_term(ctx);
    return rc;
}
