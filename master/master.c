/* Master loop (see master.h). One thread: zmq_poll on the ROUTER socket (and the ZAP
 * socket when CurveZMQ is on) drives everything (hello, blob serving, credits, results,
 * liveness), so no state is shared between threads. Who gets which tile, which result
 * counts, blame and bans are decided by the pure scheduler (sched.h); this file turns
 * messages and the clock into its events and its decisions into messages, logs and
 * counters. A result the scheduler takes is kept only after its chunk decodes to finite
 * pixels of the right size and after it is in the journal. Frame files: output.h. */
#include "master.h"
#include "base/asset.h"
#include "wire/blob.h"
#include "image/imgio.h"
#include "journal.h"
#include "outnames.h"
#include "launch.h"
#include "base/log.h"
#include "wire/fetch.h"
#include "wire/net.h"
#include "wire/proto.h"
#include "zap.h"
#include "output.h"
#include "fold.h"
#include "adapt.h"
#include "photons.h"
#include "sched.h"
#include "check.h"
#include "peerindex.h"
#include "render/aov.h"
#include "render/integrator.h"
#include "render/media_integrator.h"
#include "render/photon_trace.h"
#include "scene/scene_json.h"
#include "render/tile.h"
#include <errno.h>
#include <stdarg.h>
#include <fcntl.h>
#include <libgen.h>
#include <float.h>
#include <math.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zmq.h>

#define MAX_PEERS 4096          /* live workers at once */
#define MAX_SLOTS (2 * MAX_PEERS) /* peer slots; past this, a gone worker's slot is reused */
#define MAX_PEERS_PER_KEY 1024  /* live workers of one identity (one key, or all without CurveZMQ) */
/* Bytes of BLOB_DATA answers libzmq may hold for one peer slot (queued, not yet written to
 * the connection). A worker keeps at most PROTO_FETCH_WINDOW requests in flight over all
 * its fetches (FETCH_REQUESTS_MAX), so it never meets the cap: only a peer that asks for
 * more and stops reading does, and the answers past it are dropped. */
#define BLOB_QUEUED_PER_PEER ((PROTO_FETCH_WINDOW + 1u) * BLOB_CHUNK_SIZE)
#define PROGRESS_PLAIN_MS 5000
#define PROGRESS_TTY_MS 250
/* Adaptive defaults (docs/adaptive.md): the spp cap without --spp, and the samples of a
 * pass (each pass is an independently scrambled set, so a larger one keeps more of the
 * sampler's stratification; a smaller one adapts in finer steps). */
#define MASTER_ADAPT_SPP_CAP 4096u
#define MASTER_ADAPT_PASS_SPP 8u
/* Who a worker is; its scheduling state is m->sched->workers[same index]. */
struct peer {
    uint8_t id[NET_MAX_IDENTITY];
    size_t id_len;
    char user_id[NET_Z85_KEY_LEN + 1]; /* with CurveZMQ: its public key (what it proved), else "" */
    int job_sent;           /* it was sent the JOB (only then does it get blobs) */
    uint64_t job_retry_ms;  /* a JOB that could not be queued is tried again from then on */
    uint32_t maps_sent;     /* passes 0..maps_sent-1 of its JOB had their MAP queued (send_maps) */
    char name[300];         /* host:pid it claims, for messages only: never who it is */
    uint32_t pid;
    uint32_t dropped;       /* messages of this peer dropped; only the first few are logged */
    uint64_t *map_bytes;    /* per pass: bytes of that pass's map blob it fetched (asked the chunk list of: the
                             * broadcast or point to point brings them) */
    uint64_t *wait_ms;      /* per pass: ms it was ready with credits while that pass's map was not published */
    uint64_t live_ms;       /* ms it was a ready worker of a frame */
    uint64_t fetch_wait_ms; /* ms it reported waiting for a map fetch with nothing to render (heartbeats) */
    uint64_t fetch_wait_job;  /* the job of its last report, and the ms it had reported for it */
    uint32_t fetch_wait_last;
};

/* A pass's photon map as published: its blob (among the blobs served), once traced. */
struct pass_map {
    struct blob_hash hash;
    uint64_t size;
    double seconds;         /* tracing time */
};

/* RESULTs the checker pool may hold per thread before a worker's credit waits for its
 * RESULT's check (on_result): about 28 MB a thread at 32 px tiles. */
#define MASTER_POOL_BACKLOG 256u

/* What happened, for tests and operators: OUT.stats.json ("counters"), and with
 * --verbose "summary: counter NAME VALUE" lines. */
#define COUNTERS(X)                                                                                                \
    X(tiles_assigned) X(tiles_done) X(tiles_from_journal) X(tiles_reissued) X(straggler_copies)                   \
    X(results_stale) X(results_duplicate) X(results_invalid) X(results_not_ours) X(rejected_decode)               \
    X(rejected_envelope) X(rejected_unknown_peer) X(rejected_unexpected) X(rejected_wrong_job)                    \
    X(rejected_blob_req) X(blob_reqs_dropped) X(rejected_banned) X(auth_rejects) X(handshake_failures) X(evicted_silent)                \
    X(evicted_stalled) X(evicted_died) X(evicted_error) X(workers_banned) X(workers_joined) X(ready_stale)         \
    X(local_restarts) X(kept_untied) X(results_nonfinite) X(hellos_refused)                                       \
    X(frames_done) X(frames_skipped) X(tiles_from_kept) X(kept_duplicate) X(acks_sent) X(journal_syncs)                   \
    X(blob_bytes_p2p) X(blob_bytes_bcast) X(bcast_subscriptions) X(results_in_pool_max)
struct counters {
#define X(n) uint64_t n;
    COUNTERS(X)
#undef X
};

/* A tile a worker may forget once the journal is on disk up to byte `need`. */
struct pending_ack { int32_t peer; uint64_t job_id; uint32_t frame, tile; uint64_t need; };

/* A blob on the broadcast socket: its chunk list, and the stream's place. A subscription
 * to the hash (re)starts it: BCAST_GATHER_MS later, so that the workers given the same
 * JOB share one pass; one arriving during a pass extends it by a full cycle from there. */
struct bcast_stream {
    struct blob_hash hash;
    uint64_t size, num_chunks;
    struct blob_hash *chunk_hashes;
    uint64_t cursor;            /* the next chunk to send */
    uint64_t remaining;         /* chunks left in this pass (0: idle) */
    uint64_t start_ms;          /* a pass waiting to start: when (0: none) */
};

struct master {
    const struct master_opts *opts;
    void *zctx, *sock;
    void *bcast;                /* the XPUB socket blobs are streamed on, or NULL (docs/cluster.md) */
    uint16_t bcast_port;        /* its tcp port (0: no tcp endpoint) */
    char bcast_ipc[2][400];     /* its socket files (removed at the end) */
    struct bcast_stream *streams;
    size_t num_streams, cap_streams;
    double bcast_tokens;        /* bytes the pacing allows now */
    uint64_t bcast_last_ms;
    struct zap *zap;            /* CurveZMQ admission, or NULL */
    struct net_key curve_pub, curve_sec; /* the master's key pair, with zap */
    struct blob_hash tag_key;   /* MAC key of TILE tags: from the master's secret key (random without one) */
    int tcp_open;               /* a tcp:// bind without CurveZMQ (--insecure): nobody is known */
    uint32_t hellos_logged;
    struct proto_buf out;
    struct asset_dir assets;
    struct blob_store blobs;
    struct proto_asset *manifest;
    uint32_t num_manifest;
    char scene_rel[ASSET_PATH_MAX];
    char base_hash[65];         /* names, contents and settings (a per-frame photon map: that frame's) */
    int map_per_frame;          /* the photon map depends on the frame (master_media_per_frame) */
    uint32_t map_frame;         /* the frame the photon maps are traced for */
    uint32_t scene_frame;       /* the frame the scene was parsed for (its per-frame files) */
    int scene_loaded;
    int maps_started;           /* a tracer was started (the maps of map_frame are being or were traced) */
    char scene_hash[65];        /* base_hash and the frame: what the output header records */
    struct scene scene;
    struct image_desc desc;
    uint64_t job_id;            /* this frame's job: job_base + frames started before it */
    uint64_t job_base;
    struct blob_hash job_key;   /* what fixes this frame's pixels; the same after a restart */
    uint32_t frame;
    char out_path[4000];        /* this frame's output file */
    struct sched *sched;        /* tiles, attempts, holders, blame, bans (sched.h) */
    struct output_chunk *chunks;  /* per tile, once done */
    uint64_t *tile_nans;          /* per tile: NaN/Inf samples dropped this frame (nan_report) */
    uint32_t *tile_nan_pass;      /* per tile: the first pass that had one */
    uint32_t num_tiles;
    struct peer *peers;
    uint32_t num_peers;
    struct peer_index peer_index; /* peers by routing id (find_peer), every slot that holds one */
    pid_t *local_pids;
    uint32_t num_local, local_alive;
    uint32_t local_restarts;    /* local workers started again after one died or was evicted */
    uint64_t last_waiting_ms;   /* the last "waiting for workers" line (no live worker) */
    uint64_t last_liveness_ms;  /* the last check_liveness (every LIVENESS_MS, not every pass) */
    int sends_behind;           /* a JOB or MAP could not be queued to some peer: assign_tiles
                                 * looks for peers still owed one (set by send_job, send_maps) */
    struct tile_stats stats;
    struct counters c;
    char last_worker_error[PROTO_MAX_STRING];
    char fatal[2048];           /* set when the job cannot finish: the reason, printed last */
    int journal_busy;           /* refused: another master renders to this output (no stats written) */
    double wall_seconds;        /* of the frames rendered */
    uint32_t passes;            /* passes of the frame (adaptive: the most a tile gets); 1: a unit is a tile */
    uint32_t spp_per_pass;      /* spp / passes */
    uint32_t photon_maps;       /* photon maps: 0 (none) or passes */
    struct image_desc out_desc; /* the output's layout: desc, and with passes the samples channel */
    struct adapt *adapt;        /* adaptive rounds (target error or time limit), or NULL */
    double target_error, time_limit; /* adaptive settings (0: none) */
    double pixel_error;         /* adaptive: the per-pixel bound (0: none) */
    uint32_t max_rounds;
    int time_up;                /* the time limit passed: the round under way is the last */
    const char *adapt_stop;     /* why the rounds ended (a static string), or NULL before */
    uint32_t *round_from;       /* per block (adapt's tiles): its passes before the round being released */
    uint32_t blocks_side, num_cells; /* adaptive: blocks in a tile's row (render/tile.h), blocks of the frame */
    uint32_t *slots_used;       /* adaptive, per tile: its units released so far (slots 0..n-1) */
    uint32_t *slot_pass;        /* adaptive, per unit: the sample pass it renders */
    uint64_t *slot_mask;        /* adaptive, per unit: the tile's blocks it renders */
    uint32_t num_units;         /* units (tile, pass): u = pass * num_tiles + tile (adaptive: slot * num_tiles + tile) */
    struct fold *fold;          /* passes >= 2: a tile's pass means folded in pass order */
    struct imgio_encoder *enc;  /* encodes folded tiles */
    float *fold_out;
    void *fold_scratch;         /* fold_run's without the checker pool */
    size_t fold_scratch_size;
    struct pass_map *maps;      /* per pass */
    uint32_t maps_published;    /* passes 0..maps_published-1 have their map announced */
    uint32_t maps_frame;        /* the frame the maps are traced for */
    struct photon_tracer *tracer; /* tracing the rest of the maps, or NULL */
    double rel_rmse_est;        /* the last frame's estimated relRMSE from its variance channels (error_estimate) */
    struct fold_est *est;       /* its sums, fed each final tile's pixels as they are decoded or folded */
    uint64_t var_saturated;     /* its pixels whose variance channel is saturated (tile_variance_value) */
    float *decode_scratch;
    uint64_t results_in_pool;   /* RESULTs handed to the checker pool and not taken back */
    float *decode_keep;         /* the checked unit's copy for the fold (check_item.keep), while
                                 * result_verdict decides on it; NULL when the loop decoded */
    struct check_ctx check_ctx; /* what chunks of this frame must be (chunk_check) */
    struct checker *checker;    /* checks RESULT chunks off the loop (--check-threads), or NULL: in the loop */
    char ipc_dir[256];
    char ipc_endpoint[320];
    struct journal *journal;    /* this frame's, or NULL (--no-journal, --tiles, after the output is in place) */
    char banned_names[16][400]; /* ban_key: key and claimed name */
    uint32_t num_banned;
    uint32_t stranger_drops_logged;
    struct pending_ack *acks;   /* tiles to acknowledge once the journal is synced */
    uint32_t num_acks, cap_acks;
    char local_key_path[400], local_pub_path[400];
    struct net_key local_public; /* with CurveZMQ: the key the local workers prove ("" without) */
};

static atomic_int g_interrupted; /* lock-free: safe in the handler (asset.h) */
/* SIGINT / SIGTERM: the render loop polls the flag; a photon pass stops at its next photon. */
static void on_signal(int sig)
{
    (void)sig;
    g_interrupted = 1;
    photon_trace_request_stop();
}

/* ---- setup ---- */

static int publish_manifest(struct master *m);
static int bind_endpoint(struct master *m, const char *endpoint);

/* Records why the job cannot finish (the first reason wins): master_run prints it last,
 * after the workers are stopped, and writes it into the stats file. */
