/* Master loop (see master.h). One thread: zmq_poll on the ROUTER socket drives
 * everything (hello, blob serving, credits, tile assignment, results, liveness), so no
 * state is shared between threads. A result is accepted only from the peer holding the
 * tile's current attempt, only once, and only after its chunk decodes to finite pixels
 * of the right size; anything else is counted and dropped. */
#include "master.h"
#include "asset.h"
#include "blob.h"
#include "imgio.h"
#include "launch.h"
#include "log.h"
#include "net.h"
#include "proto.h"
#include "scene_json.h"
#include "tile.h"
#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zmq.h>

#define MAX_PEERS 4096
#define PROGRESS_PLAIN_MS 5000
#define PROGRESS_TTY_MS 250

enum tile_state { TILE_QUEUED, TILE_ASSIGNED, TILE_DONE };

struct tile_slot {
    enum tile_state state;
    uint32_t attempt;
    int32_t peer;
    uint8_t *chunk;
    size_t chunk_size;
};

struct peer {
    uint8_t id[NET_MAX_IDENTITY];
    size_t id_len;
    char name[300];         /* host:pid for messages */
    uint32_t pid, threads;
    int ready, gone;
    uint32_t credits;
    uint64_t last_heard_ms;
    uint32_t tiles_done;
    uint32_t dropped;       /* messages of this peer dropped; only the first few are logged */
};

struct master {
    const struct master_opts *opts;
    void *zctx, *sock;
    struct proto_buf out;
    struct asset_dir assets;
    struct blob_store blobs;
    struct proto_asset *manifest;
    uint32_t num_manifest;
    char scene_rel[ASSET_PATH_MAX];
    char scene_hash[65];
    struct scene scene;
    struct image_desc desc;
    uint64_t job_id;
    struct tile_slot *tiles;
    uint32_t num_tiles, tiles_done;
    uint32_t *queue;            /* FIFO of tile indices waiting for a worker */
    uint32_t q_head, q_count;
    struct peer *peers;
    uint32_t num_peers;
    pid_t *local_pids;
    uint32_t num_local, local_alive;
    struct tile_stats stats;
    uint64_t dropped_results;
    char last_worker_error[PROTO_MAX_STRING];
    float *decode_scratch;
    char ipc_dir[256];
    char ipc_endpoint[320];
};

static volatile sig_atomic_t g_interrupted;
static void on_signal(int sig) { (void)sig; g_interrupted = 1; }

static void queue_push(struct master *m, uint32_t tile)
{
    m->queue[(m->q_head + m->q_count) % m->num_tiles] = tile;
    m->q_count++;
}

static uint32_t queue_pop(struct master *m)
{
    uint32_t t = m->queue[m->q_head];
    m->q_head = (m->q_head + 1) % m->num_tiles;
    m->q_count--;
    return t;
}

/* ---- setup ---- */

