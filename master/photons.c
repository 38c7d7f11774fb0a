/* Photon pass on the master and publication of the volume blob (see photons.h). The
 * photon map it builds is a pure function of the scene and frame (photon_trace.c). */
#include "photons.h"
#include "wire/blob.h"
#include "base/log.h"
#include "render/media_track.h"
#include "render/photon_map.h"
#include "render/photon_trace.h"
#include "render/render_job.h"
#include "scene/medium.h"
#include <stdlib.h>
#include <stdio.h>
#include <string.h>

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
    for (uint32_t i = 0; i < scene->num_meshes; i++)
        if (scene->meshes[i].num_keys > 1 || scene->meshes[i].num_frames >= 2)
            return 1;
    for (uint32_t i = 0; i < scene->num_spheres; i++)
        if (scene->spheres[i].num_keys > 1)
            return 1;
    return 0;
}

int master_media_prepare(struct scene *scene, const struct master_opts *o, uint32_t frame, struct asset_dir *assets)
{
    struct scene_media *sm = scene->media;
    if (!sm)
        return 0;
    if (o->have_media_method)
        sm->method = (enum media_method)o->media_method;
    if (o->have_photons)
        sm->photons = o->photons;
    if (o->have_gather_radius)
        sm->radius = o->gather_radius;
    if (o->have_march_step)
        sm->step = o->march_step;
    uint8_t *map = NULL, *blob = NULL;
    size_t map_size = 0, blob_size = 0;
    int used = 0;
    for (uint32_t i = 0; i < sm->num_media; i++)
        used |= !v3_is_black(sm->media[i].sigma_t);
    if (sm->method == MEDIA_VPT) {
        log_info("media: volumetric path tracing, no photon pass");
    } else if (!used || sm->photons == 0) {
        log_info("media: no photon pass (%s)", used ? "photons 0" : "no medium scatters or absorbs");
    } else {
        char err[512];
        struct render_job job;
        uint32_t threads = o->photon_threads ? o->photon_threads : 1;
        if (render_job_init(&job, scene, frame, threads, err, sizeof err) != 0) {
            log_error("photon pass: %s", err);
            return -1;
        }
        double bound = photon_trace_indirect_bound(scene, job.media->scene_size);
        if (bound < sm->skip_bound) {
            log_info("media: photon pass skipped: multiple scattering is bounded by %.3g < skip_bound %.3g "
                     "(max(surface reflectance, medium albedo x (1 - exp(-sigma_t,max x %.3g))))",
                     bound, (double)sm->skip_bound, (double)job.media->scene_size);
        } else {
            struct photon_pass_stats st;
            if (photon_trace_map(&job, scene->settings.seed, threads, &map, &map_size, &st, err, sizeof err) != 0) {
                render_job_fini(&job);
                log_error("%s", err);
                return -1;
            }
            struct blob_hash h;
            char hex[65];
            blob_hash_compute(map, map_size, &h);
            blob_hash_hex(&h, hex);
            log_info("media: photon pass: %llu emitted, %llu stored (%llu on surfaces) in %.3f s on %u thread(s) "
                     "(%.3g photons/s), %zu bytes (%.1f bytes/photon), radius %g, multiple-scattering bound %.3g, "
                     "map %.16s",
                     (unsigned long long)st.emitted, (unsigned long long)st.stored,
                     (unsigned long long)st.stored_surface, st.seconds, threads,
                     st.seconds > 0 ? (double)st.emitted / st.seconds : 0.0, st.bytes,
                     st.stored ? (double)st.bytes / (double)st.stored : 0.0, (double)job.media->radius, bound, hex);
        }
        render_job_fini(&job);
    }
    volume_blob_make(sm, map, map_size, &blob, &blob_size);
    free(map);
    publish(assets, blob, blob_size);
    log_info("media: method %s, volume blob %zu bytes", media_method_name(sm->method), blob_size);
    return 0;
}
