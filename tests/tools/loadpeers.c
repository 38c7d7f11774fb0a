/* loadpeers: N fake workers in one process, built from the real protocol code, against a
 * real master over loopback, to measure what one master can serve (docs/cluster.md).
 *   loadpeers ENDPOINT [-n N] [--credits C] [--key KEYFILE MASTER.pub] [--image REF.exr]
 *                      [--master-pid PID] [--no-fetch] [--hold-ready] [--timeout-ms MS]
 *                      [--no-bcast] [--drop-bcast K] [--corrupt-bcast K] [--strangers]
 *                      [--pause-ms MS] [--tiny-queue] [--flood-at-end N MS]
 * Each fake worker says HELLO (host "loadpeers-PID", pid = its index: distinct names;
 * threads: C / 2 rounded up, as a worker that asks 2 credits per thread; C at most 4096),
 * fetches every blob the JOB and MAP messages name as a worker does (proto_fetch: the
 * chunk list, the master's broadcast on a SUB socket of its own, BLOB_REQ for the rest;
 * every chunk checked against the list, the blob's hash at the end; none with
 * --no-fetch; point to point only with --no-bcast; fake worker 0 drops, or flips a byte
 * of, every K-th broadcast chunk it receives with --drop-bcast / --corrupt-bcast; with
 * --strangers two more SUB sockets subscribe to everything on the broadcast as soon as its
 * endpoint is known, one without CurveZMQ and one with a fresh key pair no allow-list
 * holds, and count what reaches them), says READY with C credits (with --hold-ready
 * only once every peer has its blobs: a delivery benchmark; with --pause-ms, reads nothing
 * for MS ms after its first READY, with --tiny-queue takes 1 message
 * into its queue and a few KB into its socket buffer: a worker that reads slowly; with
 * --flood-at-end, just before the last RESULT of the first job it sends N BLOB_REQs for the
 * first chunk of its largest asset and then reads nothing for MS ms, so that the master's queue for
 * it is full when the next frame's JOB goes out) and answers every TILE at once with a
 * RESULT whose chunk is a valid EXR tile chunk of the job's layout (tile_image_desc),
 * encoded once per tile at first use: pixels from REF.exr (channels R G B A
 * variance.R/G/B; repeated when the job is larger) or, without it, a smooth deterministic pattern
 * with noise. Heartbeats every second keep it alive; BYE ends a peer. At the end it prints
 *   loadpeers: granted G results R acked A acked_twice D unacked U peers P   (units over every job)
 *   loadpeers: fetch N bytes B first_ms F last_ms L   (N peers fetched B bytes in all; the
 *     first and last finished F and L ms after the first JOB arrived)
 *   loadpeers: chunks bcast X p2p Y bad Z fallbacks F   (chunks kept from the broadcast
 *     and point to point, refused by their hash, and fetches whose broadcast went quiet
 *     before they were complete, over every peer)
 *   loadpeers: strangers received N   (with --strangers: frames that reached them)
 *   loadpeers: tiles_before_map N   (TILEs of a pass whose MAP had not arrived: a worker
 *     drops them)
 *   loadpeers: tiles_per_s X over S s
 *   loadpeers: master_cpu_us_per_tile Y loop_cpu_us_per_tile Z
 *     (with --master-pid: user+sys CPU from the first TILE to the last ACK per unit
 *     acknowledged, of the master's whole process and of its main thread, the loop)
 * and exits 0 when every unit of every job (one a frame) was acknowledged, 1 otherwise (timeout). */
#include "base/log.h"
#include "image/imgio.h"
#include "render/tile.h"
#include "scene/scene.h"
#include "wire/blob.h"
#include "wire/net.h"
#include "wire/proto.h"
#include "wire/fetch.h"
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>
#include <zmq.h>

struct fetch { struct proto_fetch pf; int done; };

struct lpeer {
    void *sock;
    void *sub;              /* the master's broadcast, once a CHUNKS names it */
    uint64_t bcast_seen;    /* broadcast chunks received (for --drop-bcast / --corrupt-bcast) */
    uint64_t job_id;
    int have_job, ready_sent, bye;
    struct fetch *fetches;
    uint32_t num_fetches;
    uint64_t job_ms;        /* when its first JOB arrived */
    uint64_t fetch_done_ms; /* when its last blob arrived */
    uint64_t samples_done;
    int fetched;            /* every blob named so far is in */
    uint64_t maps_announced; /* bit p: pass p's MAP arrived (passes 0..63) */
    struct blob_hash asset; /* its JOB's largest asset (have_asset), which --flood-at-end asks for */
    uint64_t asset_size;
    int have_asset;
    uint32_t job_results;   /* RESULTs sent for its current JOB */
    struct msg_tile *unsent; /* TILEs whose RESULT its full queue refused: sent again later, */
    uint32_t unsent_head, num_unsent; /* as a real worker offers its kept tiles again */
    size_t cap_unsent;
};