static int load_scene(struct master *m)
{
    const struct master_opts *o = m->opts;
    char err[1024];
    char dir_buf[4096], base_buf[4096];
    snprintf(dir_buf, sizeof dir_buf, "%s", o->scene_path);
    snprintf(base_buf, sizeof base_buf, "%s", o->scene_path);
    const char *dir = dirname(dir_buf);
    snprintf(m->scene_rel, sizeof m->scene_rel, "%s", basename(base_buf));
    if (asset_dir_init(&m->assets, dir, err, sizeof err) != 0) {
        log_error("%s", err);
        return -1;
    }
    char *text = NULL;
    size_t len = 0;
    if (asset_dir_read(&m->assets, m->scene_rel, &text, &len, err, sizeof err) != 0) {
        log_error("%s: %s", o->scene_path, err);
        return -1;
    }
    struct asset_source src = asset_dir_source(&m->assets);
    int rc = scene_json_parse(o->scene_path, text, len, &src, &m->scene, err, sizeof err);
    free(text);
    if (rc != 0) {
        log_error("%s", err);
        return -1;
    }
    struct render_settings *rs = &m->scene.settings;
    if (o->have_spp)
        rs->spp = o->spp;
    if (o->have_seed)
        rs->seed = o->seed;
    if (o->have_tile)
        rs->tile_size = o->tile;
    if (o->have_depth)
        rs->max_depth = o->depth;
    if (o->have_sampler)
        rs->sampler = (enum sampler_type)o->sampler;
    if (scene_validate(&m->scene, err, sizeof err) != 0) {
        log_error("%s: %s", o->scene_path, err);
        return -1;
    }
    /* Publish every file the parse read; the scene hash covers names, contents and settings. */
    m->num_manifest = (uint32_t)m->assets.num_files;
    if (m->num_manifest > PROTO_MAX_ASSETS) {
        log_error("%s: %u files, more than the %u a job can carry", o->scene_path, m->num_manifest, PROTO_MAX_ASSETS);
        return -1;
    }
    m->manifest = mem_calloc(m->num_manifest, sizeof *m->manifest);
    struct proto_buf h = {0};
    for (uint32_t i = 0; i < m->num_manifest; i++) {
        const struct asset_file *f = &m->assets.files[i];
        const struct blob_entry *e = blob_store_put(&m->blobs, f->data, f->size);
        snprintf(m->manifest[i].path, sizeof m->manifest[i].path, "%s", f->path);
        m->manifest[i].hash = e->hash;
        m->manifest[i].size = f->size;
        size_t pl = strlen(f->path) + 1;
        mem_grow((void **)&h.data, &h.cap, h.size + pl + BLOB_HASH_SIZE, 1);
        memcpy(h.data + h.size, f->path, pl);
        memcpy(h.data + h.size + pl, e->hash.bytes, BLOB_HASH_SIZE);
        h.size += pl + BLOB_HASH_SIZE;
    }
    char settings[256];
    int sl = snprintf(settings, sizeof settings, "%ux%u spp=%u depth=%u seed=%llu", rs->width, rs->height, rs->spp,
                      rs->max_depth, (unsigned long long)rs->seed);
    mem_grow((void **)&h.data, &h.cap, h.size + (size_t)sl, 1);
    memcpy(h.data + h.size, settings, (size_t)sl);
    h.size += (size_t)sl;
    struct blob_hash sh;
    blob_hash_compute(h.data, h.size, &sh);
    blob_hash_hex(&sh, m->scene_hash);
    proto_buf_free(&h);
    return 0;
}

static void setup_tiles(struct master *m)
{
    const struct render_settings *rs = &m->scene.settings;
    tile_image_desc(&m->desc, rs);
    m->num_tiles = imgio_tiles_x(&m->desc) * imgio_tiles_y(&m->desc);
    m->tiles = mem_calloc(m->num_tiles, sizeof *m->tiles);
    m->queue = mem_alloc(sizeof(uint32_t) * m->num_tiles);
    for (uint32_t t = 0; t < m->num_tiles; t++) {
        m->tiles[t].peer = -1;
        queue_push(m, t);
    }
    m->decode_scratch = mem_alloc(sizeof(float) * rs->tile_size * rs->tile_size * TILE_NUM_CHANNELS);
}

/* ---- peers ---- */

static int32_t find_peer(const struct master *m, const uint8_t *id, size_t id_len)
{
    for (uint32_t i = 0; i < m->num_peers; i++)
        if (!m->peers[i].gone && m->peers[i].id_len == id_len && memcmp(m->peers[i].id, id, id_len) == 0)
            return (int32_t)i;
    return -1;
}

static void send_to(struct master *m, const struct peer *p, const struct proto_msg *msg)
{
    net_send(m->sock, p->id, p->id_len, msg, &m->out);
}

/* Puts a peer's unfinished tiles back at the head of the queue and forgets the peer. */
static void evict_peer(struct master *m, int32_t pi, const char *why)
{
    struct peer *p = &m->peers[pi];
    if (p->gone)
        return;
    uint32_t requeued = 0;
    for (uint32_t t = 0; t < m->num_tiles; t++)
        if (m->tiles[t].state == TILE_ASSIGNED && m->tiles[t].peer == pi) {
            m->tiles[t].state = TILE_QUEUED;
            m->tiles[t].peer = -1;
            queue_push(m, t);
            requeued++;
        }
    p->gone = 1;
    log_warn("worker %s removed (%s); %u tile(s) re-queued", p->name, why, requeued);
    struct proto_msg bye = {.type = MSG_BYE};
    send_to(m, p, &bye);
}

