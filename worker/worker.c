/* Worker loop (see worker.h). The main thread owns the DEALER socket and all protocol
 * state; render threads only take tile tasks from a locked queue and hand finished
 * tiles back over an inproc PUSH/PULL pair, so the socket is never shared between
 * threads. Everything a worker renders is a pure function of the job's blobs and the
 * tile id, so results are identical on any worker. Render threads render a tile row by
 * row and publish a per-thread progress counter after each row; heartbeats carry their
 * sum and how long the slowest busy thread has made no progress, so the master can tell
 * a hung render thread from a slow one. A finished tile is kept until the master
 * acknowledges it (ACK, sent after its journal sync); when the master goes silent the
 * worker reconnects with back-off on a fresh socket, and a master that comes back on the
 * same job (same job key) gets the kept tiles as KEPT messages. */
#include "worker.h"
#include "base/asset.h"
#include "wire/blob.h"
#include "image/imgio.h"
#include "render/integrator.h"
#include "base/log.h"
#include "scene/medium.h"
#include "wire/net.h"
#include "render/photon_map.h"
#include "wire/proto.h"
#include "wire/fetch.h"
#include "scene/scene_json.h"
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>
#include <zmq.h>

#define BCAST_RCVHWM 64         /* broadcast chunks queued for us (16 MiB); past it the master's queue fills and drops */
#define TILES_PER_THREAD 2      /* credits: tiles queued or rendering per thread */
#define HEARTBEAT_MS 1000
#define MASTER_LOST_MS 4000     /* no word from the master this long: reconnect */
#define DRAIN_MAX_MS 200        /* reading messages this long in a row: go round the loop (heartbeats) */
#define MAPS_RETRY_MS 1000      /* a map waiting for room is tried at least this often (maps_retry) */
#define BACKOFF_FIRST_MS 1000   /* then a fresh attempt after 1, 2, 4, 8, 8, ... s */
#define BACKOFF_MAX_MS 8000
#define KEPT_MAX_TILES 4096     /* kept tiles beyond these (oldest first) are dropped */
#define KEPT_MAX_BYTES (1024ull * 1024 * 1024)

/* job_key and conn: the job the tile belongs to (survives a master restart) and the
 * connection it came on (a RESULT goes only to the master that assigned the tile). */
/* tile is the id on the wire: with passes the unit pass * tiles + tile (then image_tile
 * and pass split it), else the tile (pass 0). */
struct tile_task {
    uint64_t job_id;
    uint32_t frame, tile, attempt;
    struct blob_hash job_key;
    uint32_t conn;
    uint32_t image_tile, pass;
    uint64_t mask;          /* the tile's pixel blocks to render (render/tile.h); the rest stay zero */
    struct blob_hash tag;   /* the master's tag of the assignment, returned in KEPT */
};

/* A finished tile the master has not acknowledged yet. */
struct kept_tile {
    struct tile_task task;  /* job_id is rewritten when offered to a master that came back */
    struct tile_stats stats;
    uint8_t *chunk;
    size_t chunk_size;
};

struct tile_done {
    struct tile_task task;
    struct tile_stats stats;
    uint8_t *chunk;
    size_t chunk_size;
    char err[256];
    int failed;
};

/* Written by one render thread, read by the main thread for heartbeats. */
struct thread_progress {
    _Atomic uint64_t samples;       /* samples finished by this thread, ever */
    _Atomic uint64_t last_ms;       /* when it last finished a row or took a tile */
    _Atomic int busy;
    _Atomic uint32_t map_pass;      /* the pass of the unit it renders (set under the pool's lock when it
                                     * takes the unit, cleared once it no longer reads the pass's map);
                                     * UINT32_MAX: none */
};

struct pool {
    pthread_mutex_t lock;
    pthread_cond_t cond;
    struct tile_task *queue;
    size_t head, count, cap;
    int stop;
    pthread_t *threads;
    uint32_t num_threads;
    void *zctx;
    const struct render_job *rjob;
    const struct image_desc *desc;
    struct thread_progress *progress;   /* per thread; owned by struct worker (outlives pools) */
    uint32_t next_index;
    enum worker_fault fault;
    uint32_t fault_arg;
    _Atomic uint32_t *tiles_rendered;
};

/* A pass's photon map: announced by MAP for the current job, fetched as a blob, decoded
 * into the render job's slot for the pass (installed). Decoded maps are held within
 * opts->map_memory_bytes: the least recently used one that no queued or rendering unit
 * needs is dropped (evicted) to make room, and fetched and decoded again if a unit of its
 * pass comes later (the same bytes: pixels do not depend on the budget). */
struct pass_map {
    struct blob_hash hash;      /* announced for the current job */
    uint64_t size;
    int announced;
    int installed;              /* the render job's slot holds the map of installed_hash */
    int evicted;                /* dropped for room since its last install: not prefetched, a fetch is a re-fetch */
    int used;                   /* a unit of the pass went to the render threads since the install */
    uint64_t decoded_bytes;     /* installed: photon_map_bytes of the decoded map */
    uint64_t last_use;          /* worker.map_clock when it was installed or a unit of its pass was queued */
    struct blob_hash installed_hash;
    struct proto_fetch fetch;         /* fetch.recv.data while fetching */
};

/* A job's scene loaded beside the main loop (load_thread): parsing the scene, building the
 * render job and its BVH take seconds for a big scene, and the main thread keeps
 * heartbeating and answering meanwhile. While it runs the thread alone writes w->scene,
 * w->rjob and w->desc, and the main thread neither changes w->job nor drops the job's blobs
 * (it reads them from `blobs`, a copy of the cache's entries: adopting a map blob may move
 * the cache's array, never the data). A newer JOB waits in `pending` until the load ends;
 * one naming another scene (or a BYE, a signal, a fatal error) cancels the load first. */
enum load_kind { LOAD_SCENE, LOAD_REFRAME };
struct loader {
    int running;                /* a thread was started and not joined yet */
    enum load_kind kind;
    pthread_t thread;
    int efd;                    /* eventfd: the thread is done */
    atomic_int cancel;          /* set by the main thread, read by the loader; also the asset stop flag */
    struct blob_store blobs;    /* entries copied from the cache (not owned: only the array is freed) */
    int rc;                     /* the thread's result: 0, or -1 with err */
    char err[512];
    uint64_t started_ms;
    int have_pending;           /* a JOB that came while loading */
    struct msg_job pending;
    uint32_t pending_conn;      /* the connection it came on */
    struct msg_map *pending_maps; /* MAPs that came after it (they name its job) */
    size_t num_pending_maps, cap_pending_maps;
};

struct worker {
    const struct worker_opts *opts;
    void *zctx, *sock, *results;
    void *sub;                  /* the master's blob broadcast (SUB), connected at the first CHUNKS that names one */
    uint64_t bcast_bad;         /* broadcast frames or chunks refused (the first few are logged) */
    struct proto_buf out;
    struct blob_store cache;
    struct msg_job job;
    int have_job, loaded;
    struct proto_fetch *fetches;
    size_t num_fetches;
    struct scene scene;
    struct render_job rjob;
    struct image_desc desc;
    struct pool pool;
    uint32_t tiles_done;
    struct thread_progress *progress;
    _Atomic uint32_t tiles_rendered;
    struct net_key curve_pub, curve_sec, curve_server;
    uint32_t conn;              /* connection number: a fresh socket and HELLO each */
    uint32_t job_conn;          /* the connection the current JOB came on */
    int lost;                   /* the master is silent: reconnecting */
    uint64_t conn_at_ms;        /* last connection attempt */
    uint32_t backoff_ms;
    struct kept_tile *kept;
    size_t num_kept, cap_kept, kept_bytes;
    uint32_t kept_delivered, reconnects;
    uint64_t job_at_ms;         /* when the current JOB arrived */
    uint64_t fetch_bytes;       /* bytes of its blobs fetched (not already cached) */
    struct pass_map *maps;      /* per pass of the job (job.photon_maps), or NULL */
    uint32_t num_maps;
    uint32_t maps_published;    /* the most maps a MAP of this job said were published */
    int32_t tile_pass_max;      /* the highest pass of a TILE of this job so far; -1: none */
    struct tile_task *parked;   /* units waiting for their pass's map */
    size_t num_parked, cap_parked;
    uint64_t map_wait_ms;       /* this job: ms with parked units and nothing to render */
    uint64_t map_bytes;         /* this job: bytes of photon maps fetched */
    uint64_t map_clock;         /* ticks per map install or queued unit (least recently used order) */
    uint64_t map_bytes_max;     /* the largest decoded map of the job: the room an install needs */
    int maps_waiting;           /* a fetched map waits for room (maps_retry) */
    int maps_changed;           /* since maps_retry last ran: a unit finished or waits, a map came or went */
    uint64_t maps_retry_ms;     /* when maps_retry last ran */
    /* Worker lifetime, logged at exit: maps decoded, the most held at once (and their
     * bytes), maps evicted, bytes of evicted maps fetched again. */
    uint64_t maps_decoded, maps_evicted, map_refetch_bytes, maps_peak_bytes;
    uint32_t maps_peak;
    struct loader load;
};

static volatile sig_atomic_t g_stop;
static void on_signal(int sig) { (void)sig; g_stop = 1; }

/* Sends without ever blocking: a message that cannot even be queued (no connection left,
 * or its queue full) means the master is out of reach, so the worker reconnects; what
 * mattered in it comes again (kept tiles are offered, READY follows the next JOB). */
static int worker_send(struct worker *w, const struct proto_msg *m)
{
    if (net_send(w->sock, NULL, 0, m, &w->out) == 0)
        return 0;
    if (!w->lost) {
        log_warn("cannot send %s to the master (%s); reconnecting", proto_type_name(m->type), zmq_strerror(errno));
        w->lost = 1;
        w->backoff_ms = 0; /* at once, then with back-off */
    }
    return -1;
}