static void master_fail(struct master *m, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void master_fail(struct master *m, const char *fmt, ...)
{
    if (m->fatal[0])
        return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(m->fatal, sizeof m->fatal, fmt, ap);
    va_end(ap);
}

/* Per-frame files: every frame of the range has its own (checked before the first frame
 * renders, so a missing grid does not stop a long range half way; up to FRAMES_CHECK_MAX
 * frames, the rest when their frame starts). A missing one is reported as the parse of its
 * frame reports it: the scene's file:line:col, the frame and the file. */
#define FRAMES_CHECK_MAX 100000u
static int check_frame_files(struct master *m, const char *text, size_t len)
{
    const struct master_opts *o = m->opts;
    if (!o->have_frames || !m->scene.frame_files)
        return 0;
    uint64_t n = 0;
    for (uint64_t f = o->frame_first; f <= o->frame_last && n < FRAMES_CHECK_MAX; f += o->frame_step, n++)
        for (uint32_t i = 0; i < m->scene.frame_files; i++) {
            char name[ASSET_PATH_MAX], path[sizeof m->assets.root + ASSET_PATH_MAX + 2];
            struct stat st;
            if (asset_frame_name(m->scene.frame_patterns[i], (uint32_t)f, name, sizeof name) < 0)
                continue; /* the parse of that frame says so */
            snprintf(path, sizeof path, "%s/%s", m->assets.root, name);
            if (stat(path, &st) == 0 && S_ISREG(st.st_mode))
                continue;
            struct asset_dir dir;
            struct scene sc;
            char err[1024];
            if (asset_dir_init(&dir, m->assets.root, err, sizeof err) == 0) {
                struct asset_source src = asset_dir_source(&dir);
                if (scene_json_parse_frame(o->scene_path, text, len, &src, NULL, (uint32_t)f, &sc, err, sizeof err) == 0) {
                    scene_fini(&sc); /* there after all */
                    err[0] = '\0';
                }
                asset_dir_fini(&dir);
            }
            if (err[0]) {
                master_fail(m, "%s", err);
                return -1;
            }
        }
    return 0;
}

/* Whether the frame renders in adaptive rounds (docs/adaptive.md). */
static int master_adaptive(const struct master *m)
{
    return m->target_error > 0.0 || m->pixel_error > 0.0 || m->time_limit > 0.0 || m->max_rounds > 0;
}

/* Parses the scene for `frame` (its per-frame files: scene.frame_files), applies the
 * command line, plans the passes and publishes the manifest. Called once before the first
 * frame, and again at each frame of a scene with per-frame files (scene_reload), where
 * everything but those files comes out the same. */
static int load_scene(struct master *m, uint32_t frame)
{
    const struct master_opts *o = m->opts;
    char err[1024];
    char dir_buf[4096], base_buf[4096];
    snprintf(dir_buf, sizeof dir_buf, "%s", o->scene_path);
    snprintf(base_buf, sizeof base_buf, "%s", o->scene_path);
    const char *dir = dirname(dir_buf);
    snprintf(m->scene_rel, sizeof m->scene_rel, "%s", basename(base_buf));
    if (asset_dir_init(&m->assets, dir, err, sizeof err) != 0) {
        master_fail(m, "%s", err);
        return -1;
    }
    asset_set_stop_flag(&g_interrupted); /* a signal stops a long parse too */
    char *text = NULL;
    size_t len = 0;
    if (asset_dir_read(&m->assets, m->scene_rel, &text, &len, err, sizeof err) != 0) {
        master_fail(m, "%s: %s", o->scene_path, err);
        return -1;
    }
    struct asset_source src = asset_dir_source(&m->assets);
    int rc = scene_json_parse_frame(o->scene_path, text, len, &src, NULL, frame, &m->scene, err, sizeof err);
    if (rc != 0 || outnames_check(o, &m->assets, err, sizeof err) != 0) {
        free(text);
        master_fail(m, "%s", err);
        return -1;
    }
    rc = m->scene_loaded ? 0 : check_frame_files(m, text, len);
    free(text);
    if (rc != 0)
        return -1;
    /* The output's folder takes a new file: checked now, not after the render. */
    char first[4096];
    if (output_frame_path(o->output_path, o->have_frames, o->have_frames ? o->frame_first : 0, first, sizeof first) == 0 &&
        output_check_writable(first, err, sizeof err) != 0) {
        master_fail(m, "%s", err);
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
    rs->embree_isa = (enum embree_isa)o->embree_isa;
    if (o->have_aovs)
        rs->aovs = o->aovs;
    if (o->have_filter) {
        m->scene.camera.filter = o->filter;
        m->scene.camera.filter_width = o->filter_width;
    }
    if (scene_validate(&m->scene, err, sizeof err) != 0) {
        master_fail(m, "%s: %s", o->scene_path, err);
        return -1;
    }
    if (!m->scene_loaded) /* a still scene's maps: the first frame's, even when it is skipped */
        m->map_frame = frame;
    m->scene_frame = frame;
    m->scene_loaded = 1;
    uint32_t asked = o->have_passes ? o->passes : rs->passes;
    m->target_error = o->have_target_error ? o->target_error : rs->target_error;
    m->time_limit = o->have_time_limit ? o->time_limit : rs->time_limit;
    m->pixel_error = o->have_pixel_error ? o->pixel_error : rs->pixel_error;
    m->max_rounds = o->have_max_rounds ? o->max_rounds : 0;
    int adaptive = master_adaptive(m);
    if (adaptive) {
        /* --spp is the cap; passes of MASTER_ADAPT_PASS_SPP samples unless --passes says. */
        if (!o->have_spp)
            rs->spp = MASTER_ADAPT_SPP_CAP;
        if (!asked)
            asked = (rs->spp + MASTER_ADAPT_PASS_SPP - 1) / MASTER_ADAPT_PASS_SPP;
        asked = asked < 2 ? 2 : asked > PROTO_MAX_PASSES ? PROTO_MAX_PASSES : asked;
    }
    if (master_media_prepare(&m->scene, o, frame, &m->assets, asked, &m->photon_maps) != 0)
        return -1;
    m->passes = m->photon_maps ? m->photon_maps : asked > 1 ? asked : 1;
    if (!m->photon_maps && !asked && rs->spp >= SAMPLER_STREAMS && rs->spp % SAMPLER_STREAMS == 0)
        m->passes = SAMPLER_STREAMS; /* default: one pass per stream, a truthful estimate (docs/adaptive.md) */
    if (!m->photon_maps && m->passes > SAMPLER_STREAMS && m->passes % SAMPLER_STREAMS) {
        /* Every stream holds as many passes (docs/adaptive.md). */
        uint32_t p = (m->passes + SAMPLER_STREAMS - 1) / SAMPLER_STREAMS * SAMPLER_STREAMS;
        log_info("passes: %u raised to %u, a multiple of the sampler's %u streams", m->passes, p,
                 (unsigned)SAMPLER_STREAMS);
        m->passes = p;
    }
    if (!m->photon_maps && m->passes > 1) {
        if (master_passes_fit(rs, m->passes) != 0)
            return -1;
        log_info("passes: %u of %u spp (%u spp) in %u stream(s); error estimate from batch means over the streams",
                 m->passes, rs->spp / m->passes, rs->spp, m->passes < SAMPLER_STREAMS ? m->passes : (unsigned)SAMPLER_STREAMS);
    }
    m->spp_per_pass = rs->spp / m->passes;
    if (adaptive)
        log_info("adaptive: target relRMSE %g, per-pixel bound %g, time limit %g s, at most %u passes of %u spp per tile "
                 "(%u spp)%s", m->target_error, m->pixel_error, m->time_limit, m->passes, m->spp_per_pass, rs->spp,
                 m->max_rounds ? ", round cap set" : "");
    m->map_per_frame = master_media_per_frame(&m->scene);
    return publish_manifest(m);
}

/* Publishes every file the parse read (and the volume blob) as blobs and the job's
 * manifest; the base hash covers names, contents and settings. */
static int publish_manifest(struct master *m)
{
    const struct master_opts *o = m->opts;
    const struct render_settings *rs = &m->scene.settings;
    for (uint32_t i = 0; i < m->num_manifest; i++) /* the last frame's files (scene_reload) */
        blob_store_drop(&m->blobs, &m->manifest[i].hash);
    free(m->manifest);
    m->manifest = NULL;
    m->num_manifest = (uint32_t)m->assets.num_files;
    if (m->num_manifest > PROTO_MAX_ASSETS) {
        master_fail(m, "%s: %u files, more than the %u a job can carry", o->scene_path, m->num_manifest, PROTO_MAX_ASSETS);
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
    char settings[512];
    int sl = snprintf(settings, sizeof settings,
                      "%ux%u spp=%u depth=%u seed=%llu sampler=%u photon_maps=%u passes=%u aovs=%u filter=%u/%.9g "
                      "isa=%s",
                      rs->width, rs->height, rs->spp, rs->max_depth, (unsigned long long)rs->seed,
                      (unsigned)rs->sampler, m->photon_maps, m->passes, rs->aovs, m->scene.camera.filter,
                      (double)m->scene.camera.filter_width, embree_isa_name(rs->embree_isa));
    /* What the command line can set beside the scene file and the pixels depend on: the
     * media's method and photon settings, and an adaptive render's rules (not a time limit:
     * where it stops is timing, docs/adaptive.md). A frame of --frames counts as done only
     * with all of them the same (output_is_done compares this hash). */
    const struct scene_media *sm = m->scene.media;
    if (sm)
        sl += snprintf(settings + sl, sizeof settings - (size_t)sl, " media=%u/%u/%llu/%.9g/%.9g/%.9g",
                       (unsigned)sm->method, (unsigned)sm->indirect, (unsigned long long)sm->photons,
                       (double)sm->radius, (double)sm->step, (double)sm->alpha);
    if (m->target_error > 0.0 || m->pixel_error > 0.0 || m->max_rounds)
        sl += snprintf(settings + sl, sizeof settings - (size_t)sl, " target=%.17g pixel=%.17g rounds=%u",
                       m->target_error, m->pixel_error, m->max_rounds);
    CHECK(sl > 0 && (size_t)sl < sizeof settings);
    mem_grow((void **)&h.data, &h.cap, h.size + (size_t)sl, 1);
    memcpy(h.data + h.size, settings, (size_t)sl);
    h.size += (size_t)sl;
    struct blob_hash sh;
    blob_hash_compute(h.data, h.size, &sh);
    blob_hash_hex(&sh, m->base_hash);
    proto_buf_fini(&h);
    return 0;
}

/* The frame is part of what fixes the pixels (motion, and every random number), so it
 * is part of the hash that output headers and journals are matched against. */
static void frame_hash(struct master *m)
{
    char text[128];
    int n = snprintf(text, sizeof text, "%s frame=%u", m->base_hash, m->frame);
    struct blob_hash h;
    blob_hash_compute(text, (size_t)n, &h);
    blob_hash_hex(&h, m->scene_hash);
}

/* Adaptive: the block (adapt's tile) of block b of tile t. */
static uint32_t cell_of(const struct master *m, uint32_t t, uint32_t b)
{
    uint32_t tiles_x = imgio_tiles_x(&m->desc), side = m->blocks_side;
    return ((t / tiles_x) * side + b / side) * (tiles_x * side) + (t % tiles_x) * side + b % side;
}

static void setup_tiles(struct master *m)
{
    const struct render_settings *rs = &m->scene.settings;
    tile_image_desc(&m->desc, rs);
    m->num_tiles = imgio_tiles_x(&m->desc) * imgio_tiles_y(&m->desc);
    m->num_units = m->num_tiles * m->passes;
    m->sched = sched_new(m->num_units);
    m->chunks = mem_calloc(m->num_tiles, sizeof *m->chunks);
    m->tile_nans = mem_calloc(m->num_tiles, sizeof *m->tile_nans);
    m->tile_nan_pass = mem_calloc(m->num_tiles, sizeof *m->tile_nan_pass);
    m->decode_scratch = mem_alloc(sizeof(float) * rs->tile_size * rs->tile_size * FOLD_MAX_CHANNELS);
    m->maps = mem_calloc(m->passes, sizeof *m->maps);
    m->out_desc = m->desc;
    if (m->passes > 1) {
        m->fold = fold_new(&m->desc, m->passes, m->spp_per_pass, integrator_streams(m->photon_maps > 0));
        m->fold_out = mem_alloc(sizeof(float) * rs->tile_size * rs->tile_size * FOLD_MAX_CHANNELS);
        fold_output_desc(&m->desc, &m->out_desc);
    }
    m->est = fold_est_new(&m->out_desc);
    if (master_adaptive(m)) {
        /* The rounds allocate per pixel block: adapt's "tiles" are the blocks of every tile,
         * in a grid of tiles_x x side blocks a row (docs/adaptive.md). */
        uint32_t tiles_x = imgio_tiles_x(&m->desc), side = tile_blocks_side(rs->tile_size);
        uint32_t bs = tile_block_size(rs->tile_size), cells_x = tiles_x * side;
        m->blocks_side = side;
        m->num_cells = m->num_tiles * side * side;
        uint32_t *pixels = mem_calloc(m->num_cells, sizeof *pixels);
        for (uint32_t t = 0; t < m->num_tiles; t++) {
            uint32_t x0, y0, w, h;
            imgio_tile_rect(&m->desc, t % tiles_x, t / tiles_x, &x0, &y0, &w, &h);
            for (uint32_t b = 0; b < side * side; b++) {
                uint32_t bx = b % side * bs, by = b / side * bs;
                uint32_t bw = bx < w ? (w - bx < bs ? w - bx : bs) : 0, bh = by < h ? (h - by < bs ? h - by : bs) : 0;
                pixels[cell_of(m, t, b)] = bw * bh;
            }
        }
        m->adapt = adapt_new(m->num_cells, cells_x, pixels, m->passes, integrator_streams(m->photon_maps > 0),
                             m->target_error, m->max_rounds);
        adapt_set_pass_spp(m->adapt, m->spp_per_pass);
        adapt_set_pixel_error(m->adapt, m->pixel_error);
        m->round_from = mem_calloc(m->num_cells, sizeof *m->round_from);
        m->slots_used = mem_calloc(m->num_tiles, sizeof *m->slots_used);
        m->slot_pass = mem_calloc(m->num_units, sizeof *m->slot_pass);
        m->slot_mask = mem_calloc(m->num_units, sizeof *m->slot_mask);
        free(pixels);
    }
}

/* Tile, pass and blocks of unit u (adaptive: what its slot was released for). */
static uint32_t unit_tile(const struct master *m, uint32_t u) { return u % m->num_tiles; }
static uint32_t unit_pass(const struct master *m, uint32_t u) { return m->adapt ? m->slot_pass[u] : u / m->num_tiles; }
static uint64_t unit_mask(const struct master *m, uint32_t u) { return m->adapt ? m->slot_mask[u] : TILE_MASK_ALL; }

/* --tiles: every other tile is a black, transparent chunk encoded here (AOVs: nothing
 * hit), so the output is a complete EXR in which only the chosen tiles were rendered. */
static int restrict_tiles(struct master *m)
{
    const struct master_opts *o = m->opts;
    for (uint32_t i = 0; i < o->num_only_tiles; i++)
        if (o->only_tiles[i] >= m->num_tiles) {
            master_fail(m, "--tiles: tile %u does not exist (the frame has tiles 0..%u)", o->only_tiles[i], m->num_tiles - 1);
            return -1;
        }
    char err[256];
    struct imgio_encoder *enc = imgio_encoder_new(&m->out_desc, err, sizeof err);
    if (!enc) {
        master_fail(m, "%s", err);
        return -1;
    }
    size_t n = (size_t)m->scene.settings.tile_size * m->scene.settings.tile_size * FOLD_MAX_CHANNELS;
    float *black = mem_calloc(n, sizeof *black);
    aov_fill_miss(&m->out_desc, black, (size_t)m->scene.settings.tile_size * m->scene.settings.tile_size);
    uint32_t tiles_x = imgio_tiles_x(&m->desc);
    int rc = 0;
    for (uint32_t t = 0; t < m->num_tiles && rc == 0; t++) {
        int wanted = 0;
        for (uint32_t i = 0; i < o->num_only_tiles; i++)
            wanted |= o->only_tiles[i] == t;
        if (wanted)
            continue;
        if (imgio_encode_tile(enc, t % tiles_x, t / tiles_x, black, &m->chunks[t].data, &m->chunks[t].size, err,
                              sizeof err) != 0) {
            master_fail(m, "%s", err);
            rc = -1;
        } else {
            fold_est_add(m->est, t, black);
        }
        for (uint32_t p = 0; p < m->passes; p++)
            sched_tile_set_done(m->sched, p * m->num_tiles + t);
        for (uint32_t b = 0; m->adapt && b < m->blocks_side * m->blocks_side; b++)
            m->adapt->tiles[cell_of(m, t, b)].passes = 0; /* not rendered: no passes, no variance */
    }
    free(black);
    imgio_encoder_free(&enc);
    return rc;
}

/* ---- peers ---- */

/* A peer is its connection (the ROUTER's routing id, which libzmq gives and no peer can
 * take over while the connection lives) and, with CurveZMQ, the key it proved. */
static int peer_is(const struct peer *p, const struct net_frame *f)
{
    return p->id_len == f->id_len && memcmp(p->id, f->id, f->id_len) == 0 && strcmp(p->user_id, f->user_id) == 0;
}

/* Looked up by routing id (a hash, peerindex.h): every message needs its sender. */
static int32_t find_peer(const struct master *m, const struct net_frame *f)
{
    for (int32_t i = peer_index_first(&m->peer_index, f->id, f->id_len); i >= 0; i = peer_index_next(&m->peer_index, i))
        if (!m->sched->workers[i].gone && peer_is(&m->peers[i], f))
            return i;
    return -1;
}

/* A peer we evicted (its late messages are stale, not strangers'): the newest slot. */
static int32_t find_gone_peer(const struct master *m, const struct net_frame *f)
{
    int32_t found = -1;
    for (int32_t i = peer_index_first(&m->peer_index, f->id, f->id_len); i >= 0; i = peer_index_next(&m->peer_index, i))
        if (i > found && m->sched->workers[i].gone && peer_is(&m->peers[i], f))
            found = i;
    return found;
}

/* 0, or -1 when the message could not be queued (the peer's queue is full, or it is gone). */
static int send_to(struct master *m, const struct peer *p, const struct proto_msg *msg)
{
    return net_send(m->sock, p->id, p->id_len, msg, &m->out);
}

/* The command that renders tile t alone: our own command line with another output and
 * --tiles t, so the crash can be reproduced and debugged in isolation. */
static void tile_command(const struct master *m, uint32_t t, char *out, size_t outlen)
{
    const struct master_opts *o = m->opts;
    size_t n = 0;
    out[0] = '\0';
    for (int i = 0; i < o->argc && n < outlen; i++) {
        const char *a = o->argv[i];
        if (i > 0 && (!strcmp(a, "-o") || !strcmp(a, "--output") || !strcmp(a, "--tiles") || !strcmp(a, "--frames")) &&
            i + 1 < o->argc) {
            i++;
            continue;
        }
        int quote = strpbrk(a, " \t'\"$\\") != NULL;
        n += (size_t)snprintf(out + n, outlen - n, "%s%s%s%s", n ? " " : "", quote ? "'" : "", a, quote ? "'" : "");
    }
    char base[4096];
    snprintf(base, sizeof base, "%s", o->output_path);
    char *dot = strrchr(base, '.');
    if (dot && !strcmp(dot, ".exr"))
        *dot = '\0';
    if (n < outlen)
        n += (size_t)snprintf(out + n, outlen - n, " -o %.1000s.tile%u.exr --tiles %u", base, t, t);
    if (n < outlen && o->have_frames)
        snprintf(out + n, outlen - n, " --frames %u:%u", m->frame, m->frame);
}

/* Maps an eviction onto the fatal reason, counters, the log and a BYE. A tile that took
 * SCHED_CRASHES_TO_FAIL different workers down fails the job. */
static void peer_evicted(struct master *m, int32_t pi, enum sched_evict_kind kind, const struct sched_eviction *ev,
                         const char *why)
{
    struct peer *p = &m->peers[pi];
    if (ev->blamed_tile >= 0 && !m->fatal[0]) {
        uint32_t t = (uint32_t)ev->blamed_tile;
        char cmd[1800];
        tile_command(m, t, cmd, sizeof cmd);
        uint32_t tx = t % imgio_tiles_x(&m->desc), ty = t / imgio_tiles_x(&m->desc), x0, y0, w, h;
        imgio_tile_rect(&m->desc, tx, ty, &x0, &y0, &w, &h);
        snprintf(m->fatal, sizeof m->fatal,
                 "tile %u (pixels %u,%u %ux%u) took down %u different workers; render it alone with: %s", t, x0, y0,
                 w, h, m->sched->tiles[t].crashes, cmd);
    }
    switch (kind) {
    case SCHED_SILENT: m->c.evicted_silent++; break;
    case SCHED_STALLED: m->c.evicted_stalled++; break;
    case SCHED_DIED:
    case SCHED_KILLED: m->c.evicted_died++; break;
    case SCHED_ERROR: m->c.evicted_error++; break;
    case SCHED_BANNED: m->c.workers_banned++; break;
    case SCHED_LEFT: break;
    }
    log_warn("worker %s removed (%s); %u tile(s) re-queued", p->name, why, ev->requeued);
    struct proto_msg bye = {.type = MSG_BYE};
    send_to(m, p, &bye);
    /* A local worker that went silent or stalled (stopped, swapped out, wedged) cannot
     * read the BYE: end the process, so that it is reaped and started again. The pid is
     * what the HELLO claimed: only a peer that proved the local workers' key (with
     * CurveZMQ; without it only the master's user can reach the ipc socket) is taken at
     * its word, so that a remote peer claiming a local pid cannot get that worker killed. */
    if ((kind == SCHED_SILENT || kind == SCHED_STALLED) && (!m->zap || !strcmp(p->user_id, m->local_public.z85)))
        for (uint32_t i = 0; i < m->num_local; i++)
            if (m->local_pids[i] > 0 && (uint32_t)m->local_pids[i] == p->pid) {
                log_warn("local worker %u (pid %d) ended with SIGKILL", i, (int)m->local_pids[i]);
                kill(m->local_pids[i], SIGKILL);
            }
}

static void evict_peer(struct master *m, int32_t pi, enum sched_evict_kind kind, const char *why)
{
    if (m->sched->workers[pi].gone)
        return;
    struct sched_eviction ev;
    sched_evict(m->sched, pi, kind, &ev);
    peer_evicted(m, pi, kind, &ev, why);
}

/* Bans are remembered as key and claimed name: a peer claiming a banned worker's name
 * with another key is not that worker. */
static void ban_key(const struct peer *p, char *out, size_t outlen)
{
    snprintf(out, outlen, "%s %s", p->user_id, p->name);
}

static int name_is_banned(const struct master *m, const char *user_id, const char *name)
{
    char key[400];
    snprintf(key, sizeof key, "%s %s", user_id, name);
    for (uint32_t i = 0; i < m->num_banned; i++)
        if (!strcmp(m->banned_names[i], key))
            return 1;
    return 0;
}

static void send_job(struct master *m, struct peer *p);

/* MAP of every published photon map peer p was not sent yet (after the JOB they belong
 * to), in pass order. One that cannot be queued (its queue is full) stays pending: the
 * loop sends it again (assign_tiles), and no TILE of its pass goes before it (a worker
 * drops a TILE whose map was never announced). */
static void send_maps(struct master *m, struct peer *p)
{
    while (p->maps_sent < m->maps_published) {
        uint32_t pass = p->maps_sent;
        struct proto_msg msg = {.type = MSG_MAP};
        msg.u.map.job_id = m->job_id;
        msg.u.map.pass = pass;
        msg.u.map.published = m->maps_published;
        msg.u.map.hash = m->maps[pass].hash;
        msg.u.map.size = m->maps[pass].size;
        if (send_to(m, p, &msg) != 0) {
            m->sends_behind = 1; /* assign_tiles tries again */
            return;
        }
        p->maps_sent++;
    }
}

/* Logs a refused HELLO (after a few, only counts: a flood cannot flood the log) and tells
 * the peer to go. */
static void hello_refused(struct master *m, const struct net_frame *f, const char *name, const char *why)
{
    struct proto_msg bye = {.type = MSG_BYE};
    net_send(m->sock, f->id, f->id_len, &bye, &m->out);
    m->c.hellos_refused++;
    if (++m->hellos_logged <= 5)
        log_warn("hello from %s refused: %s%s", name, why, m->hellos_logged == 5 ? " (further refusals are counted, not logged)" : "");
}

/* A slot for a new peer: the next one, or past MAX_SLOTS the oldest gone, unbanned worker's
 * (its pending ACKs dropped: they were for a connection that is gone). -1 when none. */
static int32_t peer_slot(struct master *m)
{
    if (m->num_peers < MAX_SLOTS) {
        m->peers = mem_realloc(m->peers, sizeof *m->peers * (m->num_peers + 1));
        memset(&m->peers[m->num_peers], 0, sizeof *m->peers);
        return (int32_t)m->num_peers;
    }
    for (uint32_t i = 0; i < m->num_peers; i++) {
        const struct sched_worker *w = &m->sched->workers[i];
        if (!w->gone || w->banned)
            continue;
        uint32_t k = 0;
        for (uint32_t a = 0; a < m->num_acks; a++)
            if (m->acks[a].peer != (int32_t)i)
                m->acks[k++] = m->acks[a];
        m->num_acks = k;
        free(m->peers[i].map_bytes);
        free(m->peers[i].wait_ms);
        memset(&m->peers[i], 0, sizeof *m->peers);
        peer_index_remove(&m->peer_index, (int32_t)i);
        return (int32_t)i;
    }
    return -1;
}

/* Peer text (a HELLO's host, an ERROR's message) goes into our log, the fatal message and
 * the stats file: printable ASCII only, so that it cannot forge log lines (a newline),
 * drive the terminal (escapes) or make the stats' JSON drop it (bytes not UTF-8). */
static void peer_text_printable(char *s)
{
    for (unsigned char *c = (unsigned char *)s; *c; c++)
        if (*c < 0x20 || *c >= 0x7f)
            *c = '?';
}

static void on_hello(struct master *m, const struct net_frame *f, const struct msg_hello *h)
{
    if (find_peer(m, f) >= 0) {
        m->c.rejected_unexpected++; /* repeated hello: already known */
        return;
    }
    char name[300];
    snprintf(name, sizeof name, "%.200s:%u", h->host, h->pid);
    peer_text_printable(name);
    int32_t gone = find_gone_peer(m, f);
    if (name_is_banned(m, f->user_id, name) || (gone >= 0 && m->sched->workers[gone].banned)) {
        m->c.rejected_banned++;
        return;
    }
    /* The same worker on a new connection (it lost us and reconnected): its old
     * connection is dead; its tiles go back to the queue without counting as a crash.
     * Only a peer that proved the same key can say so: the host and pid a HELLO claims
     * are words, and without CurveZMQ a silent old connection is evicted by its timeout. */
    uint32_t live = 0, same_key = 0;
    for (uint32_t i = 0; i < m->num_peers; i++) {
        if (m->sched->workers[i].gone)
            continue;
        if (f->user_id[0] && !strcmp(m->peers[i].user_id, f->user_id) && !strcmp(m->peers[i].name, name)) {
            evict_peer(m, (int32_t)i, SCHED_LEFT, "it reconnected");
            continue;
        }
        live++;
        same_key += !strcmp(m->peers[i].user_id, f->user_id);
    }
    if (live >= MAX_PEERS || same_key >= MAX_PEERS_PER_KEY) {
        char why[128];
        snprintf(why, sizeof why, "%u workers %s already", live >= MAX_PEERS ? live : same_key,
                 live >= MAX_PEERS ? "in all" : "with its key");
        hello_refused(m, f, name, why);
        return;
    }
    int32_t slot = peer_slot(m);
    if (slot < 0) {
        hello_refused(m, f, name, "no free slot");
        return;
    }
    struct peer *p = &m->peers[slot];
    memcpy(p->id, f->id, f->id_len);
    p->id_len = f->id_len;
    peer_index_add(&m->peer_index, slot, p->id, p->id_len);
    memcpy(p->user_id, f->user_id, sizeof p->user_id);
    p->pid = h->pid;
    p->map_bytes = mem_calloc(m->passes, sizeof *p->map_bytes);
    p->wait_ms = mem_calloc(m->passes, sizeof *p->wait_ms);
    snprintf(p->name, sizeof p->name, "%s", name);
    if ((uint32_t)slot == m->num_peers) {
        sched_worker_join(m->sched, h->threads, net_now_ms());
        m->num_peers++;
    } else {
        sched_worker_rejoin(m->sched, slot, h->threads, net_now_ms());
    }
    m->c.workers_joined++;
    if (p->user_id[0])
        log_info("worker %s joined with %u thread(s), key %.8s...", p->name, h->threads, p->user_id);
    else
        log_info("worker %s joined with %u thread(s)", p->name, h->threads);
    send_job(m, p);
}

#define JOB_RETRY_MS 100 /* a JOB its peer's queue refused waits this long before it is tried again */
/* The current frame's job. A worker that has the scene already keeps it and its blobs
 * and only rebuilds what depends on the frame. */
static void send_job(struct master *m, struct peer *p)
{
    const struct render_settings *rs = &m->scene.settings;
    struct proto_msg job = {.type = MSG_JOB};
    struct msg_job *j = &job.u.job;
    j->job_id = m->job_id;
    j->job_key = m->job_key;
    j->frame = m->frame;
    j->width = rs->width;
    j->height = rs->height;
    j->spp = rs->spp;
    j->max_depth = rs->max_depth;
    j->tile_size = rs->tile_size;
    j->seed = rs->seed;
    j->sampler = rs->sampler;
    j->aovs = rs->aovs;
    j->filter = m->scene.camera.filter;
    j->filter_width = m->scene.camera.filter_width;
    j->embree_isa = rs->embree_isa;
    j->photon_maps = m->photon_maps;
    j->passes = m->passes;
    snprintf(j->scene_path, sizeof j->scene_path, "%s", m->scene_rel);
    j->num_assets = m->num_manifest;
    j->assets = m->manifest;
    if (send_to(m, p, &job) != 0) {
        /* its queue is full (or it is gone): the loop sends the JOB again (assign_tiles);
         * until then it gets no MAP, no blob and, without its READY, no TILE */
        if (p->job_sent)
            log_warn("worker %s: the JOB could not be queued; sending it again", p->name);
        p->job_sent = 0;
        p->job_retry_ms = net_now_ms() + JOB_RETRY_MS;
        m->sends_behind = 1;
        return;
    }
    p->job_sent = 1;
    p->maps_sent = 0;
    send_maps(m, p);
}

/* ---- broadcast of blobs ---- */

#define BCAST_HWM 256               /* chunks queued per subscriber before the XPUB drops for it (shared, 64 MiB at most) */
#define BCAST_GATHER_MS 100         /* a pass starts this long after the subscription that asked for it */
#define BCAST_BURST (16.0 * BLOB_CHUNK_SIZE) /* the most the pacing lets out in one pass of the loop */

/* The stream of blob e (made, with its chunk list, on first use). */
static struct bcast_stream *stream_get(struct master *m, const struct blob_entry *e)
{
    for (size_t i = 0; i < m->num_streams; i++)
        if (blob_hash_equal(&m->streams[i].hash, &e->hash))
            return &m->streams[i];
    mem_grow((void **)&m->streams, &m->cap_streams, m->num_streams + 1, sizeof *m->streams);
    struct bcast_stream *s = &m->streams[m->num_streams++];
    memset(s, 0, sizeof *s);
    s->hash = e->hash;
    s->size = e->size;
    /* The list the blob was named by: every blob the master serves has one (blob_store_put,
     * the photon tracer's blob_store_adopt_listed). */
    CHECK(e->chunks != NULL);
    s->num_chunks = blob_num_chunks(e->size);
    s->chunk_hashes = mem_alloc(sizeof *s->chunk_hashes * (s->num_chunks ? s->num_chunks : 1));
    memcpy(s->chunk_hashes, e->chunks, sizeof *s->chunk_hashes * s->num_chunks);
    return s;
}

/* Subscriptions arrive on the XPUB (verbose: every subscriber's): 1 + a 32-byte hash.
 * They are network input from admitted peers (ZAP, or the socket file's permissions);
 * anything else is ignored. A subscription to a blob we serve starts or extends its pass. */
static void bcast_read(struct master *m, uint64_t now)
{
    for (;;) {
        zmq_msg_t msg;
        zmq_msg_init(&msg);
        if (zmq_msg_recv(&msg, m->bcast, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&msg);
            return;
        }
        const uint8_t *d = zmq_msg_data(&msg);
        if (zmq_msg_size(&msg) == 1 + BLOB_HASH_SIZE && d[0] == 1 && !zmq_msg_more(&msg)) {
            struct blob_hash h;
            memcpy(h.bytes, d + 1, BLOB_HASH_SIZE);
            const struct blob_entry *e = blob_store_get(&m->blobs, &h);
            if (e && e->size > 0) {
                struct bcast_stream *s = stream_get(m, e);
                m->c.bcast_subscriptions++;
                if (s->remaining > 0)
                    s->remaining = s->num_chunks; /* a full cycle from here for the newcomer */
                else if (!s->start_ms)
                    s->start_ms = now + BCAST_GATHER_MS;
            }
        }
        zmq_msg_close(&msg);
    }
}

/* Sends what the pacing (--bcast-mbps) allows of every stream's pass; never blocks (the
 * XPUB drops for a subscriber whose queue is full: it fetches those chunks point to point).
 * 1 while a stream has work left (the loop then polls briefly). */
static int bcast_pump(struct master *m, uint64_t now)
{
    if (!m->bcast)
        return 0;
    double rate = (double)m->opts->bcast_mbps * 1e6 / 1000.0; /* bytes per ms */
    m->bcast_tokens += rate * (double)(now - m->bcast_last_ms);
    if (m->bcast_tokens > BCAST_BURST)
        m->bcast_tokens = BCAST_BURST;
    m->bcast_last_ms = now;
    int busy = 0;
    for (size_t i = 0; i < m->num_streams;) {
        struct bcast_stream *s = &m->streams[i];
        const struct blob_entry *e = blob_store_get(&m->blobs, &s->hash);
        if (!e) { /* the blob left the store (an earlier frame's): so does its stream */
            free(s->chunk_hashes);
            m->streams[i] = m->streams[--m->num_streams];
            continue;
        }
        i++;
        if (s->start_ms && now >= s->start_ms) {
            s->start_ms = 0;
            s->remaining = s->num_chunks;
        }
        while (s->remaining > 0 && m->bcast_tokens > 0) {
            struct proto_msg d = {.type = MSG_BLOB_DATA};
            uint64_t off = s->cursor * BLOB_CHUNK_SIZE, left = e->size - off;
            d.u.blob_data.hash = s->hash;
            d.u.blob_data.offset = off;
            d.u.blob_data.total_size = e->size;
            d.u.blob_data.bytes = e->data + off;
            d.u.blob_data.length = (uint32_t)(left < BLOB_CHUNK_SIZE ? left : BLOB_CHUNK_SIZE);
            /* the topic (the hash) and the message; an XPUB send does not block */
            if (proto_encode(&d, &m->out) == 0 &&
                zmq_send(m->bcast, s->hash.bytes, BLOB_HASH_SIZE, ZMQ_SNDMORE | ZMQ_DONTWAIT) == BLOB_HASH_SIZE &&
                zmq_send(m->bcast, m->out.data, m->out.size, ZMQ_DONTWAIT) >= 0)
                m->c.blob_bytes_bcast += d.u.blob_data.length;
            m->bcast_tokens -= d.u.blob_data.length;
            s->cursor = (s->cursor + 1) % s->num_chunks;
            s->remaining--;
        }
        busy |= s->remaining > 0 || s->start_ms != 0;
    }
    return busy;
}

/* CHUNKS_REQ: the chunk list of a blob the peer may have (it was sent the JOB), and where
 * the blob is broadcast. */
static void on_chunks_req(struct master *m, struct peer *p, const struct msg_chunks_req *r)
{
    const struct blob_entry *e = p->job_sent ? blob_store_get(&m->blobs, &r->hash) : NULL;
    if (!e) {
        m->c.rejected_blob_req++;
        if (p->dropped < 5)
            log_warn("worker %s: CHUNKS_REQ for an unknown blob dropped", p->name);
        return;
    }
    struct bcast_stream *s = stream_get(m, e);
    struct proto_msg c = {.type = MSG_CHUNKS};
    c.u.chunks.hash = e->hash;
    c.u.chunks.size = e->size;
    c.u.chunks.flags = m->bcast ? PROTO_CHUNKS_BCAST : 0;
    c.u.chunks.bcast_port = m->bcast_port;
    c.u.chunks.count = (uint32_t)s->num_chunks;
    c.u.chunks.hashes = s->chunk_hashes[0].bytes;
    send_to(m, p, &c);
    for (uint32_t pass = 0; pass < m->maps_published; pass++)
        if (blob_hash_equal(&m->maps[pass].hash, &r->hash))
            p->map_bytes[pass] += e->size;
}

/* The broadcast socket beside the ROUTER's endpoint (net_bcast_endpoint), secured the
 * same way: CurveZMQ with the same ZAP handler and allow-list when the ROUTER has it, a
 * socket file of mode 0600 for ipc. Made on first use; --bcast-mbps 0: none. */
static int bcast_bind(struct master *m, const char *endpoint)
{
    if (!endpoint || m->opts->bcast_mbps == 0)
        return 0;
    if (!m->bcast) {
        m->bcast = zmq_socket(m->zctx, ZMQ_XPUB);
        net_socket_setup(m->bcast);
        int one = 1, hwm = BCAST_HWM;
        zmq_setsockopt(m->bcast, ZMQ_XPUB_VERBOSE, &one, sizeof one);
        zmq_setsockopt(m->bcast, ZMQ_SNDHWM, &hwm, sizeof hwm);
        if (m->zap && net_curve_server(m->bcast, &m->curve_sec) != 0) {
            master_fail(m, "cannot enable CurveZMQ on the broadcast socket: %s", zmq_strerror(errno));
            return -1;
        }
        if (m->zap && zap_watch(m->zap, m->zctx, m->bcast) != 0)
            log_warn("the broadcast socket's failed handshakes are not counted (no monitor)");
        m->bcast_last_ms = net_now_ms();
    }
    char ep[400];
    if (net_bcast_endpoint(endpoint, 0, ep, sizeof ep) != 0) {
        log_info("no blob broadcast beside %s (its transport): workers there fetch point to point", endpoint);
        return 0;
    }
    mode_t old = umask(077);
    int rc = zmq_bind(m->bcast, ep);
    int e = errno;
    umask(old);
    if (rc != 0) {
        master_fail(m, "cannot bind the broadcast socket %s: %s", ep, zmq_strerror(e));
        return -1;
    }
    if (!strncmp(ep, "tcp://", 6)) {
        size_t len = sizeof ep;
        if (zmq_getsockopt(m->bcast, ZMQ_LAST_ENDPOINT, ep, &len) == 0)
            m->bcast_port = net_endpoint_port(ep);
    } else {
        for (int i = 0; i < 2; i++)
            if (!m->bcast_ipc[i][0]) {
                snprintf(m->bcast_ipc[i], sizeof m->bcast_ipc[i], "%s", ep + 6);
                break;
            }
    }
    log_debug("blobs are broadcast on %s", ep);
    return 0;
}

/* The queued BLOB_DATA bytes per peer slot, counted down by libzmq's I/O thread when it
 * lets a message go (written, or dropped with its connection); static: a message may
 * outlive the master's state (freed at zmq_ctx_term). */
static _Atomic uint64_t blob_queued_peer[MAX_SLOTS];

struct queued_blob {
    _Atomic uint64_t *peer;
    size_t size;
    uint8_t data[];
};

static void queued_blob_free(void *data, void *hint)
{
    (void)data;
    struct queued_blob *q = hint;
    atomic_fetch_sub(q->peer, q->size);
    free(q);
}

/* Sends the BLOB_DATA d to peer pi unless that would hold more than BLOB_QUEUED_PER_PEER
 * bytes of them for it (then drops it). 0 when queued. */
static int send_blob_data(struct master *m, int32_t pi, const struct proto_msg *d)
{
    const struct peer *p = &m->peers[pi];
    if (proto_encode(d, &m->out) != 0)
        return -1;
    size_t size = m->out.size;
    _Atomic uint64_t *mine = &blob_queued_peer[pi];
    if (atomic_load(mine) + size > BLOB_QUEUED_PER_PEER)
        return -1;
    struct queued_blob *q = mem_alloc(sizeof *q + size);
    q->peer = mine;
    q->size = size;
    memcpy(q->data, m->out.data, size);
    atomic_fetch_add(mine, size);
    zmq_msg_t msg;
    zmq_msg_init_data(&msg, q->data, size, queued_blob_free, q);
    if (zmq_send(m->sock, p->id, p->id_len, ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
        zmq_msg_send(&msg, m->sock, ZMQ_DONTWAIT) < 0) {
        zmq_msg_close(&msg); /* frees q */
        return -1;
    }
    return 0;
}

static void on_blob_req(struct master *m, struct peer *p, const struct msg_blob_req *r)
{
    const struct blob_entry *e = p->job_sent ? blob_store_get(&m->blobs, &r->hash) : NULL;
    if (!e || r->offset > e->size || r->length > BLOB_CHUNK_SIZE || r->length > e->size - r->offset) {
        m->c.rejected_blob_req++;
        if (p->dropped < 5)
            log_warn("worker %s: BLOB_REQ for an unknown blob or range dropped", p->name);
        return;
    }
    struct proto_msg d = {.type = MSG_BLOB_DATA};
    d.u.blob_data.hash = r->hash;
    d.u.blob_data.offset = r->offset;
    d.u.blob_data.total_size = e->size;
    d.u.blob_data.bytes = e->data + r->offset;
    d.u.blob_data.length = r->length;
    if (send_blob_data(m, (int32_t)(p - m->peers), &d) != 0) {
        m->c.blob_reqs_dropped++;
        return;
    }
    m->c.blob_bytes_p2p += r->length;
}

/* Decodes unit u's chunk into decode_scratch and checks it (chunk_check): 1 when sane, 0
 * when not, -1 when it decodes but holds non-finite values (which the scene may cause:
 * see on_result). */
static int chunk_is_sane(struct master *m, uint32_t unit, const uint8_t *chunk, size_t chunk_size, char *err,
                         size_t errlen)
{
    return chunk_check(&m->check_ctx, unit, chunk, chunk_size, m->decode_scratch, err, errlen);
}

/* Logs a dropped message of a peer; after a few, only counts (a peer cannot flood the log). */
static int peer_should_log_drop(struct peer *p)
{
    p->dropped++;
    if (p->dropped == 6)
        log_warn("worker %s: further dropped messages are counted, not logged", p->name);
    return p->dropped <= 5;
}

/* Acknowledges tile of (job_id, frame) to peer pi after the next journal sync. */
static void ack_push(struct master *m, int32_t pi, uint64_t job_id, uint32_t frame, uint32_t tile)
{
    if (m->num_acks == m->cap_acks) {
        m->cap_acks = m->cap_acks ? m->cap_acks * 2 : 64;
        m->acks = mem_realloc(m->acks, sizeof *m->acks * m->cap_acks);
    }
    /* Everything written so far must be on disk: also the record of a tile that this
     * result duplicates, which may still wait for its sync. */
    m->acks[m->num_acks++] = (struct pending_ack){pi, job_id, frame, tile, m->journal ? m->journal->end : 0};
}

/* Group commit: the journal's sync thread makes every record written so far durable with
 * one fdatasync (the results read in one pass over the socket, and more while a sync is
 * running), and the ACKs of the tiles now on disk go out, one message per worker and job.
 * The loop never waits for the disk (wait = 0), except at the end of a frame. A worker
 * forgets a tile only after this, so a master killed before the sync loses nothing: the
 * worker still has the tile for the master that comes back. */
static void commit_and_ack(struct master *m, int wait)
{
    uint64_t durable = UINT64_MAX;
    if (m->journal) {
        char err[512];
        if (wait && journal_sync(m->journal, err, sizeof err) != 0) {
            snprintf(m->fatal, sizeof m->fatal, "%s", err);
            return;
        }
        journal_sync_async(m->journal);
        int64_t d = journal_durable(m->journal, err, sizeof err);
        if (d < 0) {
            snprintf(m->fatal, sizeof m->fatal, "%s", err);
            return;
        }
        durable = (uint64_t)d;
    }
    for (;;) {
        uint32_t f = 0;
        while (f < m->num_acks && m->acks[f].need > durable)
            f++;
        if (f == m->num_acks)
            break;
        struct pending_ack first = m->acks[f];
        struct proto_msg msg = {.type = MSG_ACK};
        msg.u.ack.job_id = first.job_id;
        msg.u.ack.frame = first.frame;
        uint32_t k = 0;
        for (uint32_t i = 0; i < m->num_acks; i++) {
            const struct pending_ack *a = &m->acks[i];
            if (a->peer == first.peer && a->job_id == first.job_id && a->frame == first.frame &&
                a->need <= durable && msg.u.ack.count < PROTO_MAX_ACK_TILES)
                msg.u.ack.tiles[msg.u.ack.count++] = a->tile;
            else
                m->acks[k++] = *a;
        }
        m->num_acks = k;
        if (!m->sched->workers[first.peer].gone) {
            send_to(m, &m->peers[first.peer], &msg);
            m->c.acks_sent++;
        }
    }
}

/* Encodes the folded tile in fold_out as the tile's output chunk (and counts its pixels in
 * the error estimate). With the checker pool the encoding runs there: fold_out goes with
 * the item (the loop takes the item's buffer instead), and the chunk is in place once
 * checks_drain took the item (the frame's output waits for checks_drain(m, 1)). */
static int tile_encode_folded(struct master *m, uint32_t tile)
{
    fold_est_add(m->est, tile, m->fold_out);
    if (m->checker) {
        struct check_item *it = checker_item_new(m->checker);
        it->kind = CHECK_ENCODE;
        it->peer = -1;
        it->unit = tile;
        float *px = it->pixels; /* the same size: tile_size^2 x FOLD_MAX_CHANNELS floats */
        it->pixels = m->fold_out;
        m->fold_out = px;
        checker_submit(m->checker, it);
        return 0;
    }
    char err[256];
    uint32_t tiles_x = imgio_tiles_x(&m->desc);
    if (!m->enc && !(m->enc = imgio_encoder_new(&m->out_desc, err, sizeof err))) {
        master_fail(m, "%s", err);
        return -1;
    }
    if (imgio_encode_tile(m->enc, tile % tiles_x, tile / tiles_x, m->fold_out, &m->chunks[tile].data,
                          &m->chunks[tile].size, err, sizeof err) != 0) {
        master_fail(m, "%s", err);
        return -1;
    }
    return 0;
}

/* Queues the units of the round just decided, pass by pass (so folding proceeds in
 * order): for each pass p some block of tile t gets (round_from <= p < its new count), the
 * tile's next slot renders p for those blocks. A tile whose blocks would need more units
 * than it has slots left keeps some where they are (adapt_fit_units). The round's units
 * are what adapt waits for. */
static void adapt_release(struct master *m)
{
    struct adapt *a = m->adapt;
    uint32_t nb = m->blocks_side * m->blocks_side, lo = m->passes, hi = 0, units = 0;
    uint32_t old[TILE_MAX_BLOCKS_SIDE * TILE_MAX_BLOCKS_SIDE], now[TILE_MAX_BLOCKS_SIDE * TILE_MAX_BLOCKS_SIDE];
    for (uint32_t t = 0; t < m->num_tiles; t++) {
        for (uint32_t b = 0; b < nb; b++) {
            old[b] = m->round_from[cell_of(m, t, b)];
            now[b] = a->tiles[cell_of(m, t, b)].passes;
        }
        adapt_fit_units(old, now, nb, m->passes - m->slots_used[t]);
        for (uint32_t b = 0; b < nb; b++) {
            a->tiles[cell_of(m, t, b)].passes = now[b];
            if (now[b] > old[b]) {
                lo = old[b] < lo ? old[b] : lo;
                hi = now[b] > hi ? now[b] : hi;
            }
        }
    }
    for (uint32_t p = lo; p < hi; p++)
        for (uint32_t t = 0; t < m->num_tiles; t++) {
            uint64_t mask = 0;
            for (uint32_t b = 0; b < nb; b++) {
                uint32_t c = cell_of(m, t, b);
                if (p >= m->round_from[c] && p < a->tiles[c].passes)
                    mask |= (uint64_t)1 << b;
            }
            if (!mask)
                continue;
            CHECK(m->slots_used[t] < m->passes);
            uint32_t u = m->slots_used[t]++ * m->num_tiles + t;
            /* every block of the tile in the mask: the EXR chunk check and the fold see a whole tile */
            m->slot_mask[u] = mask == ((nb == 64 ? 0 : (uint64_t)1 << nb) - 1) ? TILE_MASK_ALL : mask;
            m->slot_pass[u] = p;
            sched_unhold(m->sched, u);
            units++;
        }
    for (uint32_t c = 0; c < m->num_cells; c++)
        m->round_from[c] = a->tiles[c].passes;
    a->outstanding = units;
    /* The maps of the round's passes and one more, so that the next round's first pass
     * need not wait for its map; the tracer traces no further. */
    if (m->tracer)
        photon_tracer_want(m->tracer, hi + 1);
}

/* The per-pixel bound's state at the last decision into buf: "" without a bound. */
static void pixel_bound_text(const struct master *m, char *buf, size_t size)
{
    const struct adapt *a = m->adapt;
    double pixels = (double)m->scene.settings.width * m->scene.settings.height;
    buf[0] = '\0';
    if (a && m->pixel_error > 0.0)
        snprintf(buf, size, "; pixels above %g: %llu (%.2f %%, %llu at the cap), worst %.4f", m->pixel_error,
                 (unsigned long long)a->pixels_over, pixels > 0 ? 100.0 * (double)a->pixels_over / pixels : 0.0,
                 (unsigned long long)a->pixels_over_capped, a->worst);
}

/* A round's last unit is folded: the decision, from the folded passes only (the same after
 * a journal replay, whose records come in the order the units were accepted). Either the
 * next round goes out, or every tile is final and the units never wanted are done. */
static int adapt_round_end(struct master *m)
{
    struct adapt *a = m->adapt;
    enum { NB = TILE_MAX_BLOCKS_SIDE * TILE_MAX_BLOCKS_SIDE };
    double v[NB], v2[NB], mu[NB];
    for (uint32_t t = 0; t < m->num_tiles; t++) {
        fold_blocks_sums(m->fold, t, v, v2, mu); /* one pass over the tile */
        for (uint32_t b = 0; b < m->blocks_side * m->blocks_side; b++) {
            struct adapt_tile *at = &a->tiles[cell_of(m, t, b)];
            at->sum_var = v[b];
            at->sum_var_sq = v2[b];
            at->sum_mean = mu[b];
        }
    }
    if (m->pixel_error > 0.0) { /* the per-pixel bound's scale needs the image's mean: a second pass */
        double floor = adapt_pixel_floor(a);
        uint32_t over[NB];
        for (uint32_t t = 0; t < m->num_tiles; t++) {
            fold_blocks_worst(m->fold, t, floor, m->pixel_error, v, over);
            for (uint32_t b = 0; b < m->blocks_side * m->blocks_side; b++) {
                a->tiles[cell_of(m, t, b)].worst = v[b];
                a->tiles[cell_of(m, t, b)].over = over[b];
            }
        }
    }
    uint32_t round = a->round;
    const char *why = NULL;
    char px[160];
    int decided = adapt_decide(a, m->time_up, m->stats.samples);
    pixel_bound_text(m, px, sizeof px);
    if (decided) {
        if (round == 0 && a->predicted > 0.0) /* 0: met at round 0, or a bound alone (no pilot) */
            log_info("adaptive: the pilot predicts the allocation at %.3f of uniform passes' work (fallback above %g): %s",
                     a->predicted, ADAPT_UNIFORM_GAIN, a->uniform ? "uniform passes" : "passes per block");
        adapt_release(m);
        uint64_t units = a->outstanding;
        if (units > 0) {
            log_info("adaptive: round %u: estimated relRMSE %.4f (tiles alone %.4f, %.0f dof; target %g, aim %.4f)%s; "
                     "round %u: %llu more units", round, a->est, a->est_raw, a->dof, m->target_error, a->aim, px,
                     a->round, (unsigned long long)units);
            return 0;
        }
        a->finished = 1;
        a->round--;
        why = "every growing tile out of units";
    }
    if (!why)
        why = m->time_up ? "time limit reached"
              : a->met
                  ? (a->pixel_error > 0.0 ? (a->target > 0.0 ? "target and per-pixel bound met" : "per-pixel bound met")
                                          : "target met")
              : a->max_rounds && round + 1 >= a->max_rounds ? "round cap reached" : "every block at its pass cap";
    log_info("adaptive: round %u: estimated relRMSE %.4f (tiles alone %.4f, %.0f dof; target %g, aim %.4f)%s: %s", round,
             a->est, a->est_raw, a->dof, m->target_error, a->aim, px, why);
    m->adapt_stop = why;
    for (uint32_t t = 0; t < m->num_tiles; t++) {
        if (m->chunks[t].data) /* --tiles: a black tile */
            continue;
        fold_finish(m->fold, t, m->fold_out, &m->stats);
        if (tile_encode_folded(m, t) != 0)
            return -1;
    }
    for (uint32_t u = 0; u < m->num_units; u++)
        if (m->sched->tiles[u].state == SCHED_HELD)
            sched_tile_set_done(m->sched, u);
    return 0;
}

/* Folds a tile's batch of units (fold_add_take; NULL: none due): on the pool if there is
 * one (CHECK_FOLD; a batch that is not the tile's last comes back to result_checked),
 * else here, with the tile's next batches while they are due; a tile's last batch is
 * encoded as its chunk. */
static int fold_submit(struct master *m, struct fold_units *u)
{
    while (u) {
        uint32_t tile = fold_units_tile(u);
        if (m->checker) {
            struct check_item *it = checker_item_new(m->checker);
            it->kind = CHECK_FOLD;
            it->peer = -1;
            it->unit = tile;
            it->units = u;
            checker_submit(m->checker, it);
            return 0;
        }
        fold_run(m->fold, u, &m->fold_scratch, &m->fold_scratch_size, m->fold_out, &m->stats);
        if (fold_units_final(u)) {
            fold_units_free(&u);
            return tile_encode_folded(m, tile);
        }
        u = fold_units_return(m->fold, &u);
    }
    return 0;
}

/* A unit whose chunk chunk_is_sane has just decoded into decode_scratch: with one pass
 * the chunk is the tile's (held: the received frame it lies in, or NULL; the tile takes
 * the frame over instead of copying the chunk); with several it is folded (fold.h), and
 * once the tile's last pass is in (adaptive: once the rounds end), the folded tile is
 * encoded as the tile's chunk. With the checker pool a uniform render's tile is folded
 * (in batches, fold_submit) and encoded there (CHECK_FOLD), and each unit's pixels are
 * copied there too (decode_keep, which the fold keeps until its batch): the loop copies
 * nothing. */
static int unit_keep(struct master *m, uint32_t unit, const struct tile_stats *st, const uint8_t *chunk,
                     size_t chunk_size, struct net_payload **held)
{
    uint32_t tile = unit_tile(m, unit);
    tile_stats_add(&m->stats, st);
    if (st->nan_samples) {
        if (!m->tile_nans[tile] || unit_pass(m, unit) < m->tile_nan_pass[tile])
            m->tile_nan_pass[tile] = unit_pass(m, unit);
        m->tile_nans[tile] += st->nan_samples;
    }
    if (m->passes == 1) {
        struct output_chunk *c = &m->chunks[tile];
        if (held && *held) { /* chunk lies in the received frame: kept as it is, not copied */
            uint8_t *base = net_payload_data(*held);
            c->data = base + (chunk - base);
            c->payload = *held;
            *held = NULL;
        } else {
            c->data = mem_alloc(chunk_size ? chunk_size : 1);
            memcpy(c->data, chunk, chunk_size);
        }
        c->size = chunk_size;
        fold_est_add(m->est, tile, m->decode_scratch);
        return 0;
    }
    if (m->adapt) {
        struct adapt *a = m->adapt;
        uint64_t mask = unit_mask(m, unit);
        fold_add_slot(m->fold, tile, unit / m->num_tiles, unit_pass(m, unit), mask, m->decode_scratch);
        /* The unit's cost, counted by the worker for its blocks together, shared by pixels. */
        double px_all = 0.0;
        for (uint32_t b = 0; b < m->blocks_side * m->blocks_side; b++)
            if (mask >> b & 1)
                px_all += a->tiles[cell_of(m, tile, b)].pixels;
        for (uint32_t b = 0; b < m->blocks_side * m->blocks_side && px_all > 0.0; b++)
            if (mask >> b & 1) {
                struct adapt_tile *at = &a->tiles[cell_of(m, tile, b)];
                at->samples += (uint64_t)llround((double)st->samples * at->pixels / px_all);
                at->rays += (uint64_t)llround((double)st->rays * at->pixels / px_all);
            }
        CHECK(a->outstanding > 0);
        if (--a->outstanding == 0)
            return adapt_round_end(m);
        return 0;
    }
    /* Every tile gets all its passes, and nobody reads an unfinished tile's sums: its units
     * are kept until its last is in, then folded (fold_add_take), by the pool if there is
     * one, which also encodes the tile. */
    struct fold_units *u = m->decode_keep ? fold_add_take_own(m->fold, tile, unit_pass(m, unit), &m->decode_keep)
                                          : fold_add_take(m->fold, tile, unit_pass(m, unit), m->decode_scratch);
    return fold_submit(m, u);
}

/* Keeps an accepted unit: journal first (appended here, from the record the checker built
 * when it did, which this takes over; written and synced by the journal's thread before
 * commit_and_ack tells anyone), then the caller marks it done in the scheduler. */
static int tile_accept(struct master *m, uint32_t unit, const struct tile_stats *st, const uint8_t *chunk,
                       size_t chunk_size, uint8_t *record, size_t record_size, struct net_payload **held)
{
    if (!m->journal)
        free(record);
    if (m->journal) {
        char err[512];
        if (record ? journal_write_record(m->journal, unit, record, record_size, err, sizeof err) != 0
                   : journal_write(m->journal, unit, st, chunk, (uint32_t)chunk_size, err, sizeof err) != 0) {
            snprintf(m->fatal, sizeof m->fatal, "%s", err);
            return -1;
        }
    }
    m->c.tiles_done++;
    return unit_keep(m, unit, st, chunk, chunk_size, held);
}

/* An invalid tile from peer pi was counted by the scheduler; a ban (SCHED_FAILS_TO_BAN in
 * a row) is remembered by name and the worker is told to go. */
static void peer_sent_invalid(struct master *m, int32_t pi, int banned, const struct sched_eviction *ev)
{
    struct peer *p = &m->peers[pi];
    m->c.results_invalid++;
    if (!banned)
        return;
    if (m->num_banned < sizeof m->banned_names / sizeof m->banned_names[0])
        ban_key(p, m->banned_names[m->num_banned++], sizeof m->banned_names[0]);
    char why[64];
    snprintf(why, sizeof why, "banned for the job: %u invalid results in a row", m->sched->workers[pi].fail_streak);
    peer_evicted(m, pi, SCHED_BANNED, ev, why);
}

/* The tag of an assignment of unit `unit` to a peer with key user_id: a MAC under the
 * master's tag key over the job key, the unit and the key. A master restarted with the
 * same key pair computes the same tag, so it can tell a kept tile that was assigned to
 * this very key from one that was not. */
static void tile_tag(const struct master *m, uint32_t unit, const char *user_id, struct blob_hash *tag)
{
    uint8_t text[BLOB_HASH_SIZE + 4 + NET_Z85_KEY_LEN] = {0};
    memcpy(text, m->job_key.bytes, BLOB_HASH_SIZE);
    for (int i = 0; i < 4; i++)
        text[BLOB_HASH_SIZE + i] = (uint8_t)(unit >> (8 * i));
    memcpy(text + BLOB_HASH_SIZE + 4, user_id, strlen(user_id));
    blob_mac_compute(&m->tag_key, text, sizeof text, tag);
}

/* Whether a kept tile is tied to the peer offering it. With CurveZMQ: its tag is the one
 * this master's key gives the assignment of that unit to the peer's key. Without it: only
 * when no tcp:// endpoint is open (then every peer came through a socket file only our
 * user can open, docs/cluster.md); with --insecure nothing ties it. */
static int kept_is_tied(const struct master *m, const struct peer *p, const struct msg_kept *k)
{
    if (!m->zap)
        return !m->tcp_open;
    struct blob_hash want;
    tile_tag(m, k->tile, p->user_id, &want);
    return blob_mac_equal(&want, &k->tag);
}

/* A tile a worker kept for a master that went away, offered to us: accepted only for this
 * very job (the key covers scene, assets, settings, frame and tile layout) and only after
 * the same checks as a RESULT. It need not be assigned: it is a finished tile we lack. */
static void on_kept(struct master *m, int32_t pi, const struct msg_kept *k)
{
    struct peer *p = &m->peers[pi];
    sched_worker_progress(m->sched, pi, net_now_ms());
    if (k->job_id != m->job_id || !blob_hash_equal(&k->job_key, &m->job_key) || k->frame != m->frame ||
        k->tile >= m->num_units) {
        if (peer_should_log_drop(p))
            log_warn("worker %s: kept tile %u (frame %u) was rendered for another job; dropped", p->name, k->tile,
                     k->frame);
        m->c.results_not_ours++;
        return;
    }
    if (m->sched->tiles[k->tile].state == SCHED_HELD) {
        /* A unit of an adaptive round not decided yet: rendered again if it is ever wanted. */
        m->c.results_stale++;
        return;
    }
    if (sched_kept(m->sched, k->tile)) {
        m->c.kept_duplicate++;
        ack_push(m, pi, k->job_id, k->frame, k->tile);
        return;
    }
    if (!kept_is_tied(m, p, k)) {
        /* Nothing ties the tile to this peer: rendered again rather than trusted. */
        m->c.kept_untied++;
        if (peer_should_log_drop(p))
            log_warn("worker %s: kept tile %u was not assigned to its key by a master with our key; dropped (it is "
                     "rendered again)", p->name, k->tile);
        return;
    }
    char err[256];
    if (chunk_is_sane(m, k->tile, k->chunk, k->chunk_size, err, sizeof err) != 1) {
        log_warn("worker %s: kept tile %u rejected: %s", p->name, k->tile, err);
        struct sched_eviction ev;
        int banned = sched_kept_invalid(m->sched, pi, &ev);
        peer_sent_invalid(m, pi, banned, &ev);
        return;
    }
    if (tile_accept(m, k->tile, &k->stats, k->chunk, k->chunk_size, NULL, 0, NULL) != 0)
        return;
    sched_kept_valid(m->sched, pi, k->tile);
    ack_push(m, pi, k->job_id, k->frame, k->tile);
    m->c.tiles_from_kept++;
}

/* The brightest emitter of the scene, for the message of a scene that overflows float. */
static void scene_brightest(const struct scene *sc, char *out, size_t outlen)
{
    float best = 0.0f;
    out[0] = '\0';
    for (uint32_t i = 0; i < sc->num_materials; i++) {
        const struct material *mt = &sc->materials[i];
        float e = fmaxf(mt->emission.x, fmaxf(mt->emission.y, mt->emission.z));
        if (e > best) {
            best = e;
            snprintf(out, outlen, "; the brightest emitter is material \"%s\" with emission %g", mt->name, (double)e);
        }
    }
    for (uint32_t i = 0; i < sc->num_lights; i++) {
        const struct vec3 *v = &sc->lights[i].intensity;
        float e = fmaxf(v->x, fmaxf(v->y, v->z));
        if (e > best) {
            best = e;
            snprintf(out, outlen, "; the brightest emitter is light %u (in the order of \"lights\") with intensity %g",
                     i, (double)e);
        }
    }
}

/* A result of unit u from peer pi that decodes but holds non-finite values. Pixels are
 * pure functions of the scene, so if another render of it (another worker, or this one
 * when it is the only one) was non-finite too, the scene causes it: the job fails with a
 * message that says so. Otherwise the unit goes to another worker, which settles it. */
static void result_nonfinite(struct master *m, int32_t pi, uint32_t u)
{
    int32_t first = m->sched->tiles[u].nonfinite_by - 1;
    m->c.results_nonfinite++;
    if (first < 0) {
        log_warn("worker %s: tile %u has non-finite values; rendered again elsewhere to tell the scene from the worker",
                 m->peers[pi].name, u);
        sched_result_nonfinite(m->sched, pi, u, net_now_ms());
        return;
    }
    uint32_t t = unit_tile(m, u), tiles_x = imgio_tiles_x(&m->desc), x0, y0, w, h;
    imgio_tile_rect(&m->desc, t % tiles_x, t / tiles_x, &x0, &y0, &w, &h);
    char brightest[400];
    scene_brightest(&m->scene, brightest, sizeof brightest);
    char who[700];
    if (first == pi)
        snprintf(who, sizeof who, "twice on worker %s, the only worker", m->peers[pi].name);
    else
        snprintf(who, sizeof who, "on two workers (%s and %s)", m->peers[first].name, m->peers[pi].name);
    master_fail(m, "the scene produces non-finite values at tile %u pass %u (pixels %u,%u %ux%u), %s: values past "
                "float's range; check the emission and intensity values%s", t, unit_pass(m, u), x0, y0, w, h, who,
                brightest);
}

static void result_verdict(struct master *m, int32_t pi, uint32_t unit, uint64_t job_id, uint32_t frame,
                           const struct tile_stats *st, const uint8_t *chunk, uint32_t chunk_size, int sane,
                           const char *err, uint8_t *record, size_t record_size, struct net_payload **held);

/* Whether a result for unit (attempt) of peer pi counts now: CHECK, or it was counted
 * (duplicate: acknowledged when we have the unit; stale: dropped). */
static enum sched_result_verdict result_counts(struct master *m, int32_t pi, uint64_t job_id, uint32_t frame,
                                               uint32_t unit, uint32_t attempt)
{
    enum sched_result_verdict v = sched_result(m->sched, pi, unit, attempt);
    if (v == SCHED_RESULT_CHECK)
        return v;
    if (v == SCHED_RESULT_DUPLICATE)
        m->c.results_duplicate++;
    else
        m->c.results_stale++;
    if (m->sched->tiles[unit].state == SCHED_DONE) /* we have it: the worker need not keep its copy */
        ack_push(m, pi, job_id, frame, unit);
    if (v == SCHED_RESULT_STALE && peer_should_log_drop(&m->peers[pi]))
        log_warn("worker %s: result for tile %u attempt %u is stale or not assigned to it; dropped", m->peers[pi].name,
                 unit, attempt);
    return v;
}

/* A RESULT: ids checked, then its chunk checked, in the loop or by the checker pool (which
 * then owns the received frame f: its payload holds the chunk). */
static void on_result(struct master *m, int32_t pi, const struct msg_result *r, struct net_frame *f)
{
    struct peer *p = &m->peers[pi];
    sched_worker_progress(m->sched, pi, net_now_ms());
    if (r->job_id >= m->job_base && r->job_id < m->job_id) {
        /* A tile of an earlier frame of this range, finished after that frame was done
         * (a straggler copy): expected. Its credit went with the old job; the frame is
         * safe on disk, so the worker may forget the tile. */
        m->c.results_stale++;
        ack_push(m, pi, r->job_id, r->frame, r->tile);
        return;
    }
    /* The worker's credit comes back with its RESULT; when the checker pool already holds
     * MASTER_POOL_BACKLOG RESULTs per thread, only once the RESULT is checked
     * (result_checked): so a pool slower than the workers holds at most that many and the
     * workers' credits, instead of piling up their RESULTs (a chunk and a decode buffer
     * each) without bound, and a pool that keeps up costs no extra pass of the loop. */
    if (r->job_id != m->job_id || r->frame != m->frame || r->tile >= m->num_units) {
        if (r->job_id == m->job_id)
            sched_worker_credit(m->sched, pi);
        if (peer_should_log_drop(p))
            log_warn("worker %s: RESULT for job %llu frame %u tile %u is not ours; dropped", p->name,
                     (unsigned long long)r->job_id, r->frame, r->tile);
        m->c.results_not_ours++;
        return;
    }
    if (result_counts(m, pi, r->job_id, r->frame, r->tile, r->attempt) != SCHED_RESULT_CHECK) {
        sched_worker_credit(m->sched, pi);
        return;
    }
    if (m->checker) {
        struct check_item *it = checker_item_new(m->checker);
        it->peer = pi;
        memcpy(it->peer_id, p->id, p->id_len);
        it->peer_id_len = p->id_len;
        it->job_id = r->job_id;
        it->frame = r->frame;
        it->unit = r->tile;
        it->attempt = r->attempt;
        it->stats = r->stats;
        it->chunk = r->chunk;
        it->chunk_size = r->chunk_size;
        it->payload = net_frame_take(f); /* the chunk lives in it */
        it->credit_owed = m->results_in_pool >= (uint64_t)MASTER_POOL_BACKLOG * checker_threads(m->checker);
        if (!it->credit_owed)
            sched_worker_credit(m->sched, pi);
        checker_submit(m->checker, it);
        if (++m->results_in_pool > m->c.results_in_pool_max)
            m->c.results_in_pool_max = m->results_in_pool;
        return;
    }
    sched_worker_credit(m->sched, pi);
    char err[256];
    int sane = chunk_is_sane(m, r->tile, r->chunk, r->chunk_size, err, sizeof err);
    result_verdict(m, pi, r->tile, r->job_id, r->frame, &r->stats, r->chunk, r->chunk_size, sane, err, NULL, 0,
                   &f->payload);
}

/* A checked item from the pool: the scheduler may have moved on while it was checked (the
 * unit done by a straggler copy, the worker evicted, the frame over), so it counts only if
 * it still would now. Its decoded pixels become decode_scratch (same size). */
static void result_checked(struct master *m, struct check_item *it)
{
    if (it->kind == CHECK_ENCODE || it->kind == CHECK_FOLD) { /* a folded tile (tile_encode_folded, unit_keep) */
        if (it->verdict != 1) {
            master_fail(m, "%s", it->err);
            return;
        }
        if (it->kind == CHECK_FOLD && it->units) { /* a batch folded, not the tile's last */
            if (fold_submit(m, fold_units_return(m->fold, &it->units)) != 0)
                master_fail(m, "folding tile %u failed", it->unit);
            return;
        }
        if (it->kind == CHECK_FOLD) { /* folded there: its error sums and relative errors */
            fold_est_put(m->est, it->unit, &it->est);
            tile_stats_add(&m->stats, &it->stats);
        }
        m->chunks[it->unit].data = it->record;
        m->chunks[it->unit].size = it->record_size;
        it->record = NULL;
        return;
    }
    int32_t pi = it->peer;
    if (it->job_id != m->job_id || it->frame != m->frame || (uint32_t)pi >= m->num_peers ||
        m->sched->workers[pi].gone || m->peers[pi].id_len != it->peer_id_len ||
        memcmp(m->peers[pi].id, it->peer_id, it->peer_id_len) != 0) {
        m->c.results_stale++;
        return;
    }
    if (it->credit_owed) /* held back while it was checked (on_result) */
        sched_worker_credit(m->sched, pi);
    if (result_counts(m, pi, it->job_id, it->frame, it->unit, it->attempt) != SCHED_RESULT_CHECK)
        return;
    float *px = m->decode_scratch;
    m->decode_scratch = it->pixels;
    it->pixels = px;
    uint8_t *record = it->record; /* result_verdict takes it over */
    it->record = NULL;
    m->decode_keep = it->keep; /* unit_keep takes it over, if it keeps the unit */
    it->keep = NULL;
    result_verdict(m, pi, it->unit, it->job_id, it->frame, &it->stats, it->chunk, it->chunk_size, it->verdict,
                   it->err, record, it->record_size, &it->payload);
    free(m->decode_keep);
    m->decode_keep = NULL;
}

/* Takes every verdict the pool has ready (wait: first every one still being checked). */
static void checks_drain(struct master *m, int wait)
{
    if (!m->checker)
        return;
    uint32_t took;
    do { /* waiting: until no item taken submits another (a fold batch's next, fold_submit) */
        if (wait)
            checker_wait_idle(m->checker);
        struct check_item *it;
        took = 0;
        while ((it = checker_take(m->checker))) {
            m->results_in_pool -= it->kind == CHECK_RESULT;
            if (!m->fatal[0])
                result_checked(m, it);
            checker_item_free(m->checker, it);
            took++;
        }
    } while (wait && took > 0);
}

/* What a checked chunk of unit (from the current holder pi) leads to: accepted (journal,
 * fold, ACK once synced), non-finite (settled by another render), or invalid (re-queued,
 * towards the worker's ban). Pixels decoded in decode_scratch. */
static void result_verdict(struct master *m, int32_t pi, uint32_t unit, uint64_t job_id, uint32_t frame,
                           const struct tile_stats *st, const uint8_t *chunk, uint32_t chunk_size, int sane,
                           const char *err, uint8_t *record, size_t record_size, struct net_payload **held)
{
    struct peer *p = &m->peers[pi];
    if (sane == -1) {
        result_nonfinite(m, pi, unit);
        return;
    }
    if (sane != 1) {
        log_warn("worker %s: tile %u rejected: %s; re-queued", p->name, unit, err);
        struct sched_eviction ev;
        int banned = sched_result_invalid(m->sched, pi, unit, &ev);
        peer_sent_invalid(m, pi, banned, &ev);
        return;
    }
    if (tile_accept(m, unit, st, chunk, chunk_size, record, record_size, held) != 0)
        return;
    int32_t wrong = m->sched->tiles[unit].nonfinite_by - 1;
    if (wrong >= 0 && wrong != pi && !m->sched->workers[wrong].gone) {
        /* Its non-finite tile is finite here: that worker got it wrong. */
        log_warn("worker %s: its non-finite tile %u renders finite on %s: counted as invalid", m->peers[wrong].name,
                 unit, p->name);
        struct sched_eviction ev;
        int banned = sched_worker_invalid(m->sched, wrong, &ev);
        peer_sent_invalid(m, wrong, banned, &ev);
    }
    sched_result_valid(m->sched, pi, unit);
    ack_push(m, pi, job_id, frame, unit);
}

/* Sends the MAPs still pending, then every tile the scheduler hands out now. */
static void assign_tiles(struct master *m)
{
    /* Peers owed a JOB or a MAP that their queue refused: only after such a refusal, so
     * that a pass of the loop costs nothing per peer (thousands of them). */
    if (m->sends_behind) {
        m->sends_behind = 0; /* set again by a send below that is refused, or a JOB not yet due */
        uint64_t now = net_now_ms();
        for (uint32_t i = 0; i < m->num_peers; i++) {
            if (m->sched->workers[i].gone)
                continue;
            if (!m->peers[i].job_sent) {
                if (now >= m->peers[i].job_retry_ms)
                    send_job(m, &m->peers[i]);
                else
                    m->sends_behind = 1;
            } else if (m->peers[i].maps_sent < m->maps_published)
                send_maps(m, &m->peers[i]);
        }
    }
    struct sched_assignment a;
    while (sched_assign_next(m->sched, net_now_ms(), &a)) {
        struct proto_msg msg = {.type = MSG_TILE};
        msg.u.tile.job_id = m->job_id;
        msg.u.tile.frame = m->frame;
        msg.u.tile.tile = a.tile;
        msg.u.tile.attempt = a.attempt;
        msg.u.tile.pass = unit_pass(m, a.tile);
        msg.u.tile.mask = unit_mask(m, a.tile);
        tile_tag(m, a.tile, m->peers[a.worker].user_id, &msg.u.tile.tag);
        if ((m->photon_maps && msg.u.tile.pass >= m->peers[a.worker].maps_sent) ||
            send_to(m, &m->peers[a.worker], &msg) != 0) {
            /* Not queued (a dropped TILE would be held by nobody until the worker is
             * evicted), or its pass's MAP is still pending: taken back; the worker gets
             * more once it is heard from. */
            sched_assign_undo(m->sched, &a);
            continue;
        }
        m->c.tiles_assigned++;
        m->c.straggler_copies += a.straggler != 0;
        m->c.tiles_reissued += a.reissue != 0;
    }
}

static void handle_message(struct master *m, struct net_frame *f)
{
    struct proto_msg msg;
    char err[256];
    int32_t pi = find_peer(m, f);
    if (proto_decode(f->data, f->size, &msg, err, sizeof err) != 0) {
        m->c.rejected_decode++;
        /* Strangers share one small log budget, known peers have their own. */
        if (pi < 0 ? ++m->stranger_drops_logged <= 5 : peer_should_log_drop(&m->peers[pi]))
            log_warn("message from %s dropped: %s", pi >= 0 ? m->peers[pi].name : "an unknown peer", err);
        return;
    }
    if (msg.type == MSG_HELLO) {
        on_hello(m, f, &msg.u.hello);
        return;
    }
    if (pi < 0) {
        int32_t gone = find_gone_peer(m, f);
        if (gone >= 0 && msg.type == MSG_RESULT) {
            m->c.results_stale++; /* a late result of an evicted worker (e.g. after SIGCONT) */
            log_debug("late RESULT for tile %u from evicted worker %s dropped", msg.u.result.tile, m->peers[gone].name);
        } else if (gone >= 0) {
            m->c.rejected_unexpected++;
        } else {
            m->c.rejected_unknown_peer++;
            log_debug("%s from an unknown peer dropped", proto_type_name(msg.type));
        }
        if (msg.type == MSG_JOB)
            proto_job_fini(&msg.u.job);
        return;
    }
    struct peer *p = &m->peers[pi];
    sched_worker_heard(m->sched, pi, net_now_ms());
    switch (msg.type) {
    case MSG_BLOB_REQ:
        on_blob_req(m, p, &msg.u.blob_req);
        break;
    case MSG_CHUNKS_REQ:
        on_chunks_req(m, p, &msg.u.chunks_req);
        break;
    case MSG_READY:
        if (msg.u.ready.job_id == m->job_id && sched_worker_ready(m->sched, pi, msg.u.ready.credits) == 0) {
            /* credits set */
        } else if (msg.u.ready.job_id >= m->job_base && msg.u.ready.job_id < m->job_id) {
            m->c.ready_stale++; /* it finished loading a frame that is already done: the next JOB is on its way */
        } else {
            m->c.rejected_wrong_job++;
        }
        break;
    case MSG_RESULT:
        on_result(m, pi, &msg.u.result, f);
        break;
    case MSG_KEPT:
        on_kept(m, pi, &msg.u.kept);
        break;
    case MSG_ERROR:
        peer_text_printable(msg.u.error.text);
        snprintf(m->last_worker_error, sizeof m->last_worker_error, "%s", msg.u.error.text);
        log_error("worker %s: %s", p->name, msg.u.error.text);
        evict_peer(m, pi, SCHED_ERROR, "it reported an error");
        break;
    case MSG_HEARTBEAT:
        sched_worker_heartbeat(m->sched, pi, msg.u.heartbeat.samples_done, msg.u.heartbeat.stalled_ms, net_now_ms());
        if (msg.u.heartbeat.job_id == m->job_id) { /* its own cumulative count for this job */
            if (p->fetch_wait_job != m->job_id)
                p->fetch_wait_last = 0;
            if (msg.u.heartbeat.map_wait_ms > p->fetch_wait_last)
                p->fetch_wait_ms += msg.u.heartbeat.map_wait_ms - p->fetch_wait_last;
            p->fetch_wait_last = msg.u.heartbeat.map_wait_ms;
            p->fetch_wait_job = m->job_id;
        }
        break;
    case MSG_BYE:
        evict_peer(m, pi, SCHED_LEFT, "it left");
        break;
    default:
        m->c.rejected_unexpected++;
        if (peer_should_log_drop(p))
            log_warn("worker %s: unexpected %s dropped", p->name, proto_type_name(msg.type));
        if (msg.type == MSG_JOB)
            proto_job_fini(&msg.u.job);
    }
}

/* ---- journal ---- */

struct replay_ctx { struct master *m; };

static int replay_tile(void *ctx, uint32_t unit, const struct tile_stats *st, const uint8_t *chunk, uint32_t size)
{
    struct master *m = ((struct replay_ctx *)ctx)->m;
    char err[256];
    if (m->sched->tiles[unit].state == SCHED_DONE)
        return 0; /* a unit journaled twice: the first copy is as good */
    if (m->sched->tiles[unit].state == SCHED_HELD)
        return 0; /* not wanted by the rounds replayed so far (cannot happen: records follow the rounds) */
    if (chunk_is_sane(m, unit, chunk, size, err, sizeof err) != 1) {
        log_warn("journal: unit %u (tile %u, pass %u) does not decode (%s); the journal is cut there", unit,
                 unit_tile(m, unit), unit_pass(m, unit), err);
        return -1;
    }
    if (unit_keep(m, unit, st, chunk, size, NULL) != 0)
        return -1;
    sched_tile_set_done(m->sched, unit);
    m->c.tiles_from_journal++;
    return 0;
}

/* The journal belongs to exactly this job: scene and assets (the scene hash covers them
 * and the settings, an adaptive render's target, per-pixel bound and round cap too:
 * publish_manifest) plus the layout of tiles and the sampler. */
static void compute_job_key(struct master *m)
{
    const struct render_settings *rs = &m->scene.settings;
    char ident[512];
    int n = snprintf(ident, sizeof ident,
                     "brume-journal-2 %s tile=%u sampler=%u frame=%u tiles=%u passes=%u target=%.17g rounds=%u",
                     m->scene_hash, rs->tile_size, (unsigned)rs->sampler, m->frame, m->num_tiles, m->passes,
                     m->target_error, m->max_rounds);
    if (m->adapt) /* units are (tile, slot) pairs of pixel blocks */
        n += snprintf(ident + n, sizeof ident - (size_t)n, " blocks=%u", m->blocks_side);
    blob_hash_compute(ident, (size_t)n, &m->job_key);
}

static int open_journal(struct master *m)
{
    const struct blob_hash key = m->job_key;
    char path[4200], err[512];
    snprintf(path, sizeof path, "%s.journal", m->out_path);
    uint32_t recovered;
    uint64_t torn;
    int other;
    struct replay_ctx ctx = {m};
    m->journal = journal_open(path, &key, m->num_units, replay_tile, &ctx, &recovered, &torn, &other, err, sizeof err);
    if (!m->journal) {
        m->journal_busy = errno == EBUSY; /* its stats file is the other master's */
        master_fail(m, "%s", err);
        return -1;
    }
    if (journal_syncer_start(m->journal, err, sizeof err) != 0)
        log_warn("%s; syncing in the main loop instead", err);
    if (other == 1)
        log_warn("%s belonged to another job (scene or settings differ); starting afresh", path);
    else if (other == 2)
        log_warn("%s is not a journal (its header is damaged or missing); starting afresh", path);
    if (recovered || torn)
        log_info("journal %s: %u unit(s) recovered%s", path, recovered, torn ? ", a torn last record cut off" : "");
    return 0;
}

/* ---- output ---- */

static int write_output(struct master *m, double seconds)
{
    const struct master_opts *o = m->opts;
    char err[512];
    struct image_attrs a;
    memset(&a, 0, sizeof a);
    a.spp = m->scene.settings.spp;
    a.seed = m->scene.settings.seed;
    a.render_seconds = seconds;
    snprintf(a.scene_hash, sizeof a.scene_hash, "%s", m->scene_hash);
    snprintf(a.software, sizeof a.software, "brume 0.1");
    a.est_rel_rmse = m->rel_rmse_est;
    a.passes = m->passes;
    if (m->adapt) {
        a.target_error = m->target_error;
        a.pixel_error = m->pixel_error;
        a.rounds = m->adapt->round + 1;
        a.time_limited = (uint32_t)m->time_up;
    }
    output_id_names(&m->scene, &a);
    int rc = output_write_exr(m->out_path, &m->out_desc, &a, m->chunks, err, sizeof err);
    output_id_names_free(&a);
    if (rc != 0) {
        master_fail(m, "%s", err);
        return -1;
    }
    /* Only now is the journal's content safe elsewhere. */
    if (m->journal) {
        m->c.journal_syncs += m->journal->syncs;
        journal_remove(&m->journal);
    }
    char preview[4200];
    if (o->preview_path && (output_frame_path(o->preview_path, o->have_frames, m->frame, preview, sizeof preview) != 0 ||
                            output_write_preview(preview, &m->out_desc, m->chunks, err, sizeof err) != 0))
        log_warn("preview: %s", err);
    return 0;
}

/* ---- progress ---- */

static void print_progress(struct master *m, uint64_t start_ms, int tty, int final)
{
    double secs = (double)(net_now_ms() - start_ms) / 1000.0;
    double rate = secs > 0 ? (double)m->stats.samples / secs : 0.0;
    double left = m->sched->tiles_done > 0 ? secs * (m->num_units - m->sched->tiles_done) / m->sched->tiles_done : 0.0;
    const char *what = m->passes > 1 ? "units" : "tiles";
    if (m->adapt) {
        /* Units of later rounds are not known yet: the ETA is fitted from the estimate's decay. */
        const struct adapt *a = m->adapt;
        double want = adapt_eta_samples(a);
        double eta = want > (double)m->stats.samples && rate > 0 ? (want - (double)m->stats.samples) / rate : 0.0;
        /* The fit is the target's: while pixels are above the bound it has no ETA to give. */
        char eta_text[32] = "";
        if (!(a->pixels_over > 0 && (m->target_error <= 0.0 || eta <= 0.0)))
            snprintf(eta_text, sizeof eta_text, "ETA %.0fs", eta);
        char est[96] = "estimate after round 0 pending", px[160] = "";
        if (a->num_history) {
            snprintf(est, sizeof est, m->target_error > 0.0 ? "est. relRMSE %.4f -> target %g" : "est. relRMSE %.4f",
                     a->est, m->target_error);
            pixel_bound_text(m, px, sizeof px);
        }
        if (tty)
            fprintf(stderr, "\rmaster: round %u, %u units to go  %s%s  %.2f Msamples/s  %s   %s", a->round,
                    a->outstanding, est, px, rate / 1e6, eta_text, final ? "\n" : "");
        else
            fprintf(stderr, "master: progress: round %u, %u units to go, %s%s, %.2f Msamples/s%s%s\n", a->round,
                    a->outstanding, est, px, rate / 1e6, eta_text[0] ? ", " : "", eta_text);
        fflush(stderr);
        return;
    }
    if (tty)
        fprintf(stderr, "\rmaster: %s %u/%u  %.2f Msamples/s  ETA %.0fs   %s", what, m->sched->tiles_done, m->num_units,
                rate / 1e6, left, final ? "\n" : "");
    else
        fprintf(stderr, "master: progress: %s %u/%u, %.2f Msamples/s, ETA %.0fs\n", what, m->sched->tiles_done,
                m->num_units, rate / 1e6, left);
    fflush(stderr);
}

/* The image's estimated relative RMSE: sqrt(mean over pixels of the variance of the pixel
 * mean, averaged over R, G, B) / (mean of R, G, B over the image), from the variance
 * channels of the finished tiles, summed as each was decoded or folded (fold_est). With
 * progressive passes they hold batch means, so the estimate includes the photon maps'
 * error. 0 for a black image. */
static double error_estimate(struct master *m)
{
    return fold_est_result(m->est, &m->var_saturated);
}

/* Design principle 4: each tile whose samples went NaN or Inf (dropped, counted in
 * nan_samples) is logged with the command that renders it alone (tile_command). A sample
 * is a pure function of (seed, frame, pixel, sample index), and every pass of the tile is
 * rendered again with the same settings, so that command drops the same samples: its
 * summary and stats show the same count. At most NAN_TILES_LOGGED tiles a frame, then a
 * count of the others. */
#define NAN_TILES_LOGGED 10
static void nan_report(struct master *m)
{
    uint32_t logged = 0, more = 0, tiles_x = imgio_tiles_x(&m->desc);
    for (uint32_t t = 0; t < m->num_tiles; t++) {
        if (!m->tile_nans[t])
            continue;
        if (logged == NAN_TILES_LOGGED) {
            more++;
            continue;
        }
        uint32_t x0, y0, w, h;
        imgio_tile_rect(&m->desc, t % tiles_x, t / tiles_x, &x0, &y0, &w, &h);
        char cmd[1800];
        tile_command(m, t, cmd, sizeof cmd);
        log_warn("frame %u tile %u (pixels %u,%u %ux%u, first in pass %u): %llu NaN/Inf sample(s) dropped; to render "
                 "exactly these samples again (the command line keeps --spp, --passes, --seed and the scene): %s",
                 m->frame, t, x0, y0, w, h, m->tile_nan_pass[t], (unsigned long long)m->tile_nans[t], cmd);
        logged++;
    }
    if (more)
        log_warn("frame %u: %u more tile(s) with NaN/Inf samples (not logged)", m->frame, more);
}

static void print_summary(struct master *m, double secs)
{
    const struct tile_stats *s = &m->stats;
    printf("summary: %s -> %s (frame %u)\n", m->opts->scene_path, m->out_path, m->frame);
    printf("summary: %ux%u, %u spp, %u tiles of %u px, seed %llu\n", m->scene.settings.width,
           m->scene.settings.height, m->scene.settings.spp, m->num_tiles, m->scene.settings.tile_size,
           (unsigned long long)m->scene.settings.seed);
    printf("summary: wall %.3f s, %.3f Msamples/s, %.3f Mrays/s\n", secs, secs > 0 ? s->samples / secs / 1e6 : 0.0,
           secs > 0 ? s->rays / secs / 1e6 : 0.0);
    printf("summary: NaN/Inf samples dropped: %llu; stale or rejected results: %llu\n",
           (unsigned long long)s->nan_samples,
           (unsigned long long)(m->c.results_stale + m->c.results_duplicate + m->c.results_invalid +
                                m->c.results_not_ours));
    printf("summary: tiles from journal: %llu\n", (unsigned long long)m->c.tiles_from_journal);
    printf("summary: noise: mean relative standard error %.4f over %u lit pixels\n",
           s->rel_stderr_pixels ? s->sum_rel_stderr / s->rel_stderr_pixels : 0.0, s->rel_stderr_pixels);
    printf("summary: estimated relRMSE %.4f (sqrt(mean pixel variance of the mean) / image mean, RGB; %s)\n",
           m->rel_rmse_est, m->passes > 1 ? "batch means over the streams of passes"
           : m->scene.settings.sampler != SAMPLER_INDEPENDENT
               ? "sample variance: an upper bound for Sobol and stratified samples; --passes 2 estimates it"
               : "sample variance");
    if (m->var_saturated)
        printf("summary: the variance of %llu pixel(s) is past float's range (saved as FLT_MAX): the estimate is a "
               "lower bound\n", (unsigned long long)m->var_saturated);
    if (m->adapt) {
        uint32_t lo = UINT32_MAX, hi = 0;
        double sum = 0.0, pixels = 0.0;
        for (uint32_t t = 0; t < m->adapt->num_tiles; t++) { /* per block */
            const struct adapt_tile *at = &m->adapt->tiles[t];
            uint32_t spp = at->passes * m->spp_per_pass;
            if (!at->pixels) /* past the image's edge */
                continue;
            lo = spp < lo ? spp : lo;
            hi = spp > hi ? spp : hi;
            sum += (double)spp * at->pixels;
            pixels += at->pixels;
        }
        printf("summary: adaptive: target relRMSE %g, estimated %.4f after %u round(s)%s; spp min %u mean %.1f max %u "
               "(cap %u); %.3f s\n", m->target_error, m->rel_rmse_est, m->adapt->round + 1,
               m->time_up ? " (time limit)" : "", lo, pixels > 0 ? sum / pixels : 0.0, hi, m->scene.settings.spp,
               secs);
        if (m->pixel_error > 0.0) {
            char px[160];
            pixel_bound_text(m, px, sizeof px);
            printf("summary: adaptive: per-pixel bound %g (relative standard error over max(pixel, %g x image mean))%s; "
                   "stopped: %s\n", m->pixel_error, ADAPT_PIXEL_FLOOR, px, m->adapt_stop ? m->adapt_stop : "-");
        }
    }
    /* Peers that did no work (refused, flooding, or joined late) are counted, not listed:
     * a flood of thousands of HELLOs must not bury the summary. Every peer is in the stats. */
    uint32_t idle = 0;
    for (uint32_t i = 0; i < m->num_peers; i++) {
        if (m->sched->workers[i].tiles_done == 0 && m->num_peers > 16) {
            idle++;
            continue;
        }
        printf("summary: worker %s: %u %s\n", m->peers[i].name, m->sched->workers[i].tiles_done,
               m->passes > 1 ? "units (tile passes)" : "tiles");
    }
    if (idle)
        printf("summary: %u other peer(s) finished no work (listed in the stats)\n", idle);
    if (m->photon_maps) {
        uint64_t bytes = 0, wait = 0, live = 0;
        for (uint32_t i = 0; i < m->num_peers; i++) {
            for (uint32_t p = 0; p < m->passes; p++)
                bytes += m->peers[i].map_bytes[p], wait += m->peers[i].wait_ms[p];
            wait += m->peers[i].fetch_wait_ms;
            live += m->peers[i].live_ms;
        }
        printf("summary: photon maps: %u pass(es), %llu map bytes fetched by %u worker(s), workers waited for maps "
               "%.1f %% of their time\n", m->passes, (unsigned long long)bytes, m->num_peers,
               live ? 100.0 * (double)wait / (double)live : 0.0);
        if (m->opts->verbose)
            for (uint32_t p = 0; p < m->passes; p++)
                for (uint32_t i = 0; i < m->num_peers; i++)
                    printf("summary: pass %u: worker %s fetched %llu map bytes, waited %llu ms for the map\n", p,
                           m->peers[i].name, (unsigned long long)m->peers[i].map_bytes[p],
                           (unsigned long long)m->peers[i].wait_ms[p]);
    }
    printf("summary: scene hash %s\n", m->scene_hash);
    fflush(stdout);
}

/* With --verbose: every counter, as tests of old read them. */
static void print_counters(const struct master *m)
{
#define X(n) printf("summary: counter %s %llu\n", #n, (unsigned long long)m->c.n);
    COUNTERS(X)
#undef X
    fflush(stdout);
}

/* OUT.stats.json: the run's outcome and counters, machine-readable; written on failure
 * too, so tests and scripts read what happened either way. */
static int write_stats(const struct master *m, int ok, char *err, size_t errlen)
{
    const struct master_opts *o = m->opts;
    const struct tile_stats *st = &m->stats;
    json_t *root = json_object(), *counters = json_object(), *workers = json_array();
    json_object_set_new(root, "format", json_string("brume-stats-1"));
    json_object_set_new(root, "ok", json_boolean(ok));
    json_object_set_new(root, "error", !ok && m->fatal[0] ? json_string(m->fatal) : json_null());
    json_object_set_new(root, "scene", json_string(o->scene_path));
    json_object_set_new(root, "output", json_string(o->output_path));
    json_object_set_new(root, "last_frame_output", json_string(m->out_path));
    json_object_set_new(root, "width", json_integer(m->scene.settings.width));
    json_object_set_new(root, "height", json_integer(m->scene.settings.height));
    json_object_set_new(root, "spp", json_integer(m->scene.settings.spp));
    json_object_set_new(root, "tiles", json_integer(m->num_tiles));
    json_object_set_new(root, "scene_hash", json_string(m->scene_hash));
    json_object_set_new(root, "wall_seconds", json_real(m->wall_seconds));
    json_object_set_new(root, "samples", json_integer((json_int_t)st->samples));
    json_object_set_new(root, "rays", json_integer((json_int_t)st->rays));
    json_object_set_new(root, "nan_samples", json_integer((json_int_t)st->nan_samples));
    json_object_set_new(root, "mean_rel_stderr",
                        json_real(st->rel_stderr_pixels ? st->sum_rel_stderr / st->rel_stderr_pixels : 0.0));
    json_object_set_new(root, "est_rel_rmse", json_real(m->rel_rmse_est));
    json_object_set_new(root, "variance_saturated_pixels", json_integer((json_int_t)m->var_saturated));
    json_object_set_new(root, "passes", json_integer(m->passes));
    if (m->adapt) {
        json_object_set_new(root, "target_error", json_real(m->target_error));
        json_object_set_new(root, "rounds", json_integer(m->adapt->round + 1));
        json_object_set_new(root, "time_limited", json_boolean(m->time_up));
        json_object_set_new(root, "uniform_passes", json_boolean(m->adapt->uniform));
        json_object_set_new(root, "predicted_work_ratio",
                            m->adapt->predicted > 0.0 ? json_real(m->adapt->predicted) : json_null());
        json_object_set_new(root, "adaptive_stop", m->adapt_stop ? json_string(m->adapt_stop) : json_null());
        if (m->pixel_error > 0.0) {
            json_object_set_new(root, "pixel_error", json_real(m->pixel_error));
            json_object_set_new(root, "pixels_over_bound", json_integer((json_int_t)m->adapt->pixels_over));
            json_object_set_new(root, "pixels_over_bound_at_cap", json_integer((json_int_t)m->adapt->pixels_over_capped));
            json_object_set_new(root, "worst_pixel_rel_error", json_real(m->adapt->worst));
        }
    }
    for (uint32_t i = 0; i < m->num_peers; i++) {
        json_t *w = json_object();
        json_object_set_new(w, "name", json_string(m->peers[i].name));
        json_object_set_new(w, "tiles", json_integer(m->sched->workers[i].tiles_done));
        json_array_append_new(workers, w);
    }
    json_object_set_new(root, "workers", workers);
    if (m->photon_maps && m->maps) {
        /* Per pass: the map's bytes and tracing time, and per worker the map bytes it
         * fetched and the ms it sat ready with credits while the pass's map was not out;
         * per worker too the ms it reported waiting for a map's fetch with nothing to render. */
        json_t *passes = json_array(), *wait = json_array();
        uint64_t waited = 0, live = 0;
        for (uint32_t p = 0; p < m->passes; p++) {
            json_t *jp = json_object(), *jw = json_array();
            json_object_set_new(jp, "pass", json_integer(p));
            json_object_set_new(jp, "map_bytes", json_integer((json_int_t)m->maps[p].size));
            json_object_set_new(jp, "trace_seconds", json_real(m->maps[p].seconds));
            for (uint32_t i = 0; i < m->num_peers; i++) {
                json_t *w = json_object();
                json_object_set_new(w, "name", json_string(m->peers[i].name));
                json_object_set_new(w, "map_bytes_fetched", json_integer((json_int_t)m->peers[i].map_bytes[p]));
                json_object_set_new(w, "wait_ms", json_integer((json_int_t)m->peers[i].wait_ms[p]));
                json_array_append_new(jw, w);
                waited += m->peers[i].wait_ms[p];
            }
            json_object_set_new(jp, "workers", jw);
            json_array_append_new(passes, jp);
        }
        for (uint32_t i = 0; i < m->num_peers; i++) {
            json_t *w = json_object();
            json_object_set_new(w, "name", json_string(m->peers[i].name));
            json_object_set_new(w, "fetch_wait_ms", json_integer((json_int_t)m->peers[i].fetch_wait_ms));
            json_object_set_new(w, "live_ms", json_integer((json_int_t)m->peers[i].live_ms));
            json_array_append_new(wait, w);
            waited += m->peers[i].fetch_wait_ms;
            live += m->peers[i].live_ms;
        }
        json_object_set_new(root, "photon_map_passes", passes);
        json_object_set_new(root, "map_waits", wait);
        json_object_set_new(root, "map_wait_share", json_real(live ? (double)waited / (double)live : 0.0));
    }
#define X(n) json_object_set_new(counters, #n, json_integer((json_int_t)m->c.n));
    COUNTERS(X)
#undef X
    json_object_set_new(root, "counters", counters);
    char path[4300];
    int rc;
    if (outnames_stats_path(o, path, sizeof path) != 0) {
        snprintf(err, errlen, "-o %s: the stats file's name is too long", o->output_path);
        rc = -1;
    } else {
        rc = asset_dir_find(&m->assets, path) >= 0 ? 0 : output_write_json(path, root, err, errlen); /* an input */
    }
    json_decref(root);
    return rc;
}

/* ---- main loop ---- */

static int start_local_workers(struct master *m)
{
    const struct master_opts *o = m->opts;
    if (o->workers == 0)
        return 0;
    /* In $TMPDIR when it is set (absolute and short enough for a socket path: 108 bytes
     * in all), so a master that is killed leaves its folder where its caller cleans up. */
    const char *tmp = getenv("TMPDIR");
    if (!tmp || tmp[0] != '/' || strlen(tmp) > 64)
        tmp = "/tmp";
    snprintf(m->ipc_dir, sizeof m->ipc_dir, "%s/brume-XXXXXX", tmp);
    if (!mkdtemp(m->ipc_dir)) {
        master_fail(m, "cannot create a private folder for the local socket in %s: %s", tmp, strerror(errno));
        return -1;
    }
    if (m->zap) {
        /* The master's own local workers get a fresh key pair in the private (0700) folder. */
        char err[512];
        snprintf(m->local_key_path, sizeof m->local_key_path, "%s/worker.key", m->ipc_dir);
        snprintf(m->local_pub_path, sizeof m->local_pub_path, "%s/master.pub", m->ipc_dir);
        if (zap_write_local_keys(m->local_key_path, m->local_pub_path, &m->curve_pub, &m->local_public, err,
                                 sizeof err) != 0) {
            master_fail(m, "%s", err);
            return -1;
        }
        zap_allow_key(m->zap, &m->local_public);
    }
    snprintf(m->ipc_endpoint, sizeof m->ipc_endpoint, "ipc://%s/master.sock", m->ipc_dir);
    if (bind_endpoint(m, m->ipc_endpoint) != 0 || bcast_bind(m, m->ipc_endpoint) != 0)
        return -1;
    m->local_pids = mem_calloc(o->workers, sizeof *m->local_pids);
    for (uint32_t i = 0; i < o->workers; i++) {
        pid_t pid = launch_worker(o->worker_exe, m->ipc_endpoint, o->threads, o->map_memory_mb,
                                  m->zap ? m->local_key_path : NULL, m->local_pub_path);
        if (pid < 0)
            return -1;
        m->local_pids[m->num_local++] = pid;
        m->local_alive++;
    }
    return 0;
}

/* A local worker process ended before the frame did: start another in its slot, up to
 * LOCAL_RESTARTS_MAX per local worker over the run, so that one stopped or crashed worker
 * cannot end a one-command render. A tile that takes workers down still fails the job
 * by its crash blame (sched.h), restarted workers being distinct workers. */
#define LOCAL_RESTARTS_MAX 3u
static void restart_local(struct master *m, uint32_t slot)
{
    const struct master_opts *o = m->opts;
    if (g_interrupted || m->fatal[0] || m->sched->tiles_done >= m->num_units ||
        m->local_restarts >= LOCAL_RESTARTS_MAX * m->num_local)
        return;
    pid_t pid = launch_worker(o->worker_exe, m->ipc_endpoint, o->threads, o->map_memory_mb,
                              m->zap ? m->local_key_path : NULL, m->local_pub_path);
    if (pid < 0)
        return;
    m->local_pids[slot] = pid;
    m->local_alive++;
    m->local_restarts++;
    m->c.local_restarts++;
    log_warn("local worker %u started again (pid %d; restart %u of at most %u)", slot, (int)pid, m->local_restarts,
             LOCAL_RESTARTS_MAX * m->num_local);
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
                restart_local(m, i);
            }
        for (uint32_t i = 0; i < m->num_peers; i++)
            if (!m->sched->workers[i].gone && m->peers[i].pid == (uint32_t)pid && m->num_local > 0) {
                char why[64];
                if (WIFSIGNALED(status))
                    snprintf(why, sizeof why, "process killed by signal %d", WTERMSIG(status));
                else
                    snprintf(why, sizeof why, "process exited with status %d", WEXITSTATUS(status));
                evict_peer(m, (int32_t)i, sched_death_kind(WIFSIGNALED(status), WTERMSIG(status)), why);
            }
    }
}

#define LIVENESS_MS 10 /* check_liveness looks at every peer this often (timeouts are 100s of ms and more) */
static void check_liveness(struct master *m, uint64_t now)
{
    const struct master_opts *o = m->opts;
    for (uint32_t i = 0; i < m->num_peers; i++) {
        char why[128];
        uint64_t for_ms;
        switch (sched_worker_health(m->sched, (int32_t)i, now, o->worker_timeout_ms, o->stall_ms, &for_ms)) {
        case SCHED_HEALTHY:
            break;
        case SCHED_HEALTH_SILENT:
            snprintf(why, sizeof why, "no heartbeat for %llu ms", (unsigned long long)for_ms);
            evict_peer(m, (int32_t)i, SCHED_SILENT, why);
            break;
        case SCHED_HEALTH_STALLED:
            snprintf(why, sizeof why, "its render threads made no progress for %llu ms", (unsigned long long)for_ms);
            evict_peer(m, (int32_t)i, SCHED_STALLED, why);
            break;
        case SCHED_HEALTH_STALL_REPORTED:
            snprintf(why, sizeof why, "a render thread made no progress for %llu ms", (unsigned long long)for_ms);
            evict_peer(m, (int32_t)i, SCHED_STALLED, why);
            break;
        }
    }
}

/* ---- frames ---- */

static int start_local_workers(struct master *m);

/* Traces the photon maps of `frame` on the tracer's thread (maps_poll publishes them);
 * the last frame's maps, if any, are dropped (geometry moves: every frame has its own). */
static int maps_start(struct master *m, uint32_t frame)
{
    char err[512];
    photon_tracer_free(&m->tracer, 0); /* the last frame's: done or nearly (the stop flag is for good) */
    for (uint32_t p = 0; p < m->maps_published; p++)
        blob_store_drop(&m->blobs, &m->maps[p].hash);
    memset(m->maps, 0, sizeof *m->maps * m->passes);
    m->maps_published = 0;
    for (uint32_t i = 0; i < m->num_peers; i++)
        m->peers[i].maps_sent = 0;
    /* An adaptive render wants the maps of the passes its rounds give out (adapt_release). */
    m->tracer = photon_tracer_new(&m->scene, m->opts, frame, m->passes, m->adapt ? 0 : m->passes, err, sizeof err);
    if (!m->tracer) {
        master_fail(m, "%s", err);
        return -1;
    }
    m->map_frame = frame;
    m->maps_started = 1;
    return 0;
}

/* Publishes the maps traced since the last call, in pass order: a blob each, MAP to every
 * worker, and the pass's units released. */
static int maps_poll(struct master *m)
{
    while (m->tracer) {
        uint32_t pass;
        uint8_t *data;
        size_t size;
        double secs;
        char err[600];
        struct blob_hash hash, *chunks;
        int rc = photon_tracer_poll(m->tracer, &pass, &data, &size, &secs, &hash, &chunks, err, sizeof err);
        if (rc < 0) {
            master_fail(m, "%s", err);
            return -1;
        }
        if (rc == 0)
            return 0;
        const struct blob_entry *e = blob_store_adopt_listed(&m->blobs, &hash, data, size, chunks); /* named by the tracer */
        m->maps[pass].hash = e->hash;
        m->maps[pass].size = size;
        m->maps[pass].seconds = secs;
        m->maps_published = pass + 1;
        for (uint32_t i = 0; i < m->num_peers; i++)
            if (!m->sched->workers[i].gone)
                send_maps(m, &m->peers[i]);
        sched_release(m->sched, m->maps_published * m->num_tiles);
        log_debug("photon map %u published (%zu bytes); its units go out", pass, size);
        if (m->maps_published == m->passes)
            photon_tracer_free(&m->tracer, 0);
    }
    return 0;
}

/* Worker time for the statistics: each ready worker's time in the frame, and the part of
 * it spent idle with credits while every queued unit waited for a map not yet published
 * (charged to that pass). */
static void account_waits(struct master *m, uint64_t dt)
{
    if (dt == 0) /* most passes of a busy loop: nothing to add to anyone */
        return;
    int blocked = sched_blocked(m->sched);
    uint32_t pass = m->maps_published < m->passes ? m->maps_published : m->passes - 1;
    for (uint32_t i = 0; i < m->num_peers; i++) {
        const struct sched_worker *w = &m->sched->workers[i];
        if (w->gone || !w->ready)
            continue;
        m->peers[i].live_ms += dt;
        if (blocked && w->in_flight == 0 && w->credits > 0)
            m->peers[i].wait_ms[pass] += dt;
    }
}

/* A scene with per-frame files (a grid "smoke.####.nvdb") parsed again for m->frame: its
 * manifest names this frame's files only, so a worker fetches the grids of the frames it
 * renders, and the frame's hash covers them (a changed grid re-renders its frame). The
 * last frame's photon tracer is done by now; the pass plan must come out the same. */
static int scene_reload(struct master *m)
{
    photon_tracer_free(&m->tracer, 0);
    uint32_t passes = m->passes, photon_maps = m->photon_maps, spp = m->scene.settings.spp;
    asset_dir_fini(&m->assets);
    scene_fini(&m->scene);
    if (load_scene(m, m->frame) != 0)
        return -1;
    if (m->passes != passes || m->photon_maps != photon_maps || m->scene.settings.spp != spp) {
        master_fail(m, "%s: frame %u plans %u pass(es), %u photon map(s), %u spp; the first frame (%u) %u, %u, %u: the frames "
                       "of a range must agree (a grid so thin that its photon pass is skipped?)",
                    m->opts->scene_path, m->frame, m->passes, m->photon_maps, m->scene.settings.spp, m->map_frame,
                    passes, photon_maps, spp);
        return -1;
    }
    return 0;
}

/* A master killed while it wrote the frame's output, stats or preview left OUT.tmp.PID:
 * removed once that PID is no live process (output_remove_stale_tmp), in one log line. */
static void remove_stale_tmp(struct master *m)
{
    const struct master_opts *o = m->opts;
    char stats[4300], preview[4200];
    unsigned n = output_remove_stale_tmp(m->out_path);
    if (outnames_stats_path(o, stats, sizeof stats) == 0)
        n += output_remove_stale_tmp(stats);
    if (o->preview_path && output_frame_path(o->preview_path, o->have_frames, m->frame, preview, sizeof preview) == 0)
        n += output_remove_stale_tmp(preview);
    if (n)
        log_info("removed %u temporary file(s) (%s.tmp.PID and the like) left by a master no longer running", n,
                 m->out_path);
}

/* Starts frame m->frame: fresh tile slots, its journal, and a JOB for every worker
 * (which keeps its blobs and rebuilds only what depends on the frame). 1 when the frame
 * is done already (skipped), 0 when it is ready to render, -1 on error. */
static int frame_begin(struct master *m, uint32_t frames_started)
{
    const struct master_opts *o = m->opts;
    if (m->scene.frame_files && m->frame != m->scene_frame && scene_reload(m) != 0)
        return -1;
    m->check_ctx = (struct check_ctx){.desc = m->desc, .num_tiles = m->num_tiles, .passes = m->passes,
                                      .num_objects = m->scene.num_meshes + m->scene.num_spheres,
                                      .num_materials = m->scene.num_materials,
                                      .journal = !o->no_journal && !o->only_tiles,
                                      .out_desc = m->fold ? m->out_desc : m->desc, .fold = m->fold,
                                      .keep_units = m->fold && !m->adapt};
    if (m->checker) /* idle: the last frame drained it */
        checker_set_ctx(m->checker, &m->check_ctx,
                        (size_t)m->scene.settings.tile_size * m->scene.settings.tile_size * FOLD_MAX_CHANNELS);
    if (output_frame_path(o->output_path, o->have_frames, m->frame, m->out_path, sizeof m->out_path) != 0) {
        master_fail(m, "-o %s: the output name for frame %u is too long", o->output_path, m->frame);
        return -1;
    }
    frame_hash(m);
    compute_job_key(m);
    if (o->have_frames && !o->only_tiles &&
        output_is_done(m->out_path, m->scene_hash, m->scene.settings.spp, m->scene.settings.seed, &m->desc)) {
        char jpath[4300];
        snprintf(jpath, sizeof jpath, "%s.journal", m->out_path);
        unlink(jpath); /* left behind by a master killed between rename and cleanup */
        log_info("frame %u: %s is already rendered with this scene and settings; skipped", m->frame, m->out_path);
        m->c.frames_skipped++;
        return 1;
    }
    if (m->photon_maps && (!m->maps_started || (m->map_per_frame && m->frame != m->map_frame)) &&
        maps_start(m, m->map_per_frame ? m->frame : m->map_frame) != 0)
        return -1;
    for (uint32_t t = 0; t < m->num_tiles; t++)
        output_chunk_free(&m->chunks[t]);
    sched_frame_begin(m->sched);
    if (m->photon_maps) /* a pass's units go out once its map is published */
        sched_release(m->sched, m->maps_published * m->num_tiles);
    if (m->fold)
        fold_reset(m->fold);
    fold_est_reset(m->est);
    memset(&m->stats, 0, sizeof m->stats);
    memset(m->tile_nans, 0, sizeof *m->tile_nans * m->num_tiles);
    if (m->adapt) { /* units go out round by round (adapt.h); round 0 now */
        sched_hold_all(m->sched);
        adapt_begin(m->adapt);
        m->adapt_stop = NULL;
        memset(m->round_from, 0, sizeof *m->round_from * m->num_cells);
        memset(m->slots_used, 0, sizeof *m->slots_used * m->num_tiles);
        m->time_up = 0;
    }
    if (o->only_tiles && restrict_tiles(m) != 0)
        return -1;
    if (m->adapt)
        adapt_release(m);
    if (m->journal) {
        m->c.journal_syncs += m->journal->syncs;
        journal_free(&m->journal);
    }
    /* A --tiles render is a debugging aid: it keeps no journal of its own. Journaled
     * tiles are done in the scheduler, so they never go out again. */
    uint32_t outside = m->sched->tiles_done; /* --tiles: the units it does not render */
    uint64_t journaled = m->c.tiles_from_journal;
    if (!o->no_journal && !o->only_tiles && open_journal(m) != 0)
        return -1;
    remove_stale_tmp(m);
    journaled = m->c.tiles_from_journal - journaled;
    m->job_id = m->job_base + frames_started;
    for (uint32_t i = 0; i < m->num_peers; i++)
        if (!m->sched->workers[i].gone && m->sched->tiles_done < m->num_units)
            send_job(m, &m->peers[i]);
    if (m->sched->tiles_done < m->num_units && !m->local_pids && start_local_workers(m) != 0)
        return -1;
    char units[64] = "";
    if (m->passes > 1)
        snprintf(units, sizeof units, " in %u passes: %u units", m->passes, m->num_units);
    char skipped[64] = "";
    if (o->only_tiles)
        snprintf(skipped, sizeof skipped, ", %u outside --tiles", outside);
    log_info("rendering %s frame %u -> %s: %ux%u, %u spp, %u tiles%s (%llu from the journal%s), %u local worker(s)%s%s",
             o->scene_path, m->frame, m->out_path, m->scene.settings.width, m->scene.settings.height,
             m->scene.settings.spp, m->num_tiles, units, (unsigned long long)journaled, skipped, o->workers,
             o->bind ? ", accepting workers at " : "", o->bind ? o->bind : "");
    return 0;
}

/* Renders the current frame until every tile is in (0) or the job fails (-1). */
static int frame_render(struct master *m, uint64_t *last_beat)
{
    const struct master_opts *o = m->opts;
    int tty = isatty(2);
    uint64_t start = net_now_ms(), last_progress = start, last_tick = start;
    int bcast_busy = 0;
    while (m->sched->tiles_done < m->num_units) {
        if (g_interrupted) {
            if (m->tracer && m->sched->tiles_done == 0) {
                /* Nothing rendered yet: the photon pass was what ran; nothing to resume. */
                snprintf(m->fatal, sizeof m->fatal, "photon pass interrupted: %u of %u photon maps of frame %u traced, "
                         "no unit rendered", m->maps_published, m->passes, m->frame);
                if (m->journal)
                    journal_remove(&m->journal);
            } else {
                snprintf(m->fatal, sizeof m->fatal, "interrupted; %u of %u %s of frame %u were finished",
                         m->sched->tiles_done, m->num_units, m->passes > 1 ? "units (tile passes)" : "tiles", m->frame);
            }
            return -1;
        }
        if (m->fatal[0])
            return -1;
        void *zap_sock = m->zap ? zap_socket(m->zap) : NULL, *mon = m->zap ? zap_monitor_socket(m->zap) : NULL;
        /* the socket, ZAP and its monitor (when CurveZMQ is on), the checker's verdicts */
        void *mon2 = m->zap ? zap_monitor2_socket(m->zap) : NULL;
        zmq_pollitem_t items[7] = {{m->sock, 0, ZMQ_POLLIN, 0}};
        int nitems = 1, izap = -1, imon = -1, imon2 = -1, ibc = -1;
        if (mon2)
            items[imon2 = nitems++] = (zmq_pollitem_t){mon2, 0, ZMQ_POLLIN, 0};
        if (m->bcast)
            items[ibc = nitems++] = (zmq_pollitem_t){m->bcast, 0, ZMQ_POLLIN, 0};
        if (zap_sock)
            items[izap = nitems++] = (zmq_pollitem_t){zap_sock, 0, ZMQ_POLLIN, 0};
        if (mon)
            items[imon = nitems++] = (zmq_pollitem_t){mon, 0, ZMQ_POLLIN, 0};
        if (m->checker)
            items[nitems++] = (zmq_pollitem_t){NULL, checker_fd(m->checker), ZMQ_POLLIN, 0};
        /* ACKs waiting for the sync thread: it wakes us when a sync ends (or, without the
         * thread, look again soon) */
        int sync_fd = m->journal ? journal_sync_fd(m->journal) : -1;
        if (sync_fd >= 0)
            items[nitems++] = (zmq_pollitem_t){NULL, sync_fd, ZMQ_POLLIN, 0};
        if (zmq_poll(items, nitems, bcast_busy ? 1 : m->num_acks && sync_fd < 0 ? 2 : 100) < 0 && errno != EINTR) {
            snprintf(m->fatal, sizeof m->fatal, "poll: %s", zmq_strerror(errno));
            return -1;
        }
        if (izap >= 0 && (items[izap].revents & ZMQ_POLLIN))
            m->c.auth_rejects += (uint64_t)zap_handle(m->zap);
        if ((imon >= 0 && (items[imon].revents & ZMQ_POLLIN)) || (imon2 >= 0 && (items[imon2].revents & ZMQ_POLLIN)))
            m->c.handshake_failures += zap_monitor_drain(m->zap);
        if (items[0].revents & ZMQ_POLLIN) {
            struct net_frame f;
            int got;
            while ((got = net_recv(m->sock, 1, &f)) != 0) {
                if (got > 0) {
                    handle_message(m, &f);
                } else {
                    m->c.rejected_envelope++;
                    if (m->c.rejected_envelope <= 5)
                        log_warn("a message with a malformed envelope (frame count or identity) was dropped");
                }
                net_frame_fini(&f);
            }
        }
        checks_drain(m, 0);
        uint64_t now = net_now_ms();
        if (ibc >= 0 && (items[ibc].revents & ZMQ_POLLIN))
            bcast_read(m, now);
        bcast_busy = bcast_pump(m, now);
        if (m->adapt && m->time_limit > 0.0 && !m->time_up && (double)(now - start) >= m->time_limit * 1000.0) {
            m->time_up = 1; /* the one decision that depends on timing (docs/adaptive.md) */
            log_info("adaptive: time limit %g s reached; the render stops at the end of round %u", m->time_limit,
                     m->adapt->round);
        }
        account_waits(m, now - last_tick);
        last_tick = now;
        if (!g_interrupted && maps_poll(m) != 0) /* interrupted: the tracer stopped too; said above */
            return -1;
        reap_local(m);
        if (now - m->last_liveness_ms >= LIVENESS_MS) {
            check_liveness(m, now);
            m->last_liveness_ms = now;
        }
        if (m->fatal[0])
            continue;
        if (!o->bind && m->local_alive == 0 && sched_live_workers(m->sched) == 0) {
            snprintf(m->fatal, sizeof m->fatal, "every worker has exited; %u of %u %s were finished%s%.1000s",
                     m->sched->tiles_done, m->num_units, m->passes > 1 ? "units" : "tiles", m->last_worker_error[0] ? "; last worker error: " : "",
                     m->last_worker_error);
            return -1;
        }
        if (o->bind && sched_live_workers(m->sched) == 0 && now - m->last_waiting_ms >= 10000) {
            m->last_waiting_ms = now;
            log_info("waiting for workers: 0 connected, %u of %u %s done", m->sched->tiles_done, m->num_units,
                     m->passes > 1 ? "units" : "tiles");
        }
        assign_tiles(m);
        commit_and_ack(m, 0);
        if (now - *last_beat >= 1000) {
            struct proto_msg hb = {.type = MSG_HEARTBEAT};
            hb.u.heartbeat.job_id = m->job_id;
            hb.u.heartbeat.tiles_done = m->sched->tiles_done;
            for (uint32_t i = 0; i < m->num_peers; i++)
                if (!m->sched->workers[i].gone)
                    send_to(m, &m->peers[i], &hb);
            *last_beat = now;
        }
        if (now - last_progress >= (tty ? PROGRESS_TTY_MS : PROGRESS_PLAIN_MS)) {
            print_progress(m, start, tty, 0);
            last_progress = now;
        }
    }
    checks_drain(m, 1); /* straggler copies still being checked: duplicates now */
    commit_and_ack(m, 1); /* the frame's last records on disk, every worker told */
    if (m->fatal[0]) /* e.g. the last journal sync failed */
        return -1;
    print_progress(m, start, tty, 1);
    double secs = (double)(net_now_ms() - start) / 1000.0;
    m->wall_seconds += secs;
    m->rel_rmse_est = error_estimate(m);
    if (write_output(m, secs) != 0)
        return -1;
    nan_report(m);
    print_summary(m, secs);
    return 0;
}

/* Who may join. Every tcp:// endpoint (loopback included) gets CurveZMQ: with the key
 * pair and allow-list of --curve-secret/--allow, or else a throw-away key pair that only
 * this master's local workers are given. Without a tcp:// endpoint the local socket's
 * file permissions are the guard (docs/cluster.md); --insecure opens tcp:// to anyone,
 * with a warning every run. The MAC key of TILE tags comes from the master's secret key,
 * so a master restarted with the same key pair recognises its assignments. */
static int auth_setup(struct master *m)
{
    const struct master_opts *o = m->opts;
    char err[600];
    int tcp = o->bind && net_endpoint_is_tcp(o->bind);
    if (!o->curve_secret && (!tcp || o->insecure)) {
        if (getrandom(m->tag_key.bytes, sizeof m->tag_key.bytes, 0) != (ssize_t)sizeof m->tag_key.bytes) {
            master_fail(m, "getrandom: %s", strerror(errno));
            return -1;
        }
        m->tcp_open = tcp;
        if (tcp)
            log_warn("--insecure: workers at %s are not authenticated: anyone who can reach it can join, read the "
                     "scene and alter the image", o->bind);
        return 0;
    }
    if (o->curve_secret ? net_key_pair_load(o->curve_secret, &m->curve_pub, &m->curve_sec, err, sizeof err) != 0
                        : zmq_curve_keypair(m->curve_pub.z85, m->curve_sec.z85) != 0) {
        master_fail(m, "%s", o->curve_secret ? err : "cannot create a CurveZMQ key pair (libzmq without CURVE?)");
        return -1;
    }
    m->zap = zap_new(m->zctx, m->sock, &m->curve_sec, err, sizeof err);
    if (!m->zap || (o->allow_path && zap_allow_file(m->zap, o->allow_path, err, sizeof err) != 0)) {
        master_fail(m, "%s", err);
        return -1;
    }
    char text[64];
    int n = snprintf(text, sizeof text, "brume-tile-tag-1 %s", m->curve_sec.z85);
    blob_hash_compute(text, (size_t)n, &m->tag_key);
    if (o->curve_secret)
        log_info("CurveZMQ on: %zu allowed worker key(s)", zap_num_allowed(m->zap));
    else
        log_info("CurveZMQ on at %s with a throw-away key pair: only this master's local workers can join (remote "
                 "workers need --curve-secret and --allow, docs/cluster.md)", o->bind);
    return 0;
}

/* Binds endpoint (none: nothing to do). A socket file is created readable and writable by
 * our user only, whatever the umask: connecting needs write permission on it. */
static int bind_endpoint(struct master *m, const char *endpoint)
{
    if (!endpoint)
        return 0;
    mode_t old = umask(077);
    int rc = zmq_bind(m->sock, endpoint);
    int e = errno;
    umask(old);
    if (rc != 0) {
        master_fail(m, "cannot bind %s: %s", endpoint, zmq_strerror(e));
        return -1;
    }
    return 0;
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
    /* Job ids of one run are consecutive (one per frame), so a message of an earlier
     * frame is recognised as late rather than foreign. */
    if (getrandom(&m.job_base, sizeof m.job_base, 0) != sizeof m.job_base)
        m.job_base = ((uint64_t)getpid() << 32) ^ net_now_ms();
    m.job_base &= ~((uint64_t)1 << 63); /* room for every frame's id above it */
    m.job_id = m.job_base;
    peer_index_init(&m.peer_index, MAX_SLOTS);
    if (load_scene(&m, o->have_frames ? o->frame_first : 0) != 0)
        goto done;
    setup_tiles(&m);
    if (o->check_threads)
        m.checker = checker_new(o->check_threads);
    m.zctx = zmq_ctx_new();
    m.sock = zmq_socket(m.zctx, ZMQ_ROUTER);
    net_socket_setup(m.sock);
    int mandatory = 1;
    zmq_setsockopt(m.sock, ZMQ_ROUTER_MANDATORY, &mandatory, sizeof mandatory);
    if (auth_setup(&m) != 0 || bind_endpoint(&m, o->bind) != 0 || bcast_bind(&m, o->bind) != 0)
        goto done;
    uint32_t first = o->have_frames ? o->frame_first : 0, last = o->have_frames ? o->frame_last : 0;
    uint32_t step = o->have_frames ? o->frame_step : 1, started = 0;
    uint64_t last_beat = net_now_ms();
    for (uint64_t f = first; f <= last; f += step) {
        m.frame = (uint32_t)f;
        int b = frame_begin(&m, started);
        if (b < 0)
            goto done;
        started++;
        if (b > 0)
            continue;
        if (frame_render(&m, &last_beat) != 0)
            goto done;
        m.c.frames_done++;
    }
    if (o->have_frames)
        printf("summary: frames %u:%u:%u: %llu rendered, %llu already done (skipped)\n", first, last, step,
               (unsigned long long)m.c.frames_done, (unsigned long long)m.c.frames_skipped);
    rc = 0;
done:
    {
        struct proto_msg bye = {.type = MSG_BYE};
        for (uint32_t i = 0; i < m.num_peers && m.sock; i++)
            if (!m.sched->workers[i].gone)
                send_to(&m, &m.peers[i], &bye);
    }
    if (m.num_local && g_interrupted) /* interrupted: local workers drop their tiles at the next row */
        for (uint32_t i = 0; i < m.num_local; i++)
            if (m.local_pids[i] > 0)
                kill(m.local_pids[i], SIGTERM);
    if (m.num_local)
        launch_stop_all(m.local_pids, m.num_local, 3000);
    if (m.ipc_dir[0]) {
        char sockpath[400];
        snprintf(sockpath, sizeof sockpath, "%s/master.sock", m.ipc_dir);
        unlink(sockpath);
        for (int i = 0; i < 2; i++)
            if (m.bcast_ipc[i][0] && !strncmp(m.bcast_ipc[i], m.ipc_dir, strlen(m.ipc_dir)))
                unlink(m.bcast_ipc[i]);
        if (m.local_key_path[0]) {
            unlink(m.local_key_path);
            char pub[420];
            snprintf(pub, sizeof pub, "%s.pub", m.local_key_path);
            unlink(pub);
            unlink(m.local_pub_path);
        }
        rmdir(m.ipc_dir);
    }
    if (m.journal) {
        m.c.journal_syncs += m.journal->syncs;
        journal_free(&m.journal);
    }
    photon_tracer_free(&m.tracer, 1);
    checker_free(&m.checker);
    zap_free(&m.zap);
    if (m.bcast)
        zmq_close(m.bcast);
    for (size_t i = 0; i < m.num_streams; i++)
        free(m.streams[i].chunk_hashes);
    free(m.streams);
    if (m.sock) {
        /* A finished job: the last ACKs and the BYEs still queued for remote workers get
         * up to a second to go (a worker that does not read them holds the exit no longer). */
        int linger = rc == 0 ? 1000 : 0;
        zmq_setsockopt(m.sock, ZMQ_LINGER, &linger, sizeof linger);
        zmq_close(m.sock);
    }
    if (m.zctx)
        zmq_ctx_term(m.zctx);
    /* Last: the stats file (none when refused for another master's journal: that name is
     * its stats'), the counters with --verbose, and on failure the one error line (a
     * reason from the render loop; set-up errors were logged where they happened). */
    char err[512];
    if (!m.journal_busy && write_stats(&m, rc == 0, err, sizeof err) != 0 && rc == 0)
        log_warn("stats: %s", err);
    if (o->verbose)
        print_counters(&m);
    if (rc != 0 && m.fatal[0])
        log_error("%s", m.fatal);
    for (uint32_t t = 0; t < m.num_tiles && m.chunks; t++)
        output_chunk_free(&m.chunks[t]);
    free(m.chunks);
    free(m.tile_nans);
    free(m.tile_nan_pass);
    sched_free(&m.sched);
    for (uint32_t i = 0; i < m.num_peers; i++) {
        free(m.peers[i].map_bytes);
        free(m.peers[i].wait_ms);
    }
    free(m.peers);
    peer_index_fini(&m.peer_index);
    fold_free(&m.fold);
    fold_est_free(&m.est);
    adapt_free(&m.adapt);
    free(m.round_from);
    free(m.slots_used);
    free(m.slot_pass);
    free(m.slot_mask);
    imgio_encoder_free(&m.enc);
    free(m.fold_out);
    free(m.fold_scratch);
    free(m.maps);
    free(m.local_pids);
    free(m.manifest);
    free(m.decode_scratch);
    free(m.acks);
    proto_buf_fini(&m.out);
    blob_store_fini(&m.blobs);
    asset_dir_fini(&m.assets);
    scene_fini(&m.scene);
    return rc;
}