static void on_hello(struct master *m, const struct net_frame *f, const struct msg_hello *h)
{
    if (find_peer(m, f->id, f->id_len) >= 0)
        return; /* repeated hello: already known */
    if (m->num_peers >= MAX_PEERS) {
        log_warn("too many workers; ignoring hello from %s", h->host);
        return;
    }
    m->peers = mem_realloc(m->peers, sizeof *m->peers * (m->num_peers + 1));
    struct peer *p = &m->peers[m->num_peers];
    memset(p, 0, sizeof *p);
    memcpy(p->id, f->id, f->id_len);
    p->id_len = f->id_len;
    p->pid = h->pid;
    p->threads = h->threads;
    p->last_heard_ms = net_now_ms();
    snprintf(p->name, sizeof p->name, "%.200s:%u", h->host, h->pid);
    for (char *c = p->name; *c; c++) /* peer text goes into our log: keep it printable */
        if (*c < 0x20 || *c == 0x7f)
            *c = '?';
    m->num_peers++;
    log_info("worker %s joined with %u thread(s)", p->name, h->threads);
    const struct render_settings *rs = &m->scene.settings;
    struct proto_msg job = {.type = MSG_JOB};
    struct msg_job *j = &job.u.job;
    j->job_id = m->job_id;
    j->frame = 0;
    j->width = rs->width;
    j->height = rs->height;
    j->spp = rs->spp;
    j->max_depth = rs->max_depth;
    j->tile_size = rs->tile_size;
    j->seed = rs->seed;
    j->sampler = rs->sampler;
    snprintf(j->scene_path, sizeof j->scene_path, "%s", m->scene_rel);
    j->num_assets = m->num_manifest;
    j->assets = m->manifest;
    send_to(m, p, &job);
}

static void on_blob_req(struct master *m, const struct peer *p, const struct msg_blob_req *r)
{
    const struct blob_entry *e = blob_store_get(&m->blobs, &r->hash);
    if (!e || r->offset > e->size || r->length > BLOB_CHUNK_SIZE || r->length > e->size - r->offset) {
        log_warn("worker %s: BLOB_REQ for an unknown blob or range dropped", p->name);
        return;
    }
    struct proto_msg d = {.type = MSG_BLOB_DATA};
    d.u.blob_data.hash = r->hash;
    d.u.blob_data.offset = r->offset;
    d.u.blob_data.total_size = e->size;
    d.u.blob_data.bytes = e->data + r->offset;
    d.u.blob_data.length = r->length;
    send_to(m, p, &d);
}

static int chunk_is_sane(struct master *m, uint32_t tile, const struct msg_result *r, char *err, size_t errlen)
{
    uint32_t tiles_x = imgio_tiles_x(&m->desc);
    uint32_t tx = tile % tiles_x, ty = tile / tiles_x, x0, y0, w, h;
    imgio_tile_rect(&m->desc, tx, ty, &x0, &y0, &w, &h);
    if (imgio_decode_tile(&m->desc, tx, ty, r->chunk, r->chunk_size, m->decode_scratch, err, errlen) != 0)
        return 0;
    for (size_t i = 0; i < (size_t)w * h * TILE_NUM_CHANNELS; i++)
        if (!isfinite(m->decode_scratch[i])) {
            str_fmt(err, errlen, "non-finite pixel value in tile %u", tile);
            return 0;
        }
    return 1;
}

/* Logs a dropped message of a peer; after a few, only counts (a peer cannot flood the log). */
static int peer_should_log_drop(struct peer *p)
{
    p->dropped++;
    if (p->dropped == 6)
        log_warn("worker %s: further dropped messages are counted, not logged", p->name);
    return p->dropped <= 5;
}