/* ---- render threads ---- */

/* Test-only faults (worker --fault): make this worker misbehave in one chosen way. */
static void fault_before_tile(struct pool *p, const struct tile_task *t)
{
    switch (p->fault) {
    case FAULT_HANG_AFTER:
        if (atomic_load(p->tiles_rendered) >= p->fault_arg)
            for (;;) { /* hang without progress until the job is dropped */
                pthread_mutex_lock(&p->lock);
                int stop = p->stop;
                pthread_mutex_unlock(&p->lock);
                if (stop)
                    return;
                struct timespec nap = {0, 50 * 1000000L};
                nanosleep(&nap, NULL);
            }
        break;
    case FAULT_CRASH_TILE:
        if (t->tile == p->fault_arg)
            abort();
        break;
    case FAULT_SLOW: {
        struct timespec nap = {(time_t)(p->fault_arg / 1000), (long)(p->fault_arg % 1000) * 1000000L};
        nanosleep(&nap, NULL);
        break;
    }
    case FAULT_NONE:
    case FAULT_GARBAGE:
    case FAULT_NONFINITE_TILE:
    case FAULT_SLOW_LOAD:
        break;
    }
}

static void *pool_thread(void *arg)
{
    struct pool *p = arg;
    pthread_mutex_lock(&p->lock);
    struct thread_progress *prog = &p->progress[p->next_index++];
    pthread_mutex_unlock(&p->lock);
    void *push = zmq_socket(p->zctx, ZMQ_PUSH);
    net_socket_setup(push);
    zmq_connect(push, "inproc://results");
    char err[256];
    struct imgio_encoder *enc = imgio_encoder_new(p->desc, err, sizeof err);
    uint32_t tiles_x = imgio_tiles_x(p->desc);
    uint32_t spp = p->rjob->scene->settings.spp, passes = p->rjob->num_passes;
    float *pixels = mem_alloc(sizeof(float) * p->desc->tile_size * p->desc->tile_size * p->desc->num_channels);
    for (;;) {
        pthread_mutex_lock(&p->lock);
        while (!p->stop && p->count == 0)
            pthread_cond_wait(&p->cond, &p->lock);
        if (p->stop) {
            pthread_mutex_unlock(&p->lock);
            break;
        }
        struct tile_task t = p->queue[p->head];
        p->head = (p->head + 1) % p->cap;
        p->count--;
        atomic_store(&prog->map_pass, t.pass); /* under the lock: maps_in_use sees it queued or here */
        pthread_mutex_unlock(&p->lock);
        atomic_store(&prog->last_ms, net_now_ms());
        atomic_store(&prog->busy, 1);
        fault_before_tile(p, &t);

        struct tile_done *d = mem_calloc(1, sizeof *d);
        d->task = t;
        uint32_t tx = t.image_tile % tiles_x, ty = t.image_tile / tiles_x, x0, y0, w, h;
        imgio_tile_rect(p->desc, tx, ty, &x0, &y0, &w, &h);
        struct timespec a, b;
        clock_gettime(CLOCK_MONOTONIC, &a);
        /* Row by row: pixels are pure functions of their coordinates, so this is the same
         * image, and each row is a proof of progress for the heartbeat. */
        uint32_t y = 0, bs = tile_block_size(p->desc->tile_size);
        for (; y < h && !g_stop; y++) { /* SIGINT / SIGTERM: the tile is dropped at the next row */
            float *rowpx = pixels + (size_t)y * w * p->desc->num_channels;
            /* Only the blocks of the mask (an adaptive unit): each run of them in the row is
             * rendered as the whole tile would render it (pixels are pure functions of their
             * coordinates), the other pixels are zero: the master folds only the mask's. */
            if (t.mask != TILE_MASK_ALL)
                memset(rowpx, 0, sizeof(float) * w * p->desc->num_channels);
            for (uint32_t xa = 0; xa < w;) {
                uint32_t xb = xa;
                while (xb < w && (t.mask >> tile_pixel_block(p->desc->tile_size, xb, y) & 1))
                    xb = (xb / bs + 1) * bs < w ? (xb / bs + 1) * bs : w;
                if (xb == xa) {
                    xa = (xa / bs + 1) * bs;
                    continue;
                }
                struct tile_stats row;
                float *runpx = rowpx + (size_t)xa * p->desc->num_channels;
                if (passes > 1) /* one pass of the tile: the master folds the passes */
                    integrator_render_tile_pass(p->rjob, t.pass, x0 + xa, y0 + y, xb - xa, 1, runpx, &row);
                else
                    integrator_render_tile(p->rjob, x0 + xa, y0 + y, xb - xa, 1, runpx, &row);
                tile_stats_add(&d->stats, &row);
                atomic_fetch_add(&prog->samples, (uint64_t)(xb - xa) * spp / passes);
                xa = xb;
            }
            atomic_store(&prog->last_ms, net_now_ms());
        }
        atomic_store(&prog->map_pass, UINT32_MAX); /* the map is no longer read: it may be dropped */
        if (y < h) {
            free(d);
            atomic_store(&prog->busy, 0);
            break;
        }
        clock_gettime(CLOCK_MONOTONIC, &b);
        d->stats.render_ns = (uint64_t)(b.tv_sec - a.tv_sec) * 1000000000ull + (uint64_t)b.tv_nsec - (uint64_t)a.tv_nsec;
        if (p->fault == FAULT_GARBAGE || (p->fault == FAULT_NONFINITE_TILE && t.tile == p->fault_arg))
            pixels[0] = p->fault == FAULT_GARBAGE ? NAN : INFINITY;
        if (!enc) {
            d->failed = 1;
            snprintf(d->err, sizeof d->err, "%s", err);
        } else if (imgio_encode_tile(enc, tx, ty, pixels, &d->chunk, &d->chunk_size, d->err, sizeof d->err) != 0) {
            d->failed = 1;
        }
        atomic_fetch_add(p->tiles_rendered, 1);
        atomic_store(&prog->busy, 0);
        zmq_send(push, &d, sizeof d, 0);
    }
    free(pixels);
    imgio_encoder_free(&enc);
    zmq_close(push);
    return NULL;
}

static void pool_start(struct worker *w)
{
    struct pool *p = &w->pool;
    memset(p, 0, sizeof *p);
    pthread_mutex_init(&p->lock, NULL);
    pthread_cond_init(&p->cond, NULL);
    p->cap = (size_t)w->opts->threads * TILES_PER_THREAD + 1;
    p->queue = mem_alloc(sizeof *p->queue * p->cap);
    p->zctx = w->zctx;
    p->rjob = &w->rjob;
    p->desc = &w->desc;
    p->num_threads = w->opts->threads;
    p->progress = w->progress;
    p->fault = w->opts->fault;
    p->fault_arg = w->opts->fault_arg;
    p->tiles_rendered = &w->tiles_rendered;
    for (uint32_t i = 0; i < p->num_threads; i++) {
        atomic_store(&p->progress[i].busy, 0);
        atomic_store(&p->progress[i].map_pass, UINT32_MAX);
    }
    p->threads = mem_alloc(sizeof *p->threads * p->num_threads);
    for (uint32_t i = 0; i < p->num_threads; i++)
        CHECK(pthread_create(&p->threads[i], NULL, pool_thread, p) == 0);
}

static void pool_stop(struct pool *p)
{
    if (!p->threads)
        return;
    pthread_mutex_lock(&p->lock);
    p->count = 0; /* tiles not started are dropped; those being rendered are finished */
    p->stop = 1;
    pthread_cond_broadcast(&p->cond);
    pthread_mutex_unlock(&p->lock);
    for (uint32_t i = 0; i < p->num_threads; i++)
        pthread_join(p->threads[i], NULL);
    free(p->threads);
    free(p->queue);
    pthread_mutex_destroy(&p->lock);
    pthread_cond_destroy(&p->cond);
    memset(p, 0, sizeof *p);
}

/* 0, or -1 when the queue is full (the master sent more than our credits). */
static int pool_push(struct pool *p, const struct tile_task *t)
{
    pthread_mutex_lock(&p->lock);
    int ok = p->count < p->cap;
    if (ok) {
        p->queue[(p->head + p->count) % p->cap] = *t;
        p->count++;
        pthread_cond_signal(&p->cond);
    }
    pthread_mutex_unlock(&p->lock);
    return ok ? 0 : -1;
}

/* No tile queued and no render thread busy. */
static int pool_idle(struct worker *w)
{
    struct pool *p = &w->pool;
    if (!p->threads)
        return 1;
    pthread_mutex_lock(&p->lock);
    int idle = p->count == 0;
    pthread_mutex_unlock(&p->lock);
    for (uint32_t i = 0; idle && i < p->num_threads; i++)
        idle = !atomic_load(&p->progress[i].busy);
    return idle;
}

/* ---- job loading ---- */

struct blob_source_ctx { const struct msg_job *job; const struct blob_store *cache; };

static int blob_source_read(void *ctx, const char *rel_path, char **data, size_t *size, char *err, size_t errlen)
{
    const struct blob_source_ctx *c = ctx;
    for (uint32_t i = 0; i < c->job->num_assets; i++) {
        const struct proto_asset *a = &c->job->assets[i];
        if (strcmp(a->path, rel_path) != 0)
            continue;
        const struct blob_entry *e = blob_store_get(c->cache, &a->hash);
        if (!e) {
            str_fmt(err, errlen, "%s: blob not fetched", rel_path);
            return -1;
        }
        *data = mem_alloc(e->size + 1);
        memcpy(*data, e->data, e->size);
        (*data)[e->size] = '\0';
        *size = e->size;
        return 0;
    }
    str_fmt(err, errlen, "%s: not among the job's assets (the master did not publish it)", rel_path);
    return -1;
}