static struct {
    struct net_key pub, sec, server;
    int curve, no_fetch, hold_ready, no_bcast, strangers;
    void *stranger[2];      /* --strangers: without CurveZMQ; with a key pair nobody allowed */
    uint32_t drop_bcast, corrupt_bcast;
    int tiny_queue;
    uint64_t pause_ms, pause_until; /* --pause-ms: no reads until pause_until (set at the first READY) */
    uint32_t flood;         /* --flood-at-end N MS: N BLOB_REQs, then MS ms without reading (once) */
    uint64_t flood_pause_ms;
    uint32_t flood_sent;
    int flooded;
    uint64_t tiles_before_map;
    const char *endpoint;
    void *ctx;
    uint64_t chunks_bcast, chunks_p2p, chunks_bad, fallbacks, stranger_frames;
    struct lpeer *peers;
    uint32_t num_peers, peers_fetched;
    uint32_t credits;
    const char *image_path;
    float *image;           /* REF.exr pixels, 7 channels */
    uint32_t image_w, image_h;
    struct proto_buf out;
    /* the job's layout (one job at a time: every peer gets the same JOB) */
    uint64_t job_id;
    struct image_desc desc;
    uint32_t num_tiles, spp_per_unit, job_photon_maps;
    struct imgio_encoder *enc;
    uint8_t **chunks;
    size_t *chunk_sizes;
    uint8_t *acked;         /* per unit of the current job: ACKs seen */
    uint32_t num_units;     /* of the current job */
    /* counters; acked_units: of the current job; units_before, acked_before: of the jobs
     * before it (a frame range sends one job per frame) */
    uint64_t granted, results, acked_units, acked_twice, fetch_bytes, units_before, acked_before;
    uint64_t first_tile_ms, last_ack_ms, start_ms;
    long master_pid;
    double master_cpu_first[2], master_cpu_last[2]; /* process, main thread */
} g;

/* CPU seconds (user + system) of the master's process (thread 0: all threads) or of its
 * main thread (the loop: thread 1), from /proc. */
static double master_cpu(int main_thread)
{
    char path[96], buf[1024];
    if (main_thread)
        snprintf(path, sizeof path, "/proc/%ld/task/%ld/stat", g.master_pid, g.master_pid);
    else
        snprintf(path, sizeof path, "/proc/%ld/stat", g.master_pid);
    FILE *f = fopen(path, "r");
    if (!f)
        return -1.0;
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = '\0';
    const char *p = strrchr(buf, ')'); /* the command name may hold spaces */
    unsigned long long ut = 0, st = 0;
    if (!p || sscanf(p + 2, "%*c %*d %*d %*d %*d %*d %*u %*u %*u %*u %*u %llu %llu", &ut, &st) != 2)
        return -1.0;
    return (double)(ut + st) / (double)sysconf(_SC_CLK_TCK);
}

/* 0 when queued; -1 when the socket's queue is full (or the message cannot be encoded). */
static int send_msg(struct lpeer *p, const struct proto_msg *m)
{
    return proto_encode(m, &g.out) == 0 && zmq_send(p->sock, g.out.data, g.out.size, ZMQ_DONTWAIT) >= 0 ? 0 : -1;
}

/* A pixel of the synthetic pattern: smooth shading plus hashed noise, so that chunks
 * compress about as a rendered tile does rather than as a constant. */
static void pattern_pixel(uint32_t x, uint32_t y, float *px)
{
    uint32_t h = x * 73856093u ^ y * 19349663u;
    h ^= h >> 13;
    h *= 0x5bd1e995u;
    h ^= h >> 15;
    float noise = (float)(h & 0xffff) / 65535.0f;
    float base = 0.3f + 0.2f * (float)((x / 37 + y / 53) % 3);
    px[CH_R] = base * (0.8f + 0.4f * noise);
    px[CH_G] = base * (0.7f + 0.5f * noise);
    px[CH_B] = base * (0.9f + 0.2f * noise);
    px[CH_A] = 1.0f;
    px[CH_VAR_R] = px[CH_VAR_G] = px[CH_VAR_B] = 1e-4f * noise;
}

/* The chunk of tile t, encoded at its first use. */
static int tile_chunk(uint32_t t, const uint8_t **chunk, size_t *size)
{
    if (!g.chunks[t]) {
        uint32_t tiles_x = imgio_tiles_x(&g.desc), tx = t % tiles_x, ty = t / tiles_x, x0, y0, w, h;
        imgio_tile_rect(&g.desc, tx, ty, &x0, &y0, &w, &h);
        float *px = mem_alloc(sizeof(float) * w * h * TILE_NUM_CHANNELS);
        for (uint32_t y = 0; y < h; y++)
            for (uint32_t x = 0; x < w; x++) {
                float *d = &px[((size_t)y * w + x) * TILE_NUM_CHANNELS];
                if (g.image)
                    memcpy(d, &g.image[((size_t)((y0 + y) % g.image_h) * g.image_w + (x0 + x) % g.image_w) * TILE_NUM_CHANNELS],
                           sizeof(float) * TILE_NUM_CHANNELS);
                else
                    pattern_pixel(x0 + x, y0 + y, d);
            }
        char err[256];
        int rc = imgio_encode_tile(g.enc, tx, ty, px, &g.chunks[t], &g.chunk_sizes[t], err, sizeof err);
        free(px);
        if (rc != 0) {
            fprintf(stderr, "loadpeers: tile %u: %s\n", t, err);
            return -1;
        }
    }
    *chunk = g.chunks[t];
    *size = g.chunk_sizes[t];
    return 0;
}