static void on_result(struct master *m, int32_t pi, const struct msg_result *r)
{
    struct peer *p = &m->peers[pi];
    if (p->credits < p->threads * 4)
        p->credits++;
    if (r->job_id != m->job_id || r->frame != 0 || r->tile >= m->num_tiles) {
        if (peer_should_log_drop(p))
            log_warn("worker %s: RESULT for job %llu frame %u tile %u is not ours; dropped", p->name,
                     (unsigned long long)r->job_id, r->frame, r->tile);
        m->dropped_results++;
        return;
    }
    struct tile_slot *t = &m->tiles[r->tile];
    if (t->state != TILE_ASSIGNED || t->peer != pi || t->attempt != r->attempt) {
        m->dropped_results++;
        if (peer_should_log_drop(p))
            log_warn("worker %s: result for tile %u attempt %u is stale, duplicate or not assigned to it; dropped",
                     p->name, r->tile, r->attempt);
        return;
    }
    char err[256];
    if (!chunk_is_sane(m, r->tile, r, err, sizeof err)) {
        log_warn("worker %s: tile %u rejected: %s; re-queued", p->name, r->tile, err);
        m->dropped_results++;
        t->state = TILE_QUEUED;
        t->peer = -1;
        queue_push(m, r->tile);
        return;
    }
    t->chunk = mem_alloc(r->chunk_size);
    memcpy(t->chunk, r->chunk, r->chunk_size);
    t->chunk_size = r->chunk_size;
    t->state = TILE_DONE;
    m->tiles_done++;
    p->tiles_done++;
    tile_stats_add(&m->stats, &r->stats);
}

static void assign_tiles(struct master *m)
{
    for (uint32_t i = 0; i < m->num_peers && m->q_count > 0; i++) {
        struct peer *p = &m->peers[i];
        while (!p->gone && p->ready && p->credits > 0 && m->q_count > 0) {
            uint32_t tile = queue_pop(m);
            struct tile_slot *t = &m->tiles[tile];
            t->state = TILE_ASSIGNED;
            t->attempt++;
            t->peer = (int32_t)i;
            p->credits--;
            struct proto_msg msg = {.type = MSG_TILE};
            msg.u.tile.job_id = m->job_id;
            msg.u.tile.frame = 0;
            msg.u.tile.tile = tile;
            msg.u.tile.attempt = t->attempt;
            send_to(m, p, &msg);
        }
    }
}

static void handle_message(struct master *m, struct net_frame *f)
{
    struct proto_msg msg;
    char err[256];
    int32_t pi = find_peer(m, f->id, f->id_len);
    if (proto_decode(f->data, f->size, &msg, err, sizeof err) != 0) {
        if (pi < 0 || peer_should_log_drop(&m->peers[pi]))
            log_warn("message from %s dropped: %s", pi >= 0 ? m->peers[pi].name : "an unknown peer", err);
        return;
    }
    if (msg.type == MSG_HELLO) {
        on_hello(m, f, &msg.u.hello);
        return;
    }
    if (pi < 0) {
        log_debug("%s from an unknown peer dropped", proto_type_name(msg.type));
        if (msg.type == MSG_JOB)
            proto_job_free(&msg.u.job);
        return;
    }
    struct peer *p = &m->peers[pi];
    p->last_heard_ms = net_now_ms();
    switch (msg.type) {
    case MSG_BLOB_REQ:
        on_blob_req(m, p, &msg.u.blob_req);
        break;
    case MSG_READY:
        if (msg.u.ready.job_id == m->job_id) {
            p->ready = 1;
            p->credits = msg.u.ready.credits < p->threads * 4 ? msg.u.ready.credits : p->threads * 4;
            if (p->credits == 0)
                p->credits = 1;
        }
        break;
    case MSG_RESULT:
        on_result(m, pi, &msg.u.result);
        break;
    case MSG_ERROR:
        snprintf(m->last_worker_error, sizeof m->last_worker_error, "%s", msg.u.error.text);
        log_error("worker %s: %s", p->name, msg.u.error.text);
        evict_peer(m, pi, "it reported an error");
        break;
    case MSG_HEARTBEAT:
        break;
    case MSG_BYE:
        evict_peer(m, pi, "it left");
        break;
    default:
        log_warn("worker %s: unexpected %s dropped", p->name, proto_type_name(msg.type));
        if (msg.type == MSG_JOB)
            proto_job_free(&msg.u.job);
    }
}