static void send_error(struct worker *w, const char *text)
{
    struct proto_msg m = {.type = MSG_ERROR};
    m.u.error.job_id = w->job.job_id;
    snprintf(m.u.error.text, sizeof m.u.error.text, "%s", text);
    worker_send(w, &m);
}

static void maps_reset(struct worker *w, int keep_installed);

static void load_discard(struct worker *w);

static void unload_job(struct worker *w)
{
    if (w->load.running) { /* a load under way: stopped, and what it built freed */
        w->load.cancel = 1;
        load_discard(w);
    }
    pool_stop(&w->pool);
    maps_reset(w, 0);
    if (w->loaded) {
        render_job_fini(&w->rjob);
        scene_fini(&w->scene);
    }
    w->loaded = 0;
    for (size_t i = 0; i < w->num_fetches; i++)
        blob_recv_fini(&w->fetches[i].recv);
    free(w->fetches);
    w->fetches = NULL;
    w->num_fetches = 0;
    if (w->have_job)
        proto_job_fini(&w->job);
    w->have_job = 0;
}

static int map_install(struct worker *w, uint32_t pass);

/* The scene, its render job and BVH are built and may render (not while a load runs). */
static int job_ready(const struct worker *w)
{
    return w->loaded && !w->load.running;
}

/* Test-only (worker --fault slow-load:MS): the load takes MS longer, as a big scene's does
 * on a loaded machine; a cancelled load stops waiting at once. */
static void fault_slow_load(struct worker *w)
{
    if (w->opts->fault != FAULT_SLOW_LOAD)
        return;
    uint64_t until = net_now_ms() + w->opts->fault_arg;
    while (!w->load.cancel && net_now_ms() < until) {
        struct timespec nap = {0, 20 * 1000000L};
        nanosleep(&nap, NULL);
    }
}

/* Parses the scene from the job's blobs and builds its render job (Embree scene, lights,
 * textures): on the loader thread. 0, or -1 with load.err (nothing left built). */
static int load_scene(struct worker *w)
{
    char *err = w->load.err;
    size_t errlen = sizeof w->load.err;
    struct blob_source_ctx ctx = {&w->job, &w->load.blobs};
    struct asset_source src = {blob_source_read, &ctx};
    char *text = NULL;
    size_t len = 0;
    fault_slow_load(w);
    if (w->load.cancel) {
        str_fmt(err, errlen, "cancelled");
        return -1;
    }
    if (blob_source_read(&ctx, w->job.scene_path, &text, &len, err, errlen) != 0 ||
        scene_json_parse_frame(w->job.scene_path, text, len, &src, NULL, w->job.frame, &w->scene, err, errlen) != 0) {
        free(text);
        return -1;
    }
    free(text);
    /* Media scenes render only with the master's volume blob (settings and photon map);
     * the decoded map goes to the render job, which owns it. */
    struct photon_map *map = NULL;
    if (w->scene.media) {
        char *vb = NULL;
        size_t vbs = 0;
        int rc = blob_source_read(&ctx, MEDIA_PHOTON_ASSET, &vb, &vbs, err, errlen);
        if (rc == 0)
            rc = volume_blob_apply(&w->scene, (const uint8_t *)vb, vbs, &map, err, errlen);
        free(vb);
        if (rc == 0 && map) { /* maps travel one blob per pass, announced by MAP */
            photon_map_free(&map);
            str_fmt(err, errlen, "volume blob: it carries photon maps; this worker takes them from MAP messages");
            rc = -1;
        }
        if (rc != 0) {
            scene_fini(&w->scene);
            return -1;
        }
    }
    struct render_settings *rs = &w->scene.settings;
    rs->width = w->job.width;
    rs->height = w->job.height;
    rs->spp = w->job.spp;
    rs->max_depth = w->job.max_depth;
    rs->tile_size = w->job.tile_size;
    rs->seed = w->job.seed;
    rs->sampler = (enum sampler_type)w->job.sampler;
    rs->aovs = w->job.aovs;
    rs->embree_isa = (enum embree_isa)w->job.embree_isa;
    w->scene.camera.filter = w->job.filter;
    w->scene.camera.filter_width = w->job.filter_width;
    if (w->load.cancel) {
        scene_fini(&w->scene);
        str_fmt(err, errlen, "cancelled");
        return -1;
    }
    if (scene_validate(&w->scene, err, errlen) != 0 ||
        render_job_init(&w->rjob, &w->scene, w->job.frame, w->opts->threads, err, errlen) != 0) {
        scene_fini(&w->scene);
        return -1;
    }
    /* Progressive passes: one map slot per pass (proto checked that they divide spp),
     * filled as the maps arrive. */
    if (w->job.photon_maps && !w->scene.media) {
        str_fmt(err, errlen, "job: %u photon maps for a scene without media", w->job.photon_maps);
        render_job_fini(&w->rjob);
        scene_fini(&w->scene);
        return -1;
    }
    /* Passes without photon maps get empty map slots: nothing waits for a MAP. */
    render_job_set_passes(&w->rjob, w->job.photon_maps ? w->job.photon_maps : w->job.passes > 1 ? w->job.passes : 0);
    tile_image_desc(&w->desc, rs);
    return 0;
}

static void *load_thread(void *arg)
{
    struct worker *w = arg;
    if (w->load.kind == LOAD_SCENE)
        w->load.rc = load_scene(w);
    else /* the next frame of the loaded scene; on failure the render job is freed */
        w->load.rc = render_job_reframe(&w->rjob, w->job.frame, w->opts->threads, w->load.err, sizeof w->load.err);
    uint64_t one = 1;
    CHECK(write(w->load.efd, &one, sizeof one) == (ssize_t)sizeof one);
    return NULL;
}

/* Starts loading the current job (LOAD_SCENE: every blob is here; LOAD_REFRAME: the
 * loaded scene moves to the job's frame) beside the main loop; load_finish sends READY. */
static void load_start(struct worker *w, enum load_kind kind)
{
    CHECK(!w->load.running);
    if (kind == LOAD_SCENE)
        log_debug("job %llu: its blobs are here; loading the scene", (unsigned long long)w->job.job_id);
    w->load.kind = kind;
    w->load.cancel = 0;
    w->load.rc = -1;
    w->load.err[0] = '\0';
    w->load.started_ms = net_now_ms();
    w->load.blobs.count = w->load.blobs.cap = w->cache.count;
    w->load.blobs.entries = mem_alloc(sizeof *w->load.blobs.entries * (w->cache.count ? w->cache.count : 1));
    memcpy(w->load.blobs.entries, w->cache.entries, sizeof *w->cache.entries * w->cache.count);
    CHECK(pthread_create(&w->load.thread, NULL, load_thread, w) == 0);
    w->load.running = 1;
}

/* Waits for the loader thread (at once when it said it is done) and clears its state. */
static void load_join(struct worker *w)
{
    pthread_join(w->load.thread, NULL);
    w->load.running = 0;
    uint64_t v;
    while (read(w->load.efd, &v, sizeof v) == (ssize_t)sizeof v) {
    }
    free(w->load.blobs.entries);
    memset(&w->load.blobs, 0, sizeof w->load.blobs);
}

/* A load that ended (or failed) after it was cancelled: what it built is freed. A cancelled
 * LOAD_REFRAME that succeeded leaves the scene loaded (for another frame of it). */
static void load_drop_result(struct worker *w)
{
    if (w->load.kind == LOAD_SCENE && w->load.rc == 0) {
        render_job_fini(&w->rjob);
        scene_fini(&w->scene);
    } else if (w->load.kind == LOAD_REFRAME && w->load.rc != 0) {
        scene_fini(&w->scene);
        w->loaded = 0;
    }
}

static void pending_drop(struct worker *w)
{
    if (w->load.have_pending)
        proto_job_fini(&w->load.pending);
    w->load.have_pending = 0;
    w->load.num_pending_maps = 0;
}

/* Stops a load under way (load.cancel set by the caller) and frees what it built; a JOB
 * waiting for it is dropped. */
static void load_discard(struct worker *w)
{
    load_join(w);
    load_drop_result(w);
    pending_drop(w);
    log_info("load of job %llu cancelled after %.3f s", (unsigned long long)w->job.job_id,
             (double)(net_now_ms() - w->load.started_ms) * 1e-3);
}

static int on_job(struct worker *w, struct msg_job *job);
static int on_map(struct worker *w, const struct msg_map *mm);
static void offer_kept(struct worker *w, int new_job_same_conn, uint64_t old_job_id);

/* The loader thread is done: READY for the job it loaded, or its error to the master
 * (fatal, as a failed load always was), or, when a newer JOB came meanwhile, that job.
 * 0, or -1 when the worker must stop. */