/* The layout of the job's chunks, once per job id. */
static int job_layout(const struct msg_job *j)
{
    if (g.enc && g.job_id == j->job_id)
        return 0;
    if (j->aovs) {
        fprintf(stderr, "loadpeers: jobs with AOVs are not supported\n");
        return -1;
    }
    for (uint32_t t = 0; g.chunks && t < g.num_tiles; t++)
        free(g.chunks[t]);
    free(g.chunks);
    free(g.chunk_sizes);
    free(g.acked);
    imgio_encoder_free(&g.enc);
    g.units_before += g.num_units;
    g.acked_before += g.acked_units;
    g.num_units = 0;
    g.acked_units = 0;
    struct render_settings rs = {.width = j->width, .height = j->height, .spp = j->spp, .tile_size = j->tile_size};
    tile_image_desc(&g.desc, &rs);
    char err[256];
    if (!(g.enc = imgio_encoder_new(&g.desc, err, sizeof err))) {
        fprintf(stderr, "loadpeers: %s\n", err);
        return -1;
    }
    uint32_t passes = j->passes > 1 ? j->passes : 1;
    g.job_id = j->job_id;
    g.num_tiles = imgio_tiles_x(&g.desc) * imgio_tiles_y(&g.desc);
    g.num_units = g.num_tiles * passes;
    g.spp_per_unit = j->spp / passes;
    g.chunks = mem_calloc(g.num_tiles, sizeof *g.chunks);
    g.chunk_sizes = mem_calloc(g.num_tiles, sizeof *g.chunk_sizes);
    g.acked = mem_calloc(g.num_units, 1);
    return 0;
}

static void fetch_add(struct lpeer *p, const struct blob_hash *hash, uint64_t size)
{
    for (uint32_t i = 0; i < p->num_fetches; i++)
        if (blob_hash_equal(&p->fetches[i].pf.recv.hash, hash))
            return;
    p->fetches = mem_realloc(p->fetches, sizeof *p->fetches * (p->num_fetches + 1));
    struct fetch *f = &p->fetches[p->num_fetches++];
    memset(f, 0, sizeof *f);
    char err[256];
    struct proto_msg req;
    if (proto_fetch_start(&f->pf, hash, size, &req, err, sizeof err) != 0) {
        fprintf(stderr, "loadpeers: %s\n", err);
        exit(1);
    }
    if (size == 0) {
        proto_fetch_fini(&f->pf);
        f->done = 1;
        return;
    }
    send_msg(p, &req);
    proto_fetch_list_sent(&f->pf, net_now_ms());
}

static struct fetch *fetch_find(struct lpeer *p, const struct blob_hash *hash)
{
    for (uint32_t i = 0; i < p->num_fetches; i++)
        if (!p->fetches[i].done && blob_hash_equal(&p->fetches[i].pf.recv.hash, hash))
            return &p->fetches[i];
    return NULL;
}

/* CHUNKS: the list, and the broadcast (this peer's SUB socket, as the worker's). */
static void on_chunks(struct lpeer *p, const struct msg_chunks *c)
{
    struct fetch *f = fetch_find(p, &c->hash);
    if (!f)
        return;
    char err[256], ep[600];
    int rc = proto_fetch_on_chunks(&f->pf, c, net_now_ms(), err, sizeof err);
    if (rc < 0)
        fprintf(stderr, "loadpeers: %s\n", err);
    if (rc <= 0)
        return;
    if (g.no_bcast || net_bcast_endpoint(g.endpoint, c->bcast_port, ep, sizeof ep) != 0 ||
        (!strncmp(ep, "tcp://", 6) && c->bcast_port == 0)) {
        f->pf.phase = FETCH_P2P;
        return;
    }
    if (!p->sub) {
        p->sub = zmq_socket(g.ctx, ZMQ_SUB);
        net_socket_setup(p->sub);
        int hwm = 64; /* as the worker's */
        zmq_setsockopt(p->sub, ZMQ_RCVHWM, &hwm, sizeof hwm);
        if ((g.curve && net_curve_client(p->sub, &g.server, &g.pub, &g.sec) != 0) || zmq_connect(p->sub, ep) != 0) {
            fprintf(stderr, "loadpeers: cannot connect to the broadcast at %s: %s\n", ep, zmq_strerror(zmq_errno()));
            exit(1);
        }
    }
    zmq_setsockopt(p->sub, ZMQ_SUBSCRIBE, c->hash.bytes, BLOB_HASH_SIZE);
    for (int k = 0; g.strangers && k < 2 && !g.stranger[k]; k++) {
        void *st = g.stranger[k] = zmq_socket(g.ctx, ZMQ_SUB);
        net_socket_setup(st);
        if (k == 1 && g.curve) {
            struct net_key pub, sec;
            if (zmq_curve_keypair(pub.z85, sec.z85) != 0 || net_curve_client(st, &g.server, &pub, &sec) != 0)
                exit(1);
        }
        zmq_setsockopt(st, ZMQ_SUBSCRIBE, "", 0);
        zmq_connect(st, ep);
    }
}