/* ---- output ---- */

static int fsync_dir_of(const char *path)
{
    char buf[4096];
    snprintf(buf, sizeof buf, "%s", path);
    int fd = open(dirname(buf), O_RDONLY | O_DIRECTORY);
    if (fd < 0)
        return -1;
    int rc = fsync(fd);
    close(fd);
    return rc;
}

static int write_output(struct master *m, double seconds)
{
    const struct master_opts *o = m->opts;
    char err[512], tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp.%d", o->output_path, (int)getpid());
    struct image_attrs a;
    memset(&a, 0, sizeof a);
    a.spp = m->scene.settings.spp;
    a.seed = m->scene.settings.seed;
    a.render_seconds = seconds;
    snprintf(a.scene_hash, sizeof a.scene_hash, "%s", m->scene_hash);
    snprintf(a.software, sizeof a.software, "brume 0.1");
    struct imgio_writer *w = imgio_writer_open(tmp, &m->desc, &a, err, sizeof err);
    if (!w) {
        log_error("%s", err);
        return -1;
    }
    uint32_t tiles_x = imgio_tiles_x(&m->desc);
    for (uint32_t t = 0; t < m->num_tiles; t++)
        if (imgio_writer_put_tile(w, t % tiles_x, t / tiles_x, m->tiles[t].chunk, m->tiles[t].chunk_size, err,
                                  sizeof err) != 0) {
            imgio_writer_close(&w, err, sizeof err);
            unlink(tmp);
            log_error("%s", err);
            return -1;
        }
    if (imgio_writer_close(&w, err, sizeof err) != 0) {
        unlink(tmp);
        log_error("%s", err);
        return -1;
    }
    if (rename(tmp, o->output_path) != 0) {
        log_error("%s: cannot rename into place: %s", o->output_path, strerror(errno));
        unlink(tmp);
        return -1;
    }
    fsync_dir_of(o->output_path);
    if (o->preview_path) {
        const struct render_settings *rs = &m->scene.settings;
        size_t n = (size_t)rs->width * rs->height * TILE_NUM_CHANNELS;
        float *img = mem_alloc(sizeof(float) * n);
        for (uint32_t t = 0; t < m->num_tiles; t++) {
            uint32_t tx = t % tiles_x, ty = t / tiles_x, x0, y0, tw, th;
            imgio_tile_rect(&m->desc, tx, ty, &x0, &y0, &tw, &th);
            if (imgio_decode_tile(&m->desc, tx, ty, m->tiles[t].chunk, m->tiles[t].chunk_size, m->decode_scratch,
                                  err, sizeof err) != 0)
                continue;
            for (uint32_t y = 0; y < th; y++)
                memcpy(&img[((size_t)(y0 + y) * rs->width + x0) * TILE_NUM_CHANNELS],
                       &m->decode_scratch[(size_t)y * tw * TILE_NUM_CHANNELS], sizeof(float) * tw * TILE_NUM_CHANNELS);
        }
        if (imgio_write_png(o->preview_path, img, rs->width, rs->height, TILE_NUM_CHANNELS, 1.0f, err, sizeof err) != 0)
            log_warn("preview: %s", err);
        free(img);
    }
    return 0;
}

/* ---- progress ---- */

static void print_progress(struct master *m, uint64_t start_ms, int tty, int final)
{
    double secs = (double)(net_now_ms() - start_ms) / 1000.0;
    double rate = secs > 0 ? (double)m->stats.samples / secs : 0.0;
    double left = m->tiles_done > 0 ? secs * (m->num_tiles - m->tiles_done) / m->tiles_done : 0.0;
    if (tty)
        fprintf(stderr, "\rmaster: tiles %u/%u  %.2f Msamples/s  ETA %.0fs   %s", m->tiles_done, m->num_tiles,
                rate / 1e6, left, final ? "\n" : "");
    else
        fprintf(stderr, "master: progress: tiles %u/%u, %.2f Msamples/s, ETA %.0fs\n", m->tiles_done, m->num_tiles,
                rate / 1e6, left);
    fflush(stderr);
}