static int load_finish(struct worker *w)
{
    load_join(w);
    if (w->load.cancel || w->load.have_pending) {
        /* Superseded: a JOB came while loading. Without cancel it names the same scene,
         * whose parse is kept (the JOB then only moves it to its frame). */
        if (w->load.cancel || w->load.rc != 0) {
            log_info("load of job %llu cancelled after %.3f s: a newer job came", (unsigned long long)w->job.job_id,
                     (double)(net_now_ms() - w->load.started_ms) * 1e-3);
            load_drop_result(w);
        } else if (w->load.kind == LOAD_SCENE) {
            w->loaded = 1;
        }
        struct msg_job job = w->load.pending;
        int have = w->load.have_pending, from_conn = w->load.pending_conn == w->conn;
        w->load.have_pending = 0;
        if (!have)
            return 0;
        if (!from_conn) { /* it came on a connection since lost: the next one brings its own */
            proto_job_fini(&job);
            w->load.num_pending_maps = 0;
            return 0;
        }
        if (on_job(w, &job) != 0)
            return -1;
        /* on_job may have started another load: MAPs then wait again behind it, handled
         * like any other (on_map keeps announcements while loading) */
        size_t n = w->load.num_pending_maps;
        w->load.num_pending_maps = 0;
        for (size_t i = 0; i < n; i++)
            if (on_map(w, &w->load.pending_maps[i]) != 0)
                return -1;
        return 0;
    }
    if (w->load.rc != 0) {
        if (w->load.kind == LOAD_REFRAME) {
            scene_fini(&w->scene);
            w->loaded = 0;
        }
        send_error(w, w->load.err);
        log_error("%s", w->load.err);
        return -1;
    }
    w->loaded = 1;
    w->maps_changed = 1; /* maps waiting for room may be tried now (maps_retry) */
    pool_start(w);
    if (w->load.kind == LOAD_SCENE)
        for (uint32_t p = 0; p < w->num_maps; p++) /* maps announced and fetched while the scene loaded */
            if (map_install(w, p) != 0)
                return -1;
    if (w->job_conn != w->conn) {
        /* The JOB came on a connection since lost. The master that hears us now has sent
         * (or will send) its own JOB on this one, which moves the loaded scene to its frame
         * and says READY then. A READY now would get tiles that arrive while that JOB's
         * reload runs, and a tile the worker cannot render then is lost until the master
         * evicts us. */
        log_info("job %llu loaded after a reconnection: READY waits for this connection's JOB",
                 (unsigned long long)w->job.job_id);
        return 0;
    }
    struct proto_msg m = {.type = MSG_READY};
    m.u.ready.job_id = w->job.job_id;
    m.u.ready.credits = w->opts->threads * TILES_PER_THREAD;
    if (w->load.kind == LOAD_SCENE)
        log_info("job %llu loaded: %ux%u, %u spp in %u pass(es), %u threads; %llu bytes of assets fetched and the scene built in %.3f s",
                 (unsigned long long)w->job.job_id, w->scene.settings.width, w->scene.settings.height,
                 w->scene.settings.spp, w->rjob.num_passes, w->opts->threads, (unsigned long long)w->fetch_bytes,
                 (double)(net_now_ms() - w->job_at_ms) * 1e-3);
    else
        log_info("job %llu: frame %u (scene kept)", (unsigned long long)w->job.job_id, w->job.frame);
    worker_send(w, &m);
    return 0;
}

/* Requests in flight, CHUNKS_REQ and BLOB_REQ, over every fetch together. A job may name
 * thousands of blobs (PROTO_MAX_ASSETS): a window per blob, all opened at once, would put
 * more in the socket's queue than it holds (ZMQ_SNDHWM: a send that fails means a lost
 * master, so the worker reconnected and began again, for ever) and as many answers in the
 * master's queue for us. */
#define FETCH_REQUESTS_MAX PROTO_FETCH_WINDOW

/* Fetch i of the worker's fetches in their one order: the job's blobs (fetches), then the
 * passes' photon maps (maps); i < num_fetches + num_maps. */
static struct proto_fetch *fetch_at(const struct worker *w, size_t i)
{
    return i >= w->num_fetches ? &w->maps[i - w->num_fetches].fetch : &w->fetches[i];
}

static uint32_t fetch_requests(const struct worker *w)
{
    uint32_t n = 0;
    for (size_t i = 0; i < w->num_fetches + w->num_maps; i++) {
        const struct proto_fetch *f = fetch_at(w, i);
        if (f->recv.data)
            n += f->in_flight + (f->phase == FETCH_LIST && f->list_asked);
    }
    return n;
}

/* Sends what the fetch wants now while *busy (fetch_requests) is under FETCH_REQUESTS_MAX:
 * its CHUNKS_REQ first, then BLOB_REQs (none while the list is on its way or the broadcast
 * brings chunks); *busy counts them. -1 after an ERROR to the master: chunks asked for
 * again and again came back bad. */
static int request_chunks_within(struct worker *w, struct proto_fetch *f, uint32_t *busy)
{
    struct proto_msg m;
    int rc = 0;
    if (f->phase == FETCH_LIST) {
        uint64_t now = net_now_ms();
        if (f->recv.size > 0 && *busy < FETCH_REQUESTS_MAX && proto_fetch_list_due(f, now)) {
            proto_fetch_list_req(f, &m);
            if (worker_send(w, &m) == 0) { /* not queued: asked for again next time */
                proto_fetch_list_sent(f, now);
                (*busy)++;
            }
        }
        return 0;
    }
    while (*busy < FETCH_REQUESTS_MAX && (rc = proto_fetch_next_req(f, net_now_ms(), &m)) > 0) {
        if (worker_send(w, &m) != 0) { /* not queued: asked for again next time */
            f->in_flight--;
            f->next_chunk = m.u.blob_req.offset / BLOB_CHUNK_SIZE;
            return 0;
        }
        (*busy)++;
    }
    if (rc < 0) {
        char err[256], hex[65];
        blob_hash_hex(&f->recv.hash, hex);
        str_fmt(err, sizeof err, "blob %.16s: %llu chunks still bad after %d requests each", hex,
                (unsigned long long)(f->recv.num_chunks - f->recv.chunks_have), PROTO_FETCH_MAX_ROUNDS);
        log_error("%s", err);
        send_error(w, err);
        proto_fetch_fini(f);
        return -1;
    }
    return 0;
}

static int request_chunks(struct worker *w, struct proto_fetch *f)
{
    uint32_t busy = fetch_requests(w);
    return request_chunks_within(w, f, &busy);
}

/* Starts fetching (hash, size): CHUNKS_REQ (now, or once the requests in flight leave
 * room: fetches_pump), the rest when the list comes. */
static int fetch_begin(struct worker *w, struct proto_fetch *f, const struct blob_hash *hash, uint64_t size, char *err,
                       size_t errlen)
{
    struct proto_msg req;
    if (proto_fetch_start(f, hash, size, &req, err, errlen) != 0)
        return -1;
    request_chunks(w, f); /* a fetch with no list yet sends at most its CHUNKS_REQ */
    return 0;
}

/* The fetch of blob hash under way, if any; *map_pass: its pass for a photon map, else -1. */
static struct proto_fetch *fetch_find(struct worker *w, const struct blob_hash *hash, int *map_pass)
{
    for (size_t i = 0; i < w->num_fetches + w->num_maps; i++) {
        *map_pass = i >= w->num_fetches ? (int)(i - w->num_fetches) : -1;
        struct proto_fetch *f = fetch_at(w, i);
        if (f->recv.data && blob_hash_equal(&f->recv.hash, hash))
            return f;
    }
    return NULL;
}

static int fetches_pump(struct worker *w);

/* CHUNKS: the list goes into the fetch; with a broadcast, we subscribe to the hash (the
 * SUB socket is connected at the first: beside our ROUTER endpoint, secured the same way). */
static int on_chunks(struct worker *w, const struct msg_chunks *c)
{
    int map_pass;
    struct proto_fetch *f = fetch_find(w, &c->hash, &map_pass);
    if (!f)
        return 0;
    char err[256];
    int rc = proto_fetch_on_chunks(f, c, net_now_ms(), err, sizeof err);
    if (rc < 0)
        log_warn("master: %s (fetching it point to point)", err);
    if (rc > 0) {
        char ep[1200];
        int ok = net_bcast_endpoint(w->opts->endpoint, c->bcast_port, ep, sizeof ep) == 0 &&
                 (strncmp(ep, "tcp://", 6) != 0 || c->bcast_port != 0);
        if (ok && !w->sub) {
            w->sub = zmq_socket(w->zctx, ZMQ_SUB);
            net_socket_setup(w->sub);
            int hwm = BCAST_RCVHWM;
            zmq_setsockopt(w->sub, ZMQ_RCVHWM, &hwm, sizeof hwm);
            ok = (!w->opts->curve_secret ||
                  net_curve_client(w->sub, &w->curve_server, &w->curve_pub, &w->curve_sec) == 0) &&
                 zmq_connect(w->sub, ep) == 0;
            if (!ok) {
                log_warn("cannot subscribe to the blob broadcast at %s: %s (fetching point to point)", ep,
                         zmq_strerror(errno));
                zmq_close(w->sub);
                w->sub = NULL;
            }
        }
        if (ok && w->sub && zmq_setsockopt(w->sub, ZMQ_SUBSCRIBE, c->hash.bytes, BLOB_HASH_SIZE) == 0)
            log_debug("blob of %llu bytes: taking the broadcast", (unsigned long long)c->size);
        else
            f->phase = FETCH_P2P;
    }
    return fetches_pump(w); /* the window goes to the fetches in order: the scene's files, then passes */
}

static int fetches_pending(const struct worker *w)
{
    for (size_t i = 0; i < w->num_fetches; i++)
        if (w->fetches[i].recv.data || !blob_store_get(&w->cache, &w->fetches[i].recv.hash))
            return 1;
    return 0;
}

/* Same scene files and settings: only the job id and the frame differ (the next frame of
 * a range). */
static int job_same_scene(const struct msg_job *a, const struct msg_job *b)
{
    if (a->width != b->width || a->height != b->height || a->spp != b->spp || a->max_depth != b->max_depth ||
        a->tile_size != b->tile_size || a->seed != b->seed || a->sampler != b->sampler ||
        a->photon_maps != b->photon_maps || a->passes != b->passes ||
        strcmp(a->scene_path, b->scene_path) != 0 || a->num_assets != b->num_assets)
        return 0;
    for (uint32_t i = 0; i < a->num_assets; i++)
        if (strcmp(a->assets[i].path, b->assets[i].path) != 0 || !blob_hash_equal(&a->assets[i].hash, &b->assets[i].hash))
            return 0;
    return 1;
}

static void offer_kept(struct worker *w, int new_job_same_conn, uint64_t old_job_id);

/* Keeps only the blobs the job names: a frame range whose photon map changes every frame
 * would otherwise pile up a map per frame. */