/* Requests chunks of unfinished fetches; READY once every blob is in. */
static void fetch_pump(struct lpeer *p)
{
    int pending = 0;
    for (uint32_t i = 0; i < p->num_fetches; i++) {
        struct fetch *f = &p->fetches[i];
        if (f->done)
            continue;
        pending = 1;
        struct proto_msg m;
        int rc, was_bcast = f->pf.phase == FETCH_BCAST;
        if (proto_fetch_list_due(&f->pf, net_now_ms())) { /* unanswered for PROTO_FETCH_STALL_MS */
            proto_fetch_list_req(&f->pf, &m);
            send_msg(p, &m);
            proto_fetch_list_sent(&f->pf, net_now_ms());
        }
        while ((rc = proto_fetch_next_req(&f->pf, net_now_ms(), &m)) > 0)
            send_msg(p, &m);
        if (was_bcast && f->pf.phase == FETCH_P2P) {
            g.fallbacks++;
            if (g.fallbacks <= 3)
                fprintf(stderr, "loadpeers: peer %u: the broadcast went quiet for %d ms with %" PRIu64 " of %" PRIu64
                        " chunks in; the rest point to point\n", (unsigned)(p - g.peers), PROTO_BCAST_IDLE_MS,
                        f->pf.recv.chunks_have, f->pf.recv.num_chunks);
        }
        if (rc < 0) {
            fprintf(stderr, "loadpeers: a blob's chunks stayed bad after %d requests\n", PROTO_FETCH_MAX_ROUNDS);
            exit(1);
        }
    }
    if (pending || !p->have_job || p->ready_sent)
        return;
    if (!p->fetched) {
        p->fetched = 1;
        g.peers_fetched++;
    }
    /* --hold-ready: nobody renders before every peer has the blobs (a delivery benchmark:
     * the frame must not end before the last fetch does) */
    if (g.hold_ready && g.peers_fetched < g.num_peers)
        return;
    for (uint32_t i = 0; i < g.num_peers; i++) {
        struct lpeer *q = g.hold_ready ? &g.peers[i] : p;
        if (q->ready_sent || !q->fetched)
            continue;
        struct proto_msg m = {.type = MSG_READY};
        m.u.ready.job_id = q->job_id;
        m.u.ready.credits = g.credits;
        send_msg(q, &m);
        q->ready_sent = 1;
        if (g.pause_ms && !g.pause_until)
            g.pause_until = net_now_ms() + g.pause_ms;
    }
}

static void on_blob_data(struct lpeer *p, const struct msg_blob_data *d, int via_bcast)
{
    struct fetch *f = fetch_find(p, &d->hash);
    if (!f)
        return;
    char err[256];
    uint64_t b = f->pf.chunks_bcast, q = f->pf.chunks_p2p;
    if (proto_fetch_on_data(&f->pf, d, via_bcast, net_now_ms(), err, sizeof err) != 0) {
        g.chunks_bad++; /* dropped: fetched again point to point */
        return;
    }
    g.chunks_bcast += f->pf.chunks_bcast - b;
    g.chunks_p2p += f->pf.chunks_p2p - q;
    g.fetch_bytes += d->length;
    if (blob_recv_complete(&f->pf.recv)) {
        uint8_t *data;
        if (blob_recv_finish(&f->pf.recv, &data, err, sizeof err) != 0) {
            fprintf(stderr, "loadpeers: %s\n", err);
            exit(1);
        }
        free(data);
        struct blob_hash h = f->pf.recv.hash;
        proto_fetch_fini(&f->pf);
        f->done = 1;
        if (p->sub)
            zmq_setsockopt(p->sub, ZMQ_UNSUBSCRIBE, h.bytes, BLOB_HASH_SIZE);
        p->fetch_done_ms = net_now_ms();
    }
}