static void print_summary(struct master *m, double secs)
{
    const struct tile_stats *s = &m->stats;
    printf("summary: %s -> %s\n", m->opts->scene_path, m->opts->output_path);
    printf("summary: %ux%u, %u spp, %u tiles of %u px, seed %llu\n", m->scene.settings.width,
           m->scene.settings.height, m->scene.settings.spp, m->num_tiles, m->scene.settings.tile_size,
           (unsigned long long)m->scene.settings.seed);
    printf("summary: wall %.3f s, %.3f Msamples/s, %.3f Mrays/s\n", secs, secs > 0 ? s->samples / secs / 1e6 : 0.0,
           secs > 0 ? s->rays / secs / 1e6 : 0.0);
    printf("summary: NaN/Inf samples dropped: %llu; stale or rejected results: %llu\n",
           (unsigned long long)s->nan_samples, (unsigned long long)m->dropped_results);
    printf("summary: noise: mean relative standard error %.4f over %u lit pixels\n",
           s->rel_stderr_pixels ? s->sum_rel_stderr / s->rel_stderr_pixels : 0.0, s->rel_stderr_pixels);
    for (uint32_t i = 0; i < m->num_peers; i++)
        printf("summary: worker %s: %u tiles\n", m->peers[i].name, m->peers[i].tiles_done);
    printf("summary: scene hash %s\n", m->scene_hash);
    fflush(stdout);
}

/* ---- main loop ---- */

static int start_local_workers(struct master *m)
{
    const struct master_opts *o = m->opts;
    if (o->workers == 0)
        return 0;
    snprintf(m->ipc_dir, sizeof m->ipc_dir, "/tmp/brume-XXXXXX");
    if (!mkdtemp(m->ipc_dir)) {
        log_error("cannot create a private folder for the local socket: %s", strerror(errno));
        return -1;
    }
    snprintf(m->ipc_endpoint, sizeof m->ipc_endpoint, "ipc://%s/master.sock", m->ipc_dir);
    if (zmq_bind(m->sock, m->ipc_endpoint) != 0) {
        log_error("cannot bind %s: %s", m->ipc_endpoint, zmq_strerror(errno));
        return -1;
    }
    m->local_pids = mem_calloc(o->workers, sizeof *m->local_pids);
    for (uint32_t i = 0; i < o->workers; i++) {
        pid_t pid = launch_worker(o->worker_exe, m->ipc_endpoint, o->threads);
        if (pid < 0)
            return -1;
        m->local_pids[m->num_local++] = pid;
        m->local_alive++;
    }
    return 0;
}

static void reap_local(struct master *m)
{
    int status;
    pid_t pid;
    while ((pid = launch_reap(&status)) > 0) {
        for (uint32_t i = 0; i < m->num_local; i++)
            if (m->local_pids[i] == pid) {
                m->local_pids[i] = 0;
                m->local_alive--;
            }
        for (uint32_t i = 0; i < m->num_peers; i++)
            if (!m->peers[i].gone && m->peers[i].pid == (uint32_t)pid && m->num_local > 0) {
                char why[64];
                if (WIFSIGNALED(status))
                    snprintf(why, sizeof why, "process killed by signal %d", WTERMSIG(status));
                else
                    snprintf(why, sizeof why, "process exited with status %d", WEXITSTATUS(status));
                evict_peer(m, (int32_t)i, why);
            }
    }
}

static uint32_t live_peers(const struct master *m)
{
    uint32_t n = 0;
    for (uint32_t i = 0; i < m->num_peers; i++)
        n += !m->peers[i].gone;
    return n;
}