static void cache_keep_only(struct blob_store *c, const struct msg_job *job)
{
    for (size_t i = 0; i < c->count;) {
        int used = 0;
        for (uint32_t k = 0; k < job->num_assets && !used; k++)
            used = blob_hash_equal(&c->entries[i].hash, &job->assets[k].hash);
        if (used) {
            i++;
        } else {
            struct blob_hash h = c->entries[i].hash;
            blob_store_drop(c, &h); /* the last entry moves to i */
        }
    }
}

/* The next frame of the loaded scene: keep the parsed scene, rebuild what depends on the
 * frame (Embree scene with its motion steps, camera at the frame's time). */
static void switch_frame(struct worker *w, struct msg_job *job, int same_conn, uint64_t old_job)
{
    pool_stop(&w->pool); /* tiles being rendered finish and go out under their old job id */
    maps_reset(w, 1); /* the maps stay until this job announces others */
    proto_job_fini(&w->job);
    w->job = *job;
    /* Kept tiles go before READY: the master must not hand them out meanwhile. */
    offer_kept(w, same_conn, old_job);
    /* Texture pyramids and the light table stay; the frame's geometry and camera are new
     * (the BVH is built again, beside the main loop; load_finish sends READY). */
    load_start(w, LOAD_REFRAME);
}

/* A JOB while a load runs waits for it (the newest one only, with the MAPs after it); one
 * that names another scene or other settings cancels the load, whose result it cannot use. */
static void job_defer(struct worker *w, struct msg_job *job)
{
    int cancel = !job_same_scene(&w->job, job);
    pending_drop(w);
    w->load.pending = *job; /* takes ownership of the asset array */
    w->load.have_pending = 1;
    w->load.pending_conn = w->conn;
    if (cancel)
        w->load.cancel = 1;
    log_info("job %llu came while job %llu loads: %s", (unsigned long long)job->job_id,
             (unsigned long long)w->job.job_id, cancel ? "that load is cancelled" : "the same scene, kept for it");
}

static int on_job(struct worker *w, struct msg_job *job)
{
    if (w->load.running) {
        job_defer(w, job);
        return 0;
    }
    /* A new job on the connection that brought the last one: that frame is done. */
    int same_conn = w->have_job && w->job_conn == w->conn && job->job_id != w->job.job_id;
    uint64_t old_job = w->have_job ? w->job.job_id : 0;
    w->job_conn = w->conn;
    if (w->loaded && w->have_job && job_same_scene(&w->job, job)) {
        switch_frame(w, job, same_conn, old_job);
        return 0;
    }
    unload_job(w);
    w->job = *job;   /* takes ownership of the asset array */
    w->have_job = 1;
    w->num_maps = job->photon_maps;
    /* (unload_job's maps_reset cleared the job's map counters) */
    w->maps = w->num_maps ? mem_calloc(w->num_maps, sizeof *w->maps) : NULL;
    cache_keep_only(&w->cache, &w->job);
    w->job_at_ms = net_now_ms();
    w->fetch_bytes = 0;
    offer_kept(w, same_conn, old_job);
    w->fetches = mem_calloc(job->num_assets ? job->num_assets : 1, sizeof *w->fetches);
    for (uint32_t i = 0; i < job->num_assets; i++) {
        const struct proto_asset *a = &job->assets[i];
        if (blob_store_get(&w->cache, &a->hash))
            continue;
        int dup = 0;
        for (size_t k = 0; k < w->num_fetches; k++)
            dup |= blob_hash_equal(&w->fetches[k].recv.hash, &a->hash);
        if (dup)
            continue;
        char err[256];
        struct proto_fetch *f = &w->fetches[w->num_fetches];
        if (fetch_begin(w, f, &a->hash, a->size, err, sizeof err) != 0) {
            log_error("asset %s: %s", a->path, err);
            send_error(w, err);
            return -1;
        }
        w->num_fetches++;
        w->fetch_bytes += a->size;
        if (a->size == 0) {
            uint8_t *data;
            if (blob_recv_finish(&f->recv, &data, err, sizeof err) != 0) {
                send_error(w, err);
                return -1;
            }
            blob_store_adopt(&w->cache, &a->hash, data, 0);
            continue;
        }
    }
    if (!fetches_pending(w))
        load_start(w, LOAD_SCENE);
    return 0;
}

/* A chunk, answering a BLOB_REQ or from the broadcast (via_bcast): kept once checked
 * against the chunk list; a bad one is dropped and asked for again. */
static int on_blob_data(struct worker *w, const struct msg_blob_data *d, int via_bcast)
{
    int map_pass;
    struct proto_fetch *f = fetch_find(w, &d->hash, &map_pass);
    if (f) {
        char err[256];
        if (proto_fetch_on_data(f, d, via_bcast, net_now_ms(), err, sizeof err) != 0 && ++w->bcast_bad <= 5)
            log_warn("master sent a bad blob chunk%s (dropped, fetched again): %s", via_bcast ? " (broadcast)" : "", err);
        if (fetches_pump(w) != 0) /* the freed request goes to the first fetch that wants one */
            return -1;
        if (blob_recv_complete(&f->recv)) {
            uint8_t *data;
            uint64_t size = f->recv.size;
            struct blob_hash h = f->recv.hash;
            if (blob_recv_finish(&f->recv, &data, err, sizeof err) != 0) {
                log_error("blob: %s", err);
                send_error(w, err);
                return -1;
            }
            blob_store_adopt(&w->cache, &h, data, size);
            log_debug("blob of %llu bytes in: %llu chunks from the broadcast, %llu point to point",
                      (unsigned long long)size, (unsigned long long)f->chunks_bcast, (unsigned long long)f->chunks_p2p);
            proto_fetch_fini(f);
            if (w->sub)
                zmq_setsockopt(w->sub, ZMQ_UNSUBSCRIBE, h.bytes, BLOB_HASH_SIZE);
            if (map_pass >= 0) {
                w->map_bytes += size;
                if (w->maps[map_pass].evicted) {
                    w->map_refetch_bytes += size;
                    log_debug("photon map of pass %d fetched again (%llu bytes): it was evicted", map_pass,
                              (unsigned long long)size);
                }
                return job_ready(w) ? map_install(w, (uint32_t)map_pass) : 0;
            }
            if (!fetches_pending(w) && !w->load.running && !w->loaded)
                load_start(w, LOAD_SCENE);
        }
    }
    return 0; /* a chunk we no longer want (e.g. a duplicate): harmless */
}

/* Each pass of the loop: fetches waiting for room in the window, or whose broadcast went
 * quiet, ask for what they lack. */
static int fetches_pump(struct worker *w)
{
    uint64_t now = net_now_ms();
    for (size_t i = 0; i < w->num_fetches + w->num_maps; i++) {
        struct proto_fetch *f = fetch_at(w, i);
        if (proto_fetch_expire(f, now)) {
            char hex[65];
            blob_hash_hex(&f->recv.hash, hex);
            log_warn("blob %.16s: no answer from the master for %d ms; asking again (%llu of %llu chunks in)", hex,
                     PROTO_FETCH_STALL_MS, (unsigned long long)f->recv.chunks_have,
                     (unsigned long long)f->recv.num_chunks);
        }
    }
    if (w->job_conn != w->conn)
        return 0; /* the master ignores a BLOB_REQ before it sent this connection its JOB */
    uint32_t busy = fetch_requests(w);
    for (size_t i = 0; i < w->num_fetches + w->num_maps && busy < FETCH_REQUESTS_MAX; i++) {
        struct proto_fetch *f = fetch_at(w, i);
        if (f->recv.data && request_chunks_within(w, f, &busy) != 0)
            return -1;
    }
    return 0;
}

/* One frame off the broadcast: the topic (a hash) and a BLOB_DATA of that hash. */
static int on_bcast_frame(struct worker *w, const struct net_frame *fr)
{
    struct proto_msg m;
    char err[256];
    if (proto_fetch_decode_bcast(fr->id, fr->id_len, fr->data, fr->size, &m, err, sizeof err) != 0) {
        if (++w->bcast_bad <= 5)
            log_warn("broadcast: message dropped: %s", err);
        return 0;
    }
    return on_blob_data(w, &m.u.blob_data, 1);
}

static int map_ready(const struct worker *w, uint32_t pass);
static void map_fetch_start(struct worker *w, uint32_t pass);

/* Pass `pass`'s map goes to the back of the least recently used order; used: a unit of
 * the pass went to the render threads (0: just installed). */
static void map_touch(struct worker *w, uint32_t pass, int used)
{
    w->maps[pass].last_use = ++w->map_clock;
    w->maps[pass].used = used;
}

static void on_tile(struct worker *w, const struct msg_tile *t)
{
    uint32_t ntiles = job_ready(w) ? imgio_tiles_x(&w->desc) * imgio_tiles_y(&w->desc) : 0;
    uint64_t nunits = (uint64_t)ntiles * (w->job.passes > 1 ? w->job.passes : 1);
    uint32_t npasses = w->job.passes > 1 ? w->job.passes : 1;
    if (!job_ready(w) || t->job_id != w->job.job_id || t->frame != w->job.frame || t->tile >= nunits ||
        t->pass >= npasses) {
        log_warn("dropping TILE %u for job %llu frame %u: not part of the loaded job", t->tile,
                 (unsigned long long)t->job_id, t->frame);
        return;
    }
    struct tile_task task = {t->job_id, t->frame, t->tile, t->attempt, w->job.job_key, w->conn, t->tile % ntiles,
                             t->pass, t->mask, t->tag};
    if ((int32_t)task.pass > w->tile_pass_max)
        w->tile_pass_max = (int32_t)task.pass;
    if (w->num_maps && !map_ready(w, task.pass)) {
        struct pass_map *pm = &w->maps[task.pass];
        if (!pm->announced) {
            log_warn("dropping TILE %u: pass %u's photon map was never announced", t->tile, task.pass);
            return;
        }
        if (w->num_parked == w->cap_parked) {
            w->cap_parked = w->cap_parked ? w->cap_parked * 2 : 16;
            w->parked = mem_realloc(w->parked, sizeof *w->parked * w->cap_parked);
        }
        w->parked[w->num_parked++] = task; /* rendered once the map is here (map_install) */
        w->maps_changed = 1;               /* its map may wait in the cache for room */
        map_fetch_start(w, task.pass);
        return;
    }
    if (w->num_maps)
        map_touch(w, task.pass, 1);
    if (pool_push(&w->pool, &task) != 0)
        log_warn("dropping TILE %u: master exceeded our credits", t->tile);
}