/* A frame off the broadcast: topic (hash) and BLOB_DATA; the fault knobs act on peer 0. */
static void on_bcast(struct lpeer *p, const struct net_frame *fr)
{
    struct proto_msg m;
    char err[256];
    if (proto_fetch_decode_bcast(fr->id, fr->id_len, fr->data, fr->size, &m, err, sizeof err) != 0) {
        fprintf(stderr, "loadpeers: broadcast message dropped: %s\n", err);
        return;
    }
    p->bcast_seen++;
    if (p == &g.peers[0] && g.drop_bcast && p->bcast_seen % g.drop_bcast == 0)
        return;
    uint8_t *copy = NULL;
    if (p == &g.peers[0] && g.corrupt_bcast && p->bcast_seen % g.corrupt_bcast == 0 && m.u.blob_data.length) {
        copy = mem_alloc(m.u.blob_data.length);
        memcpy(copy, m.u.blob_data.bytes, m.u.blob_data.length);
        copy[m.u.blob_data.length / 2] ^= 0x40;
        m.u.blob_data.bytes = copy;
    }
    on_blob_data(p, &m.u.blob_data, 1);
    free(copy);
}

/* The RESULT of TILE t: 0 when queued, -1 when the socket's queue is full (a real worker
 * then keeps the tile and offers it again; so does send_unsent). */
static int answer_tile(struct lpeer *p, const struct msg_tile *t)
{
    struct proto_msg m = {.type = MSG_RESULT};
    struct msg_result *r = &m.u.result;
    r->job_id = t->job_id;
    r->frame = t->frame;
    r->tile = t->tile;
    r->attempt = t->attempt;
    size_t size;
    if (tile_chunk(t->tile % g.num_tiles, &r->chunk, &size) != 0)
        exit(1);
    r->chunk_size = (uint32_t)size;
    uint32_t tiles_x = imgio_tiles_x(&g.desc), tt = t->tile % g.num_tiles, x0, y0, w, h;
    imgio_tile_rect(&g.desc, tt % tiles_x, tt / tiles_x, &x0, &y0, &w, &h);
    r->stats.samples = (uint64_t)w * h * g.spp_per_unit;
    r->stats.rays = r->stats.samples;
    int flood = g.flood && !g.flooded && p->have_asset && p->job_results + 1 == g.num_units;
    if (flood) { /* the first job's last RESULT: the master's queue for this peer filled first */
        struct proto_msg q = {.type = MSG_BLOB_REQ};
        q.u.blob_req.hash = p->asset;
        q.u.blob_req.length = (uint32_t)(p->asset_size < BLOB_CHUNK_SIZE ? p->asset_size : BLOB_CHUNK_SIZE);
        if (!g.flood_sent) /* read nothing from now on: the replies stay queued at the master */
            g.pause_until = net_now_ms() + g.flood_pause_ms;
        while (g.flood_sent < g.flood && send_msg(p, &q) == 0)
            g.flood_sent++;
        if (g.flood_sent < g.flood)
            return -1; /* its own queue is full: the rest (then the RESULT) on the next turns */
        g.flooded = 1;
    }
    if (send_msg(p, &m) != 0)
        return -1;
    p->job_results++;
    if (flood)
        g.pause_until = net_now_ms() + g.flood_pause_ms;
    p->samples_done += r->stats.samples;
    g.results++;
    return 0;
}

static void on_tile(struct lpeer *p, const struct msg_tile *t)
{
    if (t->job_id != g.job_id || t->tile >= g.num_units) {
        fprintf(stderr, "loadpeers: TILE for job %" PRIu64 " unit %u is not of the job\n", t->job_id, t->tile);
        return;
    }
    g.granted++;
    if (g.job_photon_maps && t->pass < 64 && !(p->maps_announced >> t->pass & 1))
        g.tiles_before_map++;
    if (!g.first_tile_ms) {
        g.first_tile_ms = net_now_ms();
        for (int k = 0; g.master_pid && k < 2; k++)
            g.master_cpu_first[k] = master_cpu(k);
    }
    if (p->num_unsent > p->unsent_head || answer_tile(p, t) != 0) { /* in order, after those waiting */
        mem_grow((void **)&p->unsent, &p->cap_unsent, (size_t)p->num_unsent + 1, sizeof *p->unsent);
        p->unsent[p->num_unsent++] = *t;
    }
}

/* The RESULTs its queue refused, again, in order, as far as the queue takes them. */
static void send_unsent(struct lpeer *p)
{
    while (p->unsent_head < p->num_unsent && answer_tile(p, &p->unsent[p->unsent_head]) == 0)
        p->unsent_head++;
    if (p->unsent_head == p->num_unsent)
        p->unsent_head = p->num_unsent = 0;
}

