/* Photon pass on the master and publication of the volume blob (see photons.h). The
 * photon map it builds is a pure function of the scene and frame (photon_trace.c). */
#include "photons.h"
#include "wire/blob.h"
#include "base/log.h"
#include "base/rng.h"
#include "scene/scene_limits.h"
#include "render/media_track.h"
#include "render/photon_map.h"
#include "render/passes.h"
#include "render/photon_trace.h"
#include "render/render_job.h"
#include "scene/medium.h"
#include <pthread.h>
#include <stdlib.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

/* Adds the volume blob to the job's files, or replaces the one there (a new frame's). */
static void publish(struct asset_dir *assets, uint8_t *data, size_t size)
{
    struct asset_file *f = NULL;
    for (size_t i = 0; i < assets->num_files && !f; i++)
        if (strcmp(assets->files[i].path, MEDIA_PHOTON_ASSET) == 0)
            f = &assets->files[i];
    if (f) {
        free(f->data);
    } else {
        mem_grow((void **)&assets->files, &assets->cap_files, assets->num_files + 1, sizeof *assets->files);
        f = &assets->files[assets->num_files++];
    }
    memset(f, 0, sizeof *f);
    snprintf(f->path, sizeof f->path, "%s", MEDIA_PHOTON_ASSET);
    f->data = (char *)data;
    f->size = size;
}

int master_media_per_frame(const struct scene *scene)
{
    const struct scene_media *sm = scene->media;
    if (!sm || sm->method == MEDIA_VPT || sm->photons == 0)
        return 0;
    if (scene->frame_files) /* a grid per frame */
        return 1;
    for (uint32_t i = 0; i < scene->num_meshes; i++)
        if (scene->meshes[i].num_keys > 1 || scene->meshes[i].num_frames >= 2)
            return 1;
    for (uint32_t i = 0; i < scene->num_spheres; i++)
        if (scene->spheres[i].num_keys > 1)
            return 1;
    return 0;
}