/* ---- photon maps, one blob per pass ---- */

/* Drops the job's map state: fetches and parked units; with keep_installed (the next frame
 * of the same scene) the maps stay in the render job until a MAP replaces them. */
static void maps_reset(struct worker *w, int keep_installed)
{
    w->maps_published = 0;
    w->tile_pass_max = -1;
    for (uint32_t p = 0; p < w->num_maps; p++) {
        blob_recv_fini(&w->maps[p].fetch.recv);
        memset(&w->maps[p].fetch, 0, sizeof w->maps[p].fetch);
        w->maps[p].announced = 0;
    }
    if (!keep_installed) { /* the render job's maps are freed with it */
        free(w->maps);
        w->maps = NULL;
        w->num_maps = 0;
        w->map_bytes_max = 0;
    }
    w->maps_waiting = 0;
    w->num_parked = 0;
    w->map_wait_ms = 0;
    w->map_bytes = 0;
}

static int map_ready(const struct worker *w, uint32_t pass)
{
    const struct pass_map *pm = &w->maps[pass];
    return pm->announced && pm->installed && blob_hash_equal(&pm->installed_hash, &pm->hash);
}

/* Fetches pass `pass`'s announced map unless it is here or on its way. */
static void map_fetch_start(struct worker *w, uint32_t pass)
{
    struct pass_map *pm = &w->maps[pass];
    if (!pm->announced || map_ready(w, pass) || pm->fetch.recv.data || blob_store_get(&w->cache, &pm->hash))
        return;
    char err[256];
    if (fetch_begin(w, &pm->fetch, &pm->hash, pm->size, err, sizeof err) != 0) {
        log_error("photon map of pass %u: %s", pass, err);
        send_error(w, err);
        return;
    }
    if (pm->size == 0) { /* never a valid map: let the decoder say why */
        uint8_t *data;
        if (blob_recv_finish(&pm->fetch.recv, &data, err, sizeof err) == 0)
            blob_store_adopt(&w->cache, &pm->hash, data, 0);
        blob_recv_fini(&pm->fetch.recv);
        return;
    }
}

/* used[p] = 1 for each pass a queued or rendering unit needs. Under the pool's lock, which
 * a render thread holds when it takes a unit and marks its pass: a pass found unused stays
 * so until the main thread (the caller) queues a unit of it. */
static void maps_in_use(struct worker *w, uint8_t *used)
{
    memset(used, 0, w->num_maps);
    struct pool *p = &w->pool;
    if (!p->threads)
        return;
    pthread_mutex_lock(&p->lock);
    for (size_t i = 0; i < p->count; i++) {
        uint32_t q = p->queue[(p->head + i) % p->cap].pass;
        if (q < w->num_maps)
            used[q] = 1;
    }
    for (uint32_t i = 0; i < p->num_threads; i++) {
        uint32_t q = atomic_load(&p->progress[i].map_pass);
        if (q < w->num_maps)
            used[q] = 1;
    }
    pthread_mutex_unlock(&p->lock);
}

/* Bytes of the decoded maps in the render job, besides pass `skip`'s (which an install
 * replaces; UINT32_MAX: none skipped); *count: how many (may be NULL). */
static uint64_t maps_held_besides(const struct worker *w, uint32_t skip, uint32_t *count)
{
    uint64_t bytes = 0;
    uint32_t n = 0;
    for (uint32_t p = 0; p < w->num_maps; p++)
        if (p != skip && w->maps[p].installed) {
            bytes += w->maps[p].decoded_bytes;
            n++;
        }
    if (count)
        *count = n;
    return bytes;
}

/* Drops pass `pass`'s decoded map (no unit of the pass is queued or rendering). */
static void map_evict(struct worker *w, uint32_t pass)
{
    struct pass_map *pm = &w->maps[pass];
    struct photon_map *none = NULL;
    render_job_set_pass_map(&w->rjob, pass, &none);
    uint64_t bytes = pm->decoded_bytes;
    pm->installed = 0;
    pm->evicted = 1;
    pm->decoded_bytes = 0;
    w->maps_evicted++;
    w->maps_changed = 1;
    log_debug("photon map of pass %u evicted (%llu bytes decoded; budget %llu)", pass, (unsigned long long)bytes,
              (unsigned long long)w->opts->map_memory_bytes);
}

/* A map as big as the job's largest so far fits beside `held` bytes of maps, or none is
 * held (one map is always allowed). */
static int maps_fit(const struct worker *w, uint64_t held)
{
    return held == 0 || held + w->map_bytes_max <= w->opts->map_memory_bytes;
}

static int maps_room(const struct worker *w, uint32_t skip)
{
    return maps_fit(w, maps_held_besides(w, skip, NULL));
}

/* Room for pass `pass`'s map within the budget. For a map that units wait for (demand),
 * maps that no queued or rendering unit needs are evicted until it fits: first the least
 * recently used of those whose units were rendered (in pass order their passes are done),
 * then of those fetched ahead and not used yet. A map fetched ahead (no unit waits) takes
 * only free room: it never evicts. 1: room, 0: not now (the maps held are in use, or it
 * was fetched ahead; maps_retry tries again). */
static int maps_make_room(struct worker *w, uint32_t pass, int demand)
{
    if (maps_room(w, pass))
        return 1;
    if (!demand)
        return 0;
    uint64_t held = maps_held_besides(w, pass, NULL);
    uint8_t *used = mem_alloc(w->num_maps);
    maps_in_use(w, used);
    while (!maps_fit(w, held)) {
        uint32_t victim = UINT32_MAX;
        for (uint32_t p = 0; p < w->num_maps; p++) {
            const struct pass_map *m = &w->maps[p], *v = victim == UINT32_MAX ? NULL : &w->maps[victim];
            if (p != pass && m->installed && !used[p] &&
                (!v || m->used > v->used || (m->used == v->used && m->last_use < v->last_use)))
                victim = p;
        }
        if (victim == UINT32_MAX)
            break;
        held -= w->maps[victim].decoded_bytes;
        map_evict(w, victim);
    }
    free(used);
    return maps_fit(w, held);
}

/* Maps whose blobs wait for room (map_install left them in the cache) are installed once
 * the units holding the others finish. Tried again only when that may have changed (a unit
 * finished or was parked, a map came or went: maps_changed) or every MAPS_RETRY_MS, not at
 * every turn of the loop (maps_make_room takes the pool's lock). 0, or -1 after an ERROR to
 * the master. */
static int maps_retry(struct worker *w, uint64_t now)
{
    if (!w->maps_waiting || !job_ready(w) || (!w->maps_changed && now - w->maps_retry_ms < MAPS_RETRY_MS))
        return 0;
    w->maps_changed = 0;
    w->maps_retry_ms = now;
    w->maps_waiting = 0; /* map_install sets it again for a map that still waits */
    for (uint32_t p = 0; p < w->num_maps; p++)
        if (w->maps[p].announced && !map_ready(w, p) && blob_store_get(&w->cache, &w->maps[p].hash) &&
            map_install(w, p) != 0)
            return -1;
    return 0;
}

/* Pass `pass`'s map, once its blob is in the cache: decoded (every size and index
 * checked) into the render job's slot, the blob dropped, and the units parked for it
 * handed to the render threads. 0 (also when the blob is not here yet), or -1 after an
 * ERROR to the master. */
static int map_install(struct worker *w, uint32_t pass)
{
    struct pass_map *pm = &w->maps[pass];
    if (!pm->announced)
        return 0;
    if (!map_ready(w, pass)) {
        const struct blob_entry *e = blob_store_get(&w->cache, &pm->hash);
        if (!e)
            return 0;
        int demand = 0;
        for (size_t i = 0; i < w->num_parked && !demand; i++)
            demand = w->parked[i].pass == pass;
        if (!maps_make_room(w, pass, demand)) { /* the blob waits in the cache (maps_retry) */
            w->maps_waiting = 1;
            return 0;
        }
        char err[256], text[PROTO_MAX_STRING];
        struct photon_map *map = NULL;
        /* the rows along the view of the scene's camera (the parser puts a moving camera's
         * first key there): the same axis for every worker and frame, whenever the map comes */
        const struct camera_desc *cd = &w->scene.camera;
        if (photon_map_decode_rows(e->data, e->size, photon_map_row_axis(v3_sub(cd->look_at, cd->position)), &map, err,
                                   sizeof err) != 0) {
            snprintf(text, sizeof text, "photon map of pass %u: %s", pass, err);
            log_error("%s", text);
            send_error(w, text);
            return -1;
        }
        uint64_t bytes = photon_map_bytes(map);
        render_job_set_pass_map(&w->rjob, pass, &map); /* replaces an installed one (the next frame's) */
        pm->installed = 1;
        pm->evicted = 0;
        pm->installed_hash = pm->hash;
        pm->decoded_bytes = bytes;
        map_touch(w, pass, 0);
        w->maps_decoded++;
        w->maps_changed = 1;
        if (bytes > w->map_bytes_max)
            w->map_bytes_max = bytes;
        uint32_t held;
        uint64_t held_bytes = maps_held_besides(w, UINT32_MAX, &held);
        if (held > w->maps_peak)
            w->maps_peak = held;
        if (held_bytes > w->maps_peak_bytes)
            w->maps_peak_bytes = held_bytes;
        struct blob_hash h = pm->hash;
        blob_store_drop(&w->cache, &h); /* decoded now; a later job announcing it again finds it installed */
        log_debug("photon map of pass %u installed (%llu bytes, %llu decoded; %u held, %llu bytes)", pass,
                  (unsigned long long)pm->size, (unsigned long long)bytes, held, (unsigned long long)held_bytes);
    }
    size_t k = 0;
    for (size_t i = 0; i < w->num_parked; i++) {
        if (w->parked[i].pass == pass) {
            map_touch(w, pass, 1);
            if (pool_push(&w->pool, &w->parked[i]) != 0)
                log_warn("dropping TILE %u: master exceeded our credits", w->parked[i].tile);
        } else {
            w->parked[k++] = w->parked[i];
        }
    }
    w->num_parked = k;
    return 0;
}