static void on_message(struct lpeer *p, const uint8_t *data, size_t size)
{
    struct proto_msg m;
    char err[256];
    if (proto_decode(data, size, &m, err, sizeof err) != 0) {
        fprintf(stderr, "loadpeers: undecodable message from the master: %s\n", err);
        return;
    }
    switch (m.type) {
    case MSG_JOB:
        if (job_layout(&m.u.job) != 0)
            exit(1);
        p->job_id = m.u.job.job_id;
        if (!p->job_ms)
            p->job_ms = net_now_ms();
        p->have_job = 1;
        p->maps_announced = 0;
        p->job_results = 0;
        p->have_asset = m.u.job.num_assets > 0;
        for (uint32_t i = 0; i < m.u.job.num_assets; i++)
            if (i == 0 || m.u.job.assets[i].size > p->asset_size) {
                p->asset = m.u.job.assets[i].hash;
                p->asset_size = m.u.job.assets[i].size;
            }
        g.job_photon_maps = m.u.job.photon_maps;
        p->ready_sent = 0;
        for (uint32_t i = 0; !g.no_fetch && i < m.u.job.num_assets; i++)
            fetch_add(p, &m.u.job.assets[i].hash, m.u.job.assets[i].size);
        proto_job_fini(&m.u.job);
        break;
    case MSG_MAP:
        if (m.u.map.pass < 64)
            p->maps_announced |= UINT64_C(1) << m.u.map.pass;
        if (!g.no_fetch)
            fetch_add(p, &m.u.map.hash, m.u.map.size);
        break;
    case MSG_BLOB_DATA:
        on_blob_data(p, &m.u.blob_data, 0);
        break;
    case MSG_CHUNKS:
        on_chunks(p, &m.u.chunks);
        break;
    case MSG_TILE:
        on_tile(p, &m.u.tile);
        break;
    case MSG_ACK:
        for (uint32_t i = 0; m.u.ack.job_id == g.job_id && i < m.u.ack.count; i++) {
            uint32_t u = m.u.ack.tiles[i];
            if (u >= g.num_units)
                continue;
            if (g.acked[u]++)
                g.acked_twice++;
            else
                g.acked_units++;
        }
        g.last_ack_ms = net_now_ms();
        for (int k = 0; g.master_pid && k < 2; k++) {
            double c = master_cpu(k);
            if (c >= 0.0)
                g.master_cpu_last[k] = c;
        }
        break;
    case MSG_BYE:
        p->bye = 1;
        break;
    default:
        break;
    }
    fetch_pump(p);
}

static void usage(void)
{
    fprintf(stderr, "usage: loadpeers ENDPOINT [-n N] [--credits C] [--key KEYFILE MASTER.pub] [--image REF.exr]\n"
                    "                 [--master-pid PID] [--no-fetch] [--hold-ready] [--timeout-ms MS]\n"
                    "                 [--no-bcast] [--drop-bcast K] [--corrupt-bcast K] [--strangers] [--pause-ms MS]\n"
                    "                 [--tiny-queue] [--flood-at-end N MS]\n");
    exit(2);
}