static double now_seconds(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* The seed of pass p's photons: the scene's seed for pass 0 (a single pass traces the map
 * it always did), a hash of (seed, pass) after; photon_trace keys every photon by (seed,
 * frame, index), so each map is a pure function of (seed, frame, pass). */
static uint64_t pass_seed(uint64_t seed, uint32_t pass)
{
    return pass == 0 ? seed : rng_mix64(seed ^ rng_mix64(0x7061737365730000ull + pass));
}

/* photon_trace_map serialises the surface map with the volume map's radius; a pass gives
 * it its own (the 2D rule): its photons are sorted again, in the order the first map holds
 * them (deterministic), in place behind the volume map's bytes (photon_map_set_radius). */
static int set_surface_radius(uint8_t *map, size_t size, float radius, char *err, size_t errlen)
{
    size_t vbytes = photon_map_serialised_bytes(map);
    CHECK(vbytes < size);
    return photon_map_set_radius(map + vbytes, photon_map_serialised_bytes(map + vbytes), radius, err, errlen);
}

int master_passes_fit(struct render_settings *rs, uint32_t passes)
{
    uint32_t k = (rs->spp + passes - 1) / passes;
    if ((uint64_t)k * passes > SCENE_MAX_SPP) {
        log_error("passes: %u passes of %u spp exceed the %u spp limit (lower --spp or --passes / render.passes)",
                  passes, k, (unsigned)SCENE_MAX_SPP);
        return -1;
    }
    if (k * passes != rs->spp)
        log_info("passes: spp %u raised to %u (%u passes of ceil(%u / %u) = %u spp)", rs->spp, k * passes, passes,
                 rs->spp, passes, k);
    rs->spp = k * passes;
    return 0;
}

/* The pilot: a map of at most PHOTON_PILOT photons, traced as pass 0's would be, measures
 * per emitted photon the bytes, the seconds and the photons stored in the volume map. Its
 * counts are a pure function of the scene, seed and frame (photon i's random numbers are
 * keyed by i), so the plan that reads them is too. */
#define PHOTON_PILOT 4096u
struct photon_pilot {
    uint32_t traced;
    double bytes, seconds, stored; /* per emitted photon; stored: in the volume map */
};

static int photon_pilot(struct scene *scene, uint32_t frame, uint32_t threads, struct photon_pilot *out)
{
    struct scene_media *sm = scene->media;
    uint64_t photons = sm->photons;
    char err[512];
    struct render_job job;
    out->traced = photons < PHOTON_PILOT ? (uint32_t)photons : PHOTON_PILOT;
    sm->photons = out->traced;
    uint8_t *data = NULL;
    size_t size = 0;
    struct photon_pass_stats st;
    int rc = render_job_init(&job, scene, frame, threads, err, sizeof err);
    if (rc == 0) {
        rc = photon_trace_map(&job, pass_seed(scene->settings.seed, 0), threads, &data, &size, &st, err, sizeof err);
        render_job_fini(&job);
    }
    sm->photons = photons;
    free(data);
    if (rc != 0) {
        log_error("photon pass: %s", err);
        return -1;
    }
    out->bytes = (double)size / out->traced;
    out->seconds = st.seconds / out->traced;
    out->stored = (double)(st.stored - st.stored_surface) / out->traced;
    return 0;
}

/* Budget before work: the maps of a frame (the master holds them all, for late workers and
 * re-issues), estimated from the pilot, must fit in budget_bytes. A photon count that
 * would take hours and all memory is refused at once, naming the setting. */
static int photon_budget(const struct scene *scene, const struct photon_pilot *pilot, uint32_t passes,
                         double budget_bytes, uint32_t threads)
{
    uint64_t photons = scene->media->photons;
    if (photons <= PHOTON_PILOT)
        return 0;
    double bytes = pilot->bytes * (double)photons * passes, secs = pilot->seconds * (double)photons * passes;
    log_info("media: photon budget: %u map(s) of %llu photons: about %.3g GB and %.3g s of tracing on %u thread(s) "
             "(from a pilot of %u photons; budget %.3g GB)", passes, (unsigned long long)photons, bytes / 1e9, secs,
             threads, pilot->traced, budget_bytes / 1e9);
    if (bytes > budget_bytes) {
        log_error("volume.photons %llu x %u pass(es): the photon maps would take about %.3g GB (%.1f bytes per emitted "
                  "photon, from a pilot of %u), more than the budget of %.3g GB (half this machine's memory, or "
                  "--photon-memory GB); lower --photons / volume.photons or the passes",
                  (unsigned long long)photons, passes, bytes / 1e9, pilot->bytes, pilot->traced,
                  budget_bytes / 1e9);
        return -1;
    }
    /* A map is one blob: past BLOB_MAX_SIZE it could not be shipped (and the tracer would
     * stop at its CHECK). The estimate is a pilot's, so keep a margin. */
    double map_bytes = pilot->bytes * (double)photons;
    if (map_bytes > 0.75 * (double)BLOB_MAX_SIZE) {
        log_error("volume.photons %llu: one photon map would take about %.3g GB (%.1f bytes per emitted photon, "
                  "from a pilot of %u), near or past the %.3g GB a blob may hold; lower --photons / volume.photons",
                  (unsigned long long)photons, map_bytes / 1e9, pilot->bytes, pilot->traced,
                  (double)BLOB_MAX_SIZE / 1e9);
        return -1;
    }
    return 0;
}

/* Half the machine's physical memory, in bytes (1 GB when it cannot be read). */
static double default_photon_memory(void)
{
    long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
    return pages > 0 && page > 0 ? 0.5 * (double)pages * (double)page : 1e9;
}

int master_media_prepare(struct scene *scene, const struct master_opts *o, uint32_t frame, struct asset_dir *assets,
                         uint32_t asked, uint32_t *photon_maps)
{
    struct scene_media *sm = scene->media;
    *photon_maps = 0;
    if (!sm)
        return 0;
    if (o->have_media_method)
        sm->method = (enum media_method)o->media_method;
    if (o->have_indirect)
        sm->indirect = (enum media_indirect)o->indirect;
    if (o->have_photons)
        sm->photons = o->photons;
    if (o->have_gather_radius)
        sm->radius = o->gather_radius;
    if (o->have_march_step)
        sm->step = o->march_step;
    if (!(sm->alpha > 0.0f))
        sm->alpha = MEDIA_DEFAULT_ALPHA;
    uint8_t *blob = NULL;
    size_t blob_size = 0;
    uint32_t passes = 0;
    int used = 0;
    const char *no_map = NULL;
    for (uint32_t i = 0; i < sm->num_media; i++)
        used |= !v3_is_black(sm->media[i].sigma_t);
    if (sm->method == MEDIA_VPT) {
        log_info("media: volumetric path tracing, no photon pass");
        no_map = "volumetric path tracing";
    } else if (!used || sm->photons == 0) {
        log_info("media: no photon pass (%s)", used ? "photons 0" : "no medium scatters or absorbs");
        no_map = "no photon pass";
    } else {
        char err[512];
        struct render_job job;
        if (render_job_init(&job, scene, frame, 1, err, sizeof err) != 0) {
            log_error("photon pass: %s", err);
            return -1;
        }
        double bound = photon_trace_indirect_bound(scene, job.media->scene_size);
        float r0 = job.media->radius, scene_size = job.media->scene_size;
        render_job_fini(&job);
        if (bound < sm->skip_bound) {
            log_info("media: photon pass skipped: multiple scattering is bounded by %.3g < skip_bound %.3g "
                     "(max(surface reflectance, medium albedo x (1 - exp(-sigma_t,max x %.3g))))",
                     bound, (double)sm->skip_bound, (double)scene_size);
            no_map = "photon pass skipped";
        } else {
            /* Progressive photon mapping: P maps from fresh seeds, radii by the PPM rule,
             * traced while tiles render (photon_tracer_new). */
            struct render_settings *rs = &scene->settings;
            struct pass_plan plan;
            struct photon_pilot pilot;
            uint32_t pilot_threads = o->photon_threads ? o->photon_threads : 1;
            /* The pilot (its stored-per-emitted ratio caps the photons) at a frame that does
             * not depend on where a range starts: this frame's grid where each frame has its
             * own (this runs again per frame), else frame 0, so that a frame renders the same
             * photons in any range (frame farms split ranges). */
            if (photon_pilot(scene, scene->frame_files ? frame : 0, pilot_threads, &pilot) != 0)
                return -1;
            int plan_rc = passes_plan(rs->spp, asked, sm->photons, o->have_photons, pilot.stored,
                                      (uint64_t)rs->width * rs->height, &plan);
            uint32_t k = plan.spp_per_pass;
            passes = plan.passes;
            if (plan.photons != sm->photons)
                log_info("passes: %llu photons per pass (of %llu: with the default passes at most %u emitted and %u "
                         "stored in the volume map per pixel, %.3g stored per emitted in a pilot of %u)",
                         (unsigned long long)plan.photons, (unsigned long long)sm->photons, PASS_PHOTONS_PER_PIXEL,
                         PASS_STORED_PER_PIXEL, pilot.stored, pilot.traced);
            sm->photons = plan.photons;
            if (plan_rc != 0) {
                log_error("passes: %u passes of %u spp exceed the %u spp limit (lower --spp or --passes / "
                          "render.passes)", passes, k, (unsigned)SCENE_MAX_SPP);
                return -1;
            }
            if (k * passes != rs->spp)
                log_info("passes: spp %u raised to %u (%u passes of ceil(%u / %u) = %u spp)", rs->spp, k * passes,
                         passes, rs->spp, passes, k);
            rs->spp = plan.spp;
            if (photon_budget(scene, &pilot, passes, o->photon_memory_gb > 0.0 ? o->photon_memory_gb * 1e9
                                                                                : default_photon_memory(),
                              pilot_threads) != 0)
                return -1;
            log_info("passes: %u of %u spp (%u spp), pass p with photon map p; radius %g to %g (surface %g to %g), "
                     "multiple-scattering bound %.3g", passes, k, rs->spp, (double)r0,
                     photon_pass_radius(r0, sm->alpha, passes - 1, passes_volume_kernel_dim(sm->method)), (double)r0,
                     photon_pass_radius(r0, sm->alpha, passes - 1, PASSES_SURFACE_KERNEL_DIM), bound);
        }
    }
    if (no_map)
        log_debug("media: no photon map (%s)", no_map);
    /* The settings alone: the maps are blobs of their own, one per pass (MSG_MAP). */
    volume_blob_make(sm, NULL, 0, &blob, &blob_size);
    publish(assets, blob, blob_size);
    *photon_maps = passes;
    log_info("media: method %s, indirect %s, settings blob %zu bytes, %u photon map(s)", media_method_name(sm->method),
             media_indirect_name(sm->indirect), blob_size, passes);
    return 0;
}

/* ---- the tracer thread ---- */

struct traced_map {
    uint8_t *data;
    size_t size;
    double seconds;
    struct blob_hash hash;      /* the blob's name and its chunk list, from one pass here */
    struct blob_hash *chunks;
};

struct photon_tracer {
    const struct scene *scene;
    uint32_t frame, passes, threads;
    uint32_t want;              /* maps 0..want-1 are to be traced (under lock; photon_tracer_want) */
    int quit;                   /* photon_tracer_free: trace nothing past want (under lock) */
    pthread_t thread;
    pthread_mutex_t lock;
    pthread_cond_t want_cv;
    struct traced_map *maps;    /* per pass, filled in pass order by the thread */
    uint32_t traced, taken;     /* maps traced (under lock), maps handed to the caller */
    int failed, joined;
    char err[512];
};

static int trace_one(struct photon_tracer *t, struct render_job *job, float r0, uint32_t p, struct traced_map *out)
{
    const struct scene_media *sm = t->scene->media;
    struct photon_pass_stats st;
    float rv = (float)photon_pass_radius(r0, sm->alpha, p, passes_volume_kernel_dim(sm->method));
    float rsurf = (float)photon_pass_radius(r0, sm->alpha, p, PASSES_SURFACE_KERNEL_DIM);
    job->media->radius = rv;
    double t0 = now_seconds();
    if (photon_trace_map(job, pass_seed(t->scene->settings.seed, p), t->threads, &out->data, &out->size, &st, t->err,
                         sizeof t->err) != 0)
        return -1;
    if (media_wants_surface_photons(sm) && set_surface_radius(out->data, out->size, rsurf, t->err, sizeof t->err) != 0) {
        free(out->data);
        out->data = NULL;
        return -1;
    }
    out->seconds = now_seconds() - t0;
    char hex[65];
    uint64_t num_chunks;
    blob_chunk_hashes(out->data, out->size, &out->chunks, &num_chunks);
    blob_name_of_chunks(out->chunks, num_chunks, &out->hash);
    blob_hash_hex(&out->hash, hex);
    log_info("media: photon map %u of %u: %llu emitted, %llu stored (%llu on surfaces, %llu beams) in %.3f s on %u thread(s), "
             "%zu bytes, radius %g (surface %g), map %.16s", p, t->passes, (unsigned long long)st.emitted,
             (unsigned long long)st.stored, (unsigned long long)st.stored_surface, (unsigned long long)st.stored_beams, out->seconds, t->threads, out->size,
             (double)rv, (double)rsurf, hex);
    return 0;
}

static void *tracer_thread(void *arg)
{
    struct photon_tracer *t = arg;
    struct render_job job;
    char err[400];
    if (render_job_init(&job, t->scene, t->frame, t->threads, err, sizeof err) != 0) {
        pthread_mutex_lock(&t->lock);
        snprintf(t->err, sizeof t->err, "photon pass: %s", err);
        t->failed = 1;
        pthread_mutex_unlock(&t->lock);
        return NULL;
    }
    const float r0 = job.media->radius;
    uint8_t *hashes = mem_alloc(32 * (size_t)t->passes); /* the maps' hashes, for one logged hash */
    double seconds = 0.0;
    size_t bytes = 0;
    uint32_t p = 0;
    for (; p < t->passes; p++) {
        pthread_mutex_lock(&t->lock); /* a map only once it is wanted */
        while (p >= t->want && !t->quit)
            pthread_cond_wait(&t->want_cv, &t->lock);
        int wanted = p < t->want;
        pthread_mutex_unlock(&t->lock);
        if (!wanted)
            break;
        struct traced_map m = {0};
        int rc = trace_one(t, &job, r0, p, &m);
        if (rc == 0) {
            memcpy(hashes + 32 * (size_t)p, m.hash.bytes, 32);
            seconds += m.seconds;
            bytes += m.size;
        }
        pthread_mutex_lock(&t->lock);
        if (rc != 0)
            t->failed = 1;
        else
            t->maps[t->traced++] = m;
        pthread_mutex_unlock(&t->lock);
        if (rc != 0)
            break;
    }
    if (p == t->passes) {
        struct blob_hash all;
        char all_hex[65];
        blob_hash_compute(hashes, 32 * (size_t)t->passes, &all);
        blob_hash_hex(&all, all_hex);
        log_info("media: photon pass: %u map(s) (progressive passes, alpha %g) of frame %u in %.3f s on %u thread(s), "
                 "%zu bytes, map %.16s", t->passes, (double)t->scene->media->alpha, t->frame, seconds, t->threads, bytes,
                 all_hex);
    }
    free(hashes);
    render_job_fini(&job);
    return NULL;
}

struct photon_tracer *photon_tracer_new(const struct scene *scene, const struct master_opts *o, uint32_t frame,
                                        uint32_t passes, uint32_t want, char *err, size_t errlen)
{
    struct photon_tracer *t = mem_calloc(1, sizeof *t);
    t->scene = scene;
    t->frame = frame;
    t->passes = passes;
    t->want = want < passes ? want : passes;
    t->threads = o->photon_threads ? o->photon_threads : 1;
    t->maps = mem_calloc(passes ? passes : 1, sizeof *t->maps);
    pthread_mutex_init(&t->lock, NULL);
    pthread_cond_init(&t->want_cv, NULL);
    if (pthread_create(&t->thread, NULL, tracer_thread, t) != 0) {
        str_fmt(err, errlen, "photon pass: cannot start its thread");
        pthread_cond_destroy(&t->want_cv);
        pthread_mutex_destroy(&t->lock);
        free(t->maps);
        free(t);
        return NULL;
    }
    return t;
}

void photon_tracer_want(struct photon_tracer *t, uint32_t maps)
{
    pthread_mutex_lock(&t->lock);
    if (maps > t->want) {
        t->want = maps < t->passes ? maps : t->passes;
        pthread_cond_signal(&t->want_cv);
    }
    pthread_mutex_unlock(&t->lock);
}

int photon_tracer_poll(struct photon_tracer *t, uint32_t *pass, uint8_t **map, size_t *size, double *seconds,
                       struct blob_hash *hash, struct blob_hash **chunks, char *err, size_t errlen)
{
    pthread_mutex_lock(&t->lock);
    int rc = 0;
    if (t->taken < t->traced) {
        struct traced_map *m = &t->maps[t->taken];
        *pass = t->taken++;
        *map = m->data;
        *size = m->size;
        *seconds = m->seconds;
        if (hash)
            *hash = m->hash;
        if (chunks)
            *chunks = m->chunks;
        else
            free(m->chunks);
        m->data = NULL;
        m->chunks = NULL;
        rc = 1;
    } else if (t->failed) {
        str_fmt(err, errlen, "%s", t->err);
        rc = -1;
    }
    pthread_mutex_unlock(&t->lock);
    return rc;
}

void photon_tracer_free(struct photon_tracer **tp, int stop)
{
    struct photon_tracer *t = *tp;
    if (!t)
        return;
    pthread_mutex_lock(&t->lock);
    int busy = !t->failed && t->traced < t->want;
    t->quit = 1; /* no map past those wanted */
    pthread_cond_signal(&t->want_cv);
    pthread_mutex_unlock(&t->lock);
    if (busy && stop)
        photon_trace_request_stop(); /* the master is leaving: the pass stops at its next photon */
    pthread_join(t->thread, NULL);
    for (uint32_t p = 0; p < t->passes; p++) {
        free(t->maps[p].data);
        free(t->maps[p].chunks);
    }
    free(t->maps);
    pthread_cond_destroy(&t->want_cv);
    pthread_mutex_destroy(&t->lock);
    free(t);
    *tp = NULL;
}