/* MAP: pass `pass` of the current job renders with this blob. The newest pass is fetched
 * at once (maps_prefetch, so it is here when its units come); an older one only when a
 * unit of it comes (a worker joining late fetches only what it renders). */
static int on_map(struct worker *w, const struct msg_map *mm)
{
    if (w->load.have_pending) { /* it names the JOB waiting for the load under way */
        if (w->load.num_pending_maps == w->load.cap_pending_maps) {
            w->load.cap_pending_maps = w->load.cap_pending_maps ? w->load.cap_pending_maps * 2 : 8;
            w->load.pending_maps = mem_realloc(w->load.pending_maps, sizeof *w->load.pending_maps * w->load.cap_pending_maps);
        }
        w->load.pending_maps[w->load.num_pending_maps++] = *mm;
        return 0;
    }
    if (!w->have_job || mm->job_id != w->job.job_id || mm->pass >= w->num_maps) {
        log_warn("master: MAP for job %llu pass %u dropped: not a pass of the current job (%u photon maps)",
                 (unsigned long long)mm->job_id, mm->pass, w->num_maps);
        return 0;
    }
    struct pass_map *pm = &w->maps[mm->pass];
    if (pm->fetch.recv.data && !blob_hash_equal(&pm->fetch.recv.hash, &mm->hash))
        blob_recv_fini(&pm->fetch.recv);
    if (!blob_hash_equal(&pm->hash, &mm->hash)) /* another map (the next frame's): never evicted */
        pm->evicted = 0;
    pm->hash = mm->hash;
    pm->size = mm->size;
    pm->announced = 1;
    if (mm->published > w->maps_published)
        w->maps_published = mm->published < w->num_maps ? mm->published : w->num_maps;
    for (size_t i = 0; i < w->num_parked; i++)
        if (w->parked[i].pass == mm->pass) {
            map_fetch_start(w, mm->pass);
            break;
        }
    return job_ready(w) ? map_install(w, mm->pass) : 0;
}

/* After the messages at hand: one map is fetched ahead of its units, into free room (it
 * evicts nothing), and never a map dropped for room (fetched again only for a unit of it).
 * Units come in pass order, so once the worker has units, that is the map of the pass after
 * the newest it was given, when announced: the next it needs, even when the tracer is
 * passes ahead. Before its first unit (a worker joining late) it is the newest map, once
 * its MAP has come: the MAPs of a late join can come in pieces, and an older one is fetched
 * only for a unit of it (its pass may be over). */
static void maps_prefetch(struct worker *w)
{
    uint32_t p = 0;
    if (w->tile_pass_max >= 0) {
        p = (uint32_t)w->tile_pass_max + 1;
        if (p >= w->num_maps || !w->maps[p].announced)
            return;
    } else {
        uint32_t newest = w->num_maps;
        for (uint32_t q = w->num_maps; q-- > 0;)
            if (w->maps[q].announced) {
                newest = q;
                break;
            }
        if (newest == w->num_maps || newest + 1 < w->maps_published)
            return;
        p = newest;
    }
    if (!w->maps[p].evicted && maps_room(w, UINT32_MAX)) /* map_fetch_start skips a map here */
        map_fetch_start(w, p);
}

static void kept_free_at(struct worker *w, size_t i)
{
    w->kept_bytes -= w->kept[i].chunk_size;
    free(w->kept[i].chunk);
    memmove(&w->kept[i], &w->kept[i + 1], sizeof *w->kept * (w->num_kept - i - 1)); /* oldest stay first */
    w->num_kept--;
}

/* Offers kept tile k to the master of the current job as KEPT (it was rendered for this
 * job key, under another connection). */
static void send_kept(struct worker *w, struct kept_tile *k)
{
    k->task.job_id = w->job.job_id; /* the ACK will name the current job */
    k->task.conn = w->conn;
    struct proto_msg m = {.type = MSG_KEPT};
    m.u.kept.job_id = w->job.job_id;
    m.u.kept.job_key = k->task.job_key;
    m.u.kept.frame = k->task.frame;
    m.u.kept.tile = k->task.tile;
    m.u.kept.tag = k->task.tag;
    m.u.kept.stats = k->stats;
    m.u.kept.chunk = k->chunk;
    m.u.kept.chunk_size = (uint32_t)k->chunk_size;
    worker_send(w, &m);
    w->kept_delivered++;
}

/* A job of this connection whose key the tile was rendered for. */
static int kept_matches_job(const struct worker *w, const struct kept_tile *k)
{
    return w->have_job && w->job_conn == w->conn && !w->lost && blob_hash_equal(&k->task.job_key, &w->job.job_key) &&
           k->task.frame == w->job.frame;
}

/* A finished tile: kept until acknowledged, sent as RESULT to the master that assigned
 * it, or as KEPT when that master is gone and the one now connected runs the same job. */
static void send_result(struct worker *w, struct tile_done *d)
{
    if (d->failed) {
        char text[PROTO_MAX_STRING];
        snprintf(text, sizeof text, "tile %u: %s", d->task.tile, d->err);
        log_error("%s", text);
        if (d->task.conn == w->conn)
            send_error(w, text);
        return;
    }
    while (w->num_kept > 0 && (w->num_kept >= KEPT_MAX_TILES || w->kept_bytes + d->chunk_size > KEPT_MAX_BYTES)) {
        log_warn("too many unacknowledged tiles; dropping tile %u of frame %u", w->kept[0].task.tile,
                 w->kept[0].task.frame);
        kept_free_at(w, 0);
    }
    if (w->num_kept == w->cap_kept) {
        w->cap_kept = w->cap_kept ? w->cap_kept * 2 : 16;
        w->kept = mem_realloc(w->kept, sizeof *w->kept * w->cap_kept);
    }
    struct kept_tile *k = &w->kept[w->num_kept++];
    k->task = d->task;
    k->stats = d->stats;
    k->chunk = d->chunk; /* the kept tile owns the chunk now */
    k->chunk_size = d->chunk_size;
    w->kept_bytes += d->chunk_size;
    d->chunk = NULL;
    w->tiles_done++;
    if (k->task.conn == w->conn && !w->lost) {
        struct proto_msg m = {.type = MSG_RESULT};
        m.u.result.job_id = k->task.job_id;
        m.u.result.frame = k->task.frame;
        m.u.result.tile = k->task.tile;
        m.u.result.attempt = k->task.attempt;
        m.u.result.stats = k->stats;
        m.u.result.chunk = k->chunk;
        m.u.result.chunk_size = (uint32_t)k->chunk_size;
        worker_send(w, &m);
    } else if (kept_matches_job(w, k)) {
        send_kept(w, k);
    }
}

static void on_ack(struct worker *w, const struct msg_ack *a)
{
    for (uint32_t i = 0; i < a->count; i++)
        for (size_t k = 0; k < w->num_kept; k++) {
            const struct tile_task *t = &w->kept[k].task;
            if (t->job_id == a->job_id && t->frame == a->frame && t->tile == a->tiles[i]) {
                kept_free_at(w, k);
                break;
            }
        }
}

/* Finished tiles waiting in the results socket go to the kept list (and out). */
static void drain_results(struct worker *w)
{
    struct tile_done *d;
    while (zmq_recv(w->results, &d, sizeof d, ZMQ_DONTWAIT) == (int)sizeof d) {
        w->maps_changed = 1; /* its unit no longer holds its pass's map */
        send_result(w, d);
        free(d->chunk);
        free(d);
    }
}

/* After a JOB: tiles kept for this job key (a master that came back on the same job)
 * are offered to it; tiles of earlier jobs of this same connection are dropped, since a
 * master moves to the next frame only after the last one is safely written. */
static void offer_kept(struct worker *w, int new_job_same_conn, uint64_t old_job_id)
{
    drain_results(w);
    uint32_t offered = 0;
    for (size_t i = 0; i < w->num_kept;) {
        struct kept_tile *k = &w->kept[i];
        if (new_job_same_conn && k->task.conn == w->conn && k->task.job_id == old_job_id) {
            kept_free_at(w, i);
            continue;
        }
        if (kept_matches_job(w, k) && (k->task.conn != w->conn || k->task.job_id != w->job.job_id)) {
            send_kept(w, k);
            offered++;
        }
        i++;
    }
    if (offered)
        log_info("offered %u finished tile(s) kept for this job to the master", offered);
}

/* Leaving: finish the tiles being rendered and send them, so a master that evicted us
 * (e.g. after SIGSTOP/SIGCONT) still sees them and counts them as late. */
static void flush_results(struct worker *w)
{
    pool_stop(&w->pool);
    drain_results(w);
}

/* A fresh socket and HELLO: a restarted master does not know our old connection, and
 * what was queued for the old one must not reach it. */