int master_run(const struct master_opts *o)
{
    struct master m;
    memset(&m, 0, sizeof m);
    m.opts = o;
    int rc = 1;
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);
    if (getrandom(&m.job_id, sizeof m.job_id, 0) != sizeof m.job_id)
        m.job_id = ((uint64_t)getpid() << 32) ^ net_now_ms();
    if (load_scene(&m) != 0)
        goto done;
    setup_tiles(&m);
    m.zctx = zmq_ctx_new();
    m.sock = zmq_socket(m.zctx, ZMQ_ROUTER);
    net_socket_setup(m.sock);
    int mandatory = 1;
    zmq_setsockopt(m.sock, ZMQ_ROUTER_MANDATORY, &mandatory, sizeof mandatory);
    if (o->bind && zmq_bind(m.sock, o->bind) != 0) {
        log_error("cannot bind %s: %s", o->bind, zmq_strerror(errno));
        goto done;
    }
    if (start_local_workers(&m) != 0)
        goto done;
    log_info("rendering %s: %ux%u, %u spp, %u tiles, %u local worker(s)%s%s", o->scene_path,
             m.scene.settings.width, m.scene.settings.height, m.scene.settings.spp, m.num_tiles, o->workers,
             o->bind ? ", accepting workers at " : "", o->bind ? o->bind : "");

    int tty = isatty(2);
    uint64_t start = net_now_ms(), last_progress = start, last_beat = start;
    while (m.tiles_done < m.num_tiles) {
        if (g_interrupted) {
            log_error("interrupted; %u of %u tiles were finished", m.tiles_done, m.num_tiles);
            goto done;
        }
        zmq_pollitem_t item = {m.sock, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&item, 1, 100) < 0 && errno != EINTR) {
            log_error("poll: %s", zmq_strerror(errno));
            goto done;
        }
        if (item.revents & ZMQ_POLLIN) {
            struct net_frame f;
            int got;
            while ((got = net_recv(m.sock, 1, &f)) != 0) {
                if (got > 0)
                    handle_message(&m, &f);
                else
                    log_warn("a message with a malformed envelope (frame count or identity) was dropped");
                net_frame_free(&f);
            }
        }
        uint64_t now = net_now_ms();
        reap_local(&m);
        for (uint32_t i = 0; i < m.num_peers; i++)
            if (!m.peers[i].gone && now - m.peers[i].last_heard_ms > o->worker_timeout_ms)
                evict_peer(&m, (int32_t)i, "no heartbeat");
        if (!o->bind && m.local_alive == 0 && live_peers(&m) == 0) {
            log_error("every worker has exited; %u of %u tiles were finished%s%s", m.tiles_done, m.num_tiles,
                      m.last_worker_error[0] ? "; last worker error: " : "", m.last_worker_error);
            goto done;
        }
        assign_tiles(&m);
        if (now - last_beat >= 1000) {
            struct proto_msg hb = {.type = MSG_HEARTBEAT};
            hb.u.heartbeat.job_id = m.job_id;
            hb.u.heartbeat.tiles_done = m.tiles_done;
            for (uint32_t i = 0; i < m.num_peers; i++)
                if (!m.peers[i].gone)
                    send_to(&m, &m.peers[i], &hb);
            last_beat = now;
        }
        if (now - last_progress >= (tty ? PROGRESS_TTY_MS : PROGRESS_PLAIN_MS)) {
            print_progress(&m, start, tty, 0);
            last_progress = now;
        }
    }
    print_progress(&m, start, tty, 1);
    double secs = (double)(net_now_ms() - start) / 1000.0;
    struct proto_msg bye = {.type = MSG_BYE};
    for (uint32_t i = 0; i < m.num_peers; i++)
        if (!m.peers[i].gone)
            send_to(&m, &m.peers[i], &bye);
    if (write_output(&m, secs) != 0)
        goto done;
    print_summary(&m, secs);
    rc = 0;
done:
    if (m.num_local)
        launch_stop_all(m.local_pids, m.num_local, 3000);
    if (m.ipc_dir[0]) {
        char sockpath[400];
        snprintf(sockpath, sizeof sockpath, "%s/master.sock", m.ipc_dir);
        unlink(sockpath);
        rmdir(m.ipc_dir);
    }
    if (m.sock)
        zmq_close(m.sock);
    if (m.zctx)
        zmq_ctx_term(m.zctx);
    for (uint32_t t = 0; t < m.num_tiles; t++)
        free(m.tiles[t].chunk);
    free(m.tiles);
    free(m.queue);
    free(m.peers);
    free(m.local_pids);
    free(m.manifest);
    free(m.decode_scratch);
    proto_buf_free(&m.out);
    blob_store_free(&m.blobs);
    asset_dir_free(&m.assets);
    scene_free(&m.scene);
    return rc;
}