int main(int argc, char **argv)
{
    const char *endpoint = NULL;
    uint32_t n = 16;
    uint64_t timeout_ms = 120000;
    g.credits = 2;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-n") && i + 1 < argc)
            n = (uint32_t)strtoul(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--credits") && i + 1 < argc)
            g.credits = (uint32_t)strtoul(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--image") && i + 1 < argc)
            g.image_path = argv[++i];
        else if (!strcmp(argv[i], "--master-pid") && i + 1 < argc)
            g.master_pid = strtol(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--timeout-ms") && i + 1 < argc)
            timeout_ms = strtoull(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--pause-ms") && i + 1 < argc)
            g.pause_ms = strtoull(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--tiny-queue"))
            g.tiny_queue = 1;
        else if (!strcmp(argv[i], "--flood-at-end") && i + 2 < argc) {
            g.flood = (uint32_t)strtoul(argv[++i], NULL, 10);
            g.flood_pause_ms = strtoull(argv[++i], NULL, 10);
        }
        else if (!strcmp(argv[i], "--no-fetch"))
            g.no_fetch = 1;
        else if (!strcmp(argv[i], "--hold-ready"))
            g.hold_ready = 1;
        else if (!strcmp(argv[i], "--no-bcast"))
            g.no_bcast = 1;
        else if (!strcmp(argv[i], "--strangers"))
            g.strangers = 1;
        else if (!strcmp(argv[i], "--drop-bcast") && i + 1 < argc)
            g.drop_bcast = (uint32_t)strtoul(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--corrupt-bcast") && i + 1 < argc)
            g.corrupt_bcast = (uint32_t)strtoul(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--key") && i + 2 < argc) {
            char err[256];
            if (net_key_pair_load(argv[i + 1], &g.pub, &g.sec, err, sizeof err) != 0 ||
                net_key_public_load(argv[i + 2], &g.server, err, sizeof err) != 0) {
                fprintf(stderr, "loadpeers: %s\n", err);
                return 2;
            }
            g.curve = 1;
            i += 2;
        } else if (argv[i][0] != '-' && !endpoint)
            endpoint = argv[i];
        else
            usage();
    }
    if (!endpoint || n == 0 || n > 4096 || g.credits == 0 || g.credits > 4096)
        usage();
    if (g.image_path) {
        char err[256];
        if (imgio_read(g.image_path, tile_channel_names, TILE_NUM_CHANNELS, &g.image, &g.image_w, &g.image_h, err,
                       sizeof err) != 0) {
            fprintf(stderr, "loadpeers: %s\n", err);
            return 1;
        }
    }
    struct rlimit rl;
    if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < rl.rlim_max) { /* a few fds per socket */
        rl.rlim_cur = rl.rlim_max;
        setrlimit(RLIMIT_NOFILE, &rl);
    }
    void *ctx = zmq_ctx_new();
    zmq_ctx_set(ctx, ZMQ_MAX_SOCKETS, 2 * (int)n + 16);
    g.ctx = ctx;
    g.endpoint = endpoint;
    struct lpeer *peers = mem_calloc(n, sizeof *peers);
    g.peers = peers;
    g.num_peers = n;
    zmq_pollitem_t *items = mem_calloc(2 * (size_t)n, sizeof *items);
    char host[64];
    snprintf(host, sizeof host, "loadpeers-%ld", (long)getpid());
    for (uint32_t i = 0; i < n; i++) {
        struct lpeer *p = &peers[i];
        if (!(p->sock = zmq_socket(ctx, ZMQ_DEALER))) {
            fprintf(stderr, "loadpeers: socket %u: %s\n", i, zmq_strerror(zmq_errno()));
            return 1;
        }
        net_socket_setup(p->sock);
        if (g.tiny_queue) {
            int one = 1, buf = 4096;
            zmq_setsockopt(p->sock, ZMQ_RCVHWM, &one, sizeof one);
            zmq_setsockopt(p->sock, ZMQ_RCVBUF, &buf, sizeof buf);
        }
        if (g.curve && net_curve_client(p->sock, &g.server, &g.pub, &g.sec) != 0) {
            fprintf(stderr, "loadpeers: cannot set the CurveZMQ keys\n");
            return 1;
        }
        if (zmq_connect(p->sock, endpoint) != 0) {
            fprintf(stderr, "loadpeers: cannot connect to %s: %s\n", endpoint, zmq_strerror(zmq_errno()));
            return 1;
        }
        struct proto_msg h = {.type = MSG_HELLO};
        h.u.hello.threads = (g.credits + 1) / 2; /* a worker's READY: 2 credits per thread */
        h.u.hello.pid = i;
        snprintf(h.u.hello.host, sizeof h.u.hello.host, "%s", host);
        send_msg(p, &h);
        items[i] = (zmq_pollitem_t){p->sock, 0, ZMQ_POLLIN, 0};
    }
    g.start_ms = net_now_ms();
    uint64_t last_beat = g.start_ms;
    uint32_t byes = 0;
    /* Ends at every peer's BYE, or once every unit is acknowledged and the master has been
     * silent for 1 s (its BYEs may come later, or be lost: it waits at most 1 s for them to go). */
    while (byes < n && net_now_ms() - g.start_ms < timeout_ms &&
           !(g.num_units && g.acked_units == g.num_units && net_now_ms() - g.last_ack_ms > 1000)) {
        /* the DEALERs, then the SUBs connected so far */
        int nsub = 0;
        for (uint32_t i = 0; i < n; i++)
            if (peers[i].sub)
                items[n + nsub++] = (zmq_pollitem_t){peers[i].sub, 0, ZMQ_POLLIN, 0};
        if (g.pause_until && net_now_ms() < g.pause_until) { /* --pause-ms: a worker that reads nothing */
            if (g.flood_sent && !g.flooded) /* --flood-at-end: the rest of the flood, then the RESULT */
                for (uint32_t i = 0; i < n; i++)
                    send_unsent(&peers[i]);
            usleep(10000);
            continue;
        }
        if (zmq_poll(items, (int)n + nsub, 100) < 0)
            continue;
        for (uint32_t i = 0, k = 0; i < n; i++) {
            if (!peers[i].sub)
                continue;
            if (items[n + k++].revents & ZMQ_POLLIN) {
                for (uint32_t j = 0; j < peers[i].num_fetches; j++)
                    proto_fetch_bcast_alive(&peers[i].fetches[j].pf, net_now_ms());
                struct net_frame f;
                int got;
                for (int budget = 8; budget > 0 && (got = net_recv(peers[i].sub, 1, &f)) != 0; budget--) {
                    if (got > 0 && !peers[i].bye)
                        on_bcast(&peers[i], &f);
                    net_frame_fini(&f);
                }
                fetch_pump(&peers[i]);
            }
        }
        for (uint32_t i = 0; i < n; i++) {
            if (!(items[i].revents & ZMQ_POLLIN))
                continue;
            zmq_msg_t msg;
            zmq_msg_init(&msg);
            while (zmq_msg_recv(&msg, peers[i].sock, ZMQ_DONTWAIT) >= 0) {
                if (!peers[i].bye)
                    on_message(&peers[i], zmq_msg_data(&msg), zmq_msg_size(&msg));
                byes += peers[i].bye && items[i].events;
                if (peers[i].bye)
                    items[i].events = 0;
            }
            zmq_msg_close(&msg);
        }
        for (int k = 0; k < 2; k++) { /* what reached the strangers (nothing, if the broadcast is secured) */
            zmq_msg_t sm;
            zmq_msg_init(&sm);
            while (g.stranger[k] && zmq_msg_recv(&sm, g.stranger[k], ZMQ_DONTWAIT) >= 0)
                g.stranger_frames++;
            zmq_msg_close(&sm);
        }
        for (uint32_t i = 0; i < n; i++) /* a broadcast gone quiet: the rest point to point */
            if (!peers[i].bye) {
                fetch_pump(&peers[i]);
                send_unsent(&peers[i]);
            }
        uint64_t now = net_now_ms();
        if (now - last_beat >= 1000) {
            last_beat = now;
            for (uint32_t i = 0; i < n; i++) {
                if (peers[i].bye)
                    continue;
                struct proto_msg hb = {.type = MSG_HEARTBEAT};
                hb.u.heartbeat.job_id = peers[i].job_id;
                hb.u.heartbeat.samples_done = peers[i].samples_done + 1;
                peers[i].samples_done++;
                send_msg(&peers[i], &hb);
            }
        }
    }
    /* Fetch times from the first JOB any peer got (the master has loaded the scene). */
    uint64_t first_fetch = 0, last_fetch = 0, fetched = 0, first_job = UINT64_MAX;
    for (uint32_t i = 0; i < n; i++)
        if (peers[i].job_ms && peers[i].job_ms < first_job)
            first_job = peers[i].job_ms;
    for (uint32_t i = 0; i < n; i++) {
        if (!peers[i].fetch_done_ms)
            continue;
        uint64_t d = peers[i].fetch_done_ms - first_job;
        first_fetch = !fetched || d < first_fetch ? d : first_fetch;
        last_fetch = d > last_fetch ? d : last_fetch;
        fetched++;
    }
    double secs = g.last_ack_ms > g.first_tile_ms ? (double)(g.last_ack_ms - g.first_tile_ms) * 1e-3 : 0.0;
    /* Over every job (frame) the master sent. */
    const uint64_t units = g.units_before + g.num_units, acked = g.acked_before + g.acked_units;
    printf("loadpeers: granted %" PRIu64 " results %" PRIu64 " acked %" PRIu64 " acked_twice %" PRIu64
           " unacked %" PRIu64 " peers %u byes %u\n",
           g.granted, g.results, acked, g.acked_twice, units - acked, n, byes);
    printf("loadpeers: fetch %" PRIu64 " bytes %" PRIu64 " first_ms %" PRIu64 " last_ms %" PRIu64 "\n", fetched,
           g.fetch_bytes, first_fetch, last_fetch);
    printf("loadpeers: chunks bcast %" PRIu64 " p2p %" PRIu64 " bad %" PRIu64 " fallbacks %" PRIu64 "\n",
           g.chunks_bcast, g.chunks_p2p, g.chunks_bad, g.fallbacks);
    if (g.strangers)
        printf("loadpeers: strangers received %" PRIu64 "\n", g.stranger_frames);
    printf("loadpeers: tiles_before_map %" PRIu64 "\n", g.tiles_before_map);
    printf("loadpeers: tiles_per_s %.1f over %.3f s\n", secs > 0.0 ? (double)acked / secs : 0.0, secs);
    if (g.master_pid && acked && g.master_cpu_first[0] >= 0.0 && g.master_cpu_first[1] >= 0.0)
        printf("loadpeers: master_cpu_us_per_tile %.1f loop_cpu_us_per_tile %.1f\n",
               (g.master_cpu_last[0] - g.master_cpu_first[0]) * 1e6 / (double)acked,
               (g.master_cpu_last[1] - g.master_cpu_first[1]) * 1e6 / (double)acked);
    for (uint32_t i = 0; i < n; i++) {
        for (uint32_t k = 0; k < peers[i].num_fetches; k++)
            proto_fetch_fini(&peers[i].fetches[k].pf);
        free(peers[i].fetches);
        free(peers[i].unsent);
        if (peers[i].sub)
            zmq_close(peers[i].sub);
        zmq_close(peers[i].sock);
    }
    for (int k = 0; k < 2; k++)
        if (g.stranger[k])
            zmq_close(g.stranger[k]);
    for (uint32_t t = 0; g.chunks && t < g.num_tiles; t++)
        free(g.chunks[t]);
    free(g.chunks);
    free(g.chunk_sizes);
    free(g.acked);
    free(g.image);
    free(peers);
    free(items);
    imgio_encoder_free(&g.enc);
    proto_buf_fini(&g.out);
    zmq_ctx_term(ctx);
    return units && acked == units ? 0 : 1;
}