static int connect_master(struct worker *w)
{
    if (w->sock)
        zmq_close(w->sock);
    if (w->sub) { /* the next master may broadcast elsewhere */
        zmq_close(w->sub);
        w->sub = NULL;
    }
    /* Answers to the requests sent on the old socket will not come (a new socket is a new
     * peer to the master): the fetches ask again on the new one. */
    for (size_t i = 0; i < w->num_fetches + w->num_maps; i++)
        proto_fetch_lost(fetch_at(w, i));
    w->sock = zmq_socket(w->zctx, ZMQ_DEALER);
    net_socket_setup(w->sock);
    if (w->opts->curve_secret && net_curve_client(w->sock, &w->curve_server, &w->curve_pub, &w->curve_sec) != 0) {
        log_error("cannot enable CurveZMQ: %s", zmq_strerror(errno));
        return -1;
    }
    if (zmq_connect(w->sock, w->opts->endpoint) != 0) {
        log_error("cannot connect to %s: %s", w->opts->endpoint, zmq_strerror(errno));
        return -1;
    }
    w->conn++;
    w->conn_at_ms = net_now_ms();
    char host[256] = "";
    gethostname(host, sizeof host - 1);
    struct proto_msg hello = {.type = MSG_HELLO};
    hello.u.hello.threads = w->opts->threads;
    hello.u.hello.pid = (uint32_t)getpid();
    snprintf(hello.u.hello.host, sizeof hello.u.hello.host, "%s", host);
    worker_send(w, &hello);
    return 0;
}

int worker_run(const struct worker_opts *opts)
{
    struct worker w;
    memset(&w, 0, sizeof w);
    w.opts = opts;
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN); /* a master that vanished is noticed by silence, not a signal */
    w.zctx = zmq_ctx_new();
    w.results = zmq_socket(w.zctx, ZMQ_PULL);
    net_socket_setup(w.results);
    w.progress = mem_calloc(opts->threads, sizeof *w.progress);
    int rc = 1;
    if (opts->curve_secret) {
        char err[512] = "";
        if (net_key_pair_load(opts->curve_secret, &w.curve_pub, &w.curve_sec, err, sizeof err) != 0 ||
            net_key_public_load(opts->server_key, &w.curve_server, err, sizeof err) != 0) {
            log_error("%s", err);
            goto done;
        }
    }
    w.load.efd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (w.load.efd < 0) {
        log_error("eventfd: %s", strerror(errno));
        goto done;
    }
    asset_set_stop_flag(&w.load.cancel); /* the scene parsers stop early when a load is cancelled */
    if (zmq_bind(w.results, "inproc://results") != 0) {
        log_error("cannot bind the results socket: %s", zmq_strerror(errno));
        goto done;
    }
    if (connect_master(&w) != 0)
        goto done;

    uint64_t last_heard = net_now_ms(), last_beat = net_now_ms(), last_tick = net_now_ms();
    while (!g_stop) {
        zmq_pollitem_t items[4] = {{w.sock, 0, ZMQ_POLLIN, 0}, {w.results, 0, ZMQ_POLLIN, 0},
                                   {NULL, w.load.efd, ZMQ_POLLIN, 0}, {w.sub, 0, ZMQ_POLLIN, 0}};
        int n = zmq_poll(items, w.sub ? 4 : 3, 200);
        if (n < 0 && errno != EINTR) {
            log_error("poll: %s", zmq_strerror(errno));
            goto done;
        }
        uint64_t now = net_now_ms();
        if (w.num_parked > 0 && pool_idle(&w))
            w.map_wait_ms += now - last_tick;
        last_tick = now;
        if (items[1].revents & ZMQ_POLLIN)
            drain_results(&w);
        if ((items[2].revents & ZMQ_POLLIN) && w.load.running && load_finish(&w) != 0)
            goto done;
        if (items[0].revents & ZMQ_POLLIN) {
            struct net_frame f;
            int got;
            /* At most DRAIN_MAX_MS of messages in a row (a blob fetch keeps them coming):
             * then the heartbeat below goes out, and the poll finds the rest at once. */
            while (net_now_ms() - now < DRAIN_MAX_MS && (got = net_recv(w.sock, 0, &f)) != 0) {
                if (got < 0) {
                    log_warn("master: malformed envelope dropped");
                    continue;
                }
                struct proto_msg m;
                char err[256];
                if (proto_decode(f.data, f.size, &m, err, sizeof err) != 0) {
                    log_warn("master: message dropped: %s", err);
                    net_frame_fini(&f);
                    continue;
                }
                last_heard = now;
                if (w.lost) {
                    log_info("the master at %s answers again", opts->endpoint);
                    w.lost = 0;
                }
                int fatal = 0;
                switch (m.type) {
                case MSG_JOB:
                    fatal = on_job(&w, &m.u.job) != 0;
                    break;
                case MSG_ACK:
                    on_ack(&w, &m.u.ack);
                    break;
                case MSG_BLOB_DATA:
                    fatal = on_blob_data(&w, &m.u.blob_data, 0) != 0;
                    break;
                case MSG_CHUNKS:
                    fatal = on_chunks(&w, &m.u.chunks) != 0;
                    break;
                case MSG_TILE:
                    on_tile(&w, &m.u.tile);
                    break;
                case MSG_MAP:
                    fatal = on_map(&w, &m.u.map) != 0;
                    break;
                case MSG_HEARTBEAT:
                    break;
                case MSG_BYE:
                    flush_results(&w);
                    rc = 0;
                    g_stop = 1;
                    break;
                default:
                    log_warn("master: unexpected %s message dropped", proto_type_name(m.type));
                }
                net_frame_fini(&f);
                if (fatal)
                    goto done;
            }
        }
        if (w.sub && (items[3].revents & ZMQ_POLLIN)) {
            for (size_t i = 0; i < w.num_fetches + w.num_maps; i++)
                proto_fetch_bcast_alive(fetch_at(&w, i), now);
            struct net_frame f;
            int got;
            while (net_now_ms() - now < DRAIN_MAX_MS && w.sub && (got = net_recv(w.sub, 1, &f)) != 0) {
                int fatal = got > 0 && on_bcast_frame(&w, &f) != 0;
                net_frame_fini(&f);
                if (fatal)
                    goto done;
            }
        }
        maps_prefetch(&w);
        if (maps_retry(&w, net_now_ms()) != 0)
            goto done;
        if (fetches_pump(&w) != 0)
            goto done;
        now = net_now_ms();
        if (!w.lost && now - last_heard > MASTER_LOST_MS && now - w.conn_at_ms > MASTER_LOST_MS) {
            log_warn("no word from the master at %s for %llu ms; reconnecting (%zu finished tile(s) kept)",
                     opts->endpoint, (unsigned long long)(now - last_heard), w.num_kept);
            w.lost = 1;
            w.backoff_ms = BACKOFF_FIRST_MS;
            w.reconnects++;
            if (connect_master(&w) != 0)
                goto done;
        } else if (w.lost && now - w.conn_at_ms >= w.backoff_ms) {
            w.backoff_ms = w.backoff_ms == 0 ? BACKOFF_FIRST_MS
                           : w.backoff_ms * 2 > BACKOFF_MAX_MS ? BACKOFF_MAX_MS : w.backoff_ms * 2;
            w.reconnects++;
            if (connect_master(&w) != 0)
                goto done;
        }
        if (!w.lost && now - last_beat >= HEARTBEAT_MS) {
            struct proto_msg hb = {.type = MSG_HEARTBEAT};
            hb.u.heartbeat.job_id = w.have_job ? w.job.job_id : 0;
            hb.u.heartbeat.tiles_done = w.tiles_done;
            uint64_t stalled = 0;
            for (uint32_t i = 0; i < opts->threads; i++) {
                hb.u.heartbeat.samples_done += atomic_load(&w.progress[i].samples);
                uint64_t last = atomic_load(&w.progress[i].last_ms);
                if (atomic_load(&w.progress[i].busy) && now > last && now - last > stalled)
                    stalled = now - last;
            }
            hb.u.heartbeat.stalled_ms = stalled > UINT32_MAX ? UINT32_MAX : (uint32_t)stalled;
            hb.u.heartbeat.map_wait_ms = w.map_wait_ms > UINT32_MAX ? UINT32_MAX : (uint32_t)w.map_wait_ms;
            worker_send(&w, &hb);
            last_beat = now;
        }
        if (now - last_heard > opts->master_timeout_ms) {
            log_error("no word from the master at %s for %u ms; giving up", opts->endpoint, opts->master_timeout_ms);
            goto done;
        }
    }
    if (g_stop && rc != 0)
        rc = 0; /* stopped by a signal or BYE: a clean exit */
done:
    log_info("rendered %u tile(s); %u offered again to a master that came back; %u reconnection(s)",
             atomic_load(&w.tiles_rendered), w.kept_delivered, w.reconnects);
    if (w.maps_decoded)
        log_info("photon maps: %llu decoded, at most %u held at once (%.1f MiB, budget %.1f MiB); %llu evicted, "
                 "%llu bytes fetched again", (unsigned long long)w.maps_decoded, w.maps_peak,
                 (double)w.maps_peak_bytes / 1048576.0, (double)opts->map_memory_bytes / 1048576.0,
                 (unsigned long long)w.maps_evicted, (unsigned long long)w.map_refetch_bytes);
    unload_job(&w);
    pending_drop(&w);
    free(w.load.pending_maps);
    if (w.load.efd > 0)
        close(w.load.efd);
    asset_set_stop_flag(NULL);
    free(w.parked);
    while (w.num_kept > 0)
        kept_free_at(&w, w.num_kept - 1);
    free(w.kept);
    blob_store_fini(&w.cache);
    proto_buf_fini(&w.out);
    zmq_close(w.results);
    if (w.sub)
        zmq_close(w.sub);
    if (w.sock)
        zmq_close(w.sock);
    zmq_ctx_term(w.zctx);
    free(w.progress);
    return rc;
}
