/* The frame context (see render_job.h). Texture pyramids, the light table and the photon
 * map depend only on the scene and are kept across frames; the Embree scene, camera and
 * media state are rebuilt per frame. */
#include "render/render_job.h"
#include "base/log.h"
#include "image/mip.h"
#include "render/media_track.h"
#include "render/motion_vis.h"
#include "render/photon_beams.h"
#include "render/photon_map.h"
#include "scene/texture.h"
#include <stdlib.h>
#include <string.h>

/* BRUME_PACKETS=0 turns camera packets off (tests compare the two). */
static int packets_env_enabled(void)
{
    const char *e = getenv("BRUME_PACKETS");
    return !(e && strcmp(e, "0") == 0);
}

/* MIP pyramids of the scene's image textures, once per job, only when a material uses a
 * texture (others never look one up, so their images are unchanged bit for bit). */
static void mips_init(struct render_job *job)
{
    const struct scene *scene = job->scene;
    job->textured = 0;
    for (uint32_t i = 0; i < scene->num_materials; i++)
        if (scene->materials[i].albedo_tex || scene->materials[i].bump_tex || scene->materials[i].normal_tex ||
            scene->materials[i].roughness_tex)
            job->textured = 1;
    if (!job->textured || scene->num_textures == 0)
        return;
    job->mips = mem_calloc(scene->num_textures, sizeof *job->mips);
    for (uint32_t i = 0; i < scene->num_textures; i++) {
        const struct texture *t = &scene->textures[i];
        if (t->type == TEXTURE_IMAGE)
            mip_init(&job->mips[i], &t->image, t->wrap);
    }
}

static void mips_fini(struct render_job *job)
{
    for (uint32_t i = 0; job->mips && i < job->scene->num_textures; i++)
        mip_fini(&job->mips[i]);
    free(job->mips);
    job->mips = NULL;
}

/* Pass p's view of the media state: the job's, with pass p's map (and its radius). */
static void pass_view_set(struct render_job *job, uint32_t p)
{
    const struct photon_map *m = job->pass_maps ? job->pass_maps[p] : NULL;
    job->pass_media[p] = *job->media;
    job->pass_media[p].map = job->media->sm->method != MEDIA_VPT ? m : NULL;
    if (job->pass_media[p].map)
        job->pass_media[p].radius = m->radius;
}

/* The passes' views of the media state, after the media state or the passes change. */
static void passes_update(struct render_job *job)
{
    free(job->pass_media);
    job->pass_media = NULL;
    if (job->num_passes == 0)
        job->num_passes = 1;
    if (!job->media)
        return;
    job->pass_media = mem_calloc(job->num_passes, sizeof *job->pass_media);
    for (uint32_t p = 0; p < job->num_passes; p++)
        pass_view_set(job, p);
}

static void pass_maps_free(struct render_job *job)
{
    for (uint32_t p = 0; job->pass_maps && p < job->num_passes; p++)
        photon_map_free(&job->pass_maps[p]);
    free(job->pass_maps);
    job->pass_maps = NULL;
}

const struct media_job *render_job_pass_media(const struct render_job *job, uint32_t pass)
{
    return job->pass_media && pass < job->num_passes ? &job->pass_media[pass] : job->media;
}

/* What depends on the frame: Embree scene, camera at the frame's time, media state. */
static int frame_init(struct render_job *job, uint32_t frame, uint32_t threads, char *err, size_t errlen)
{
    const struct scene *scene = job->scene;
    job->frame = frame;
    if (accel_init(&job->accel, scene, frame, threads, err, errlen) != 0)
        return -1;
    camera_init(&job->camera, &scene->camera, scene->settings.width, scene->settings.height);
    camera_set_scene_motion(&job->camera, job->accel.has_motion);
    job->motion_vis = motion_vis_new(&job->accel, scene, &job->camera, frame);
    if (scene->media)
        job->media = media_job_new(&job->accel, &job->lights, job->pass_maps ? job->pass_maps[0] : NULL);
    /* Lights seen straight from the camera, averaged over stratified camera rays: what a
     * sample of a media scene costs is mostly its path, and a pixel on a lamp's outline
     * otherwise takes one sample's guess of how much of it the lamp covers. */
    job->direct_samples = 1;
    if (job->media && (job->lights.num_surface > 0 || scene->env)) {
        uint32_t cm = job->media->camera_medium;
        if (cm == MEDIUM_NONE || !scene->media->media[cm].grid)
            job->direct_samples = media_direct_samples(scene->media);
    }
    for (uint32_t i = 0; i < job->direct_samples; i++) {
        double a = (double)i * 0.7548776662466927, b = (double)i * 0.5698402909980532;
        job->direct_shift[i][0] = (float)(a - (double)(int64_t)a); /* exact: a - trunc(a) */
        job->direct_shift[i][1] = (float)(b - (double)(int64_t)b);
    }
    job->packets = !job->media && job->accel.packets_exact && packets_env_enabled();
    passes_update(job);
    return 0;
}

int render_job_init(struct render_job *job, const struct scene *scene, uint32_t frame, uint32_t threads,
                    char *err, size_t errlen)
{
    memset(job, 0, sizeof *job);
    job->scene = scene;
    light_table_init(&job->lights, scene);
    job->rays_find_light = scene->env != NULL;
    for (uint32_t i = 0; i < scene->num_materials; i++)
        if (!v3_is_black(scene->materials[i].emission))
            job->rays_find_light = 1;
    if (frame_init(job, frame, threads, err, errlen) != 0) {
        light_table_fini(&job->lights);
        return -1;
    }
    mips_init(job);
    return 0;
}

int render_job_reframe(struct render_job *job, uint32_t frame, uint32_t threads, char *err, size_t errlen)
{
    motion_vis_free(&job->motion_vis);
    accel_fini(&job->accel);
    media_job_free(&job->media);
    free(job->pass_media);
    job->pass_media = NULL;
    if (frame_init(job, frame, threads, err, errlen) != 0) {
        render_job_fini(job);
        return -1;
    }
    return 0;
}

void render_job_set_photon_map(struct render_job *job, struct photon_map **map)
{
    uint32_t n = 0;
    for (const struct photon_map *m = *map; m; m = m->next_pass)
        n++;
    render_job_set_passes(job, n);
    for (uint32_t p = 0; p < n; p++) {
        struct photon_map *m = *map;
        *map = m->next_pass;
        m->next_pass = NULL;
        render_job_set_pass_map(job, p, &m);
    }
}

void render_job_set_passes(struct render_job *job, uint32_t passes)
{
    pass_maps_free(job);
    job->num_passes = passes ? passes : 1;
    job->pass_maps = passes ? mem_calloc(passes, sizeof *job->pass_maps) : NULL;
    if (job->media)
        job->media->map = NULL;
    passes_update(job);
}

void render_job_set_pass_map(struct render_job *job, uint32_t pass, struct photon_map **map)
{
    CHECK(job->pass_maps && pass < job->num_passes);
    photon_map_free(&job->pass_maps[pass]);
    job->pass_maps[pass] = *map;
    *map = NULL;
    if (job->pass_maps[pass] && job->pass_maps[pass]->beams) /* traversed with the job's kernels */
        photon_beams_set_isa(job->pass_maps[pass]->beams, job->scene->settings.embree_isa);
    if (pass == 0 && job->media)
        job->media->map = job->media->sm->method != MEDIA_VPT ? job->pass_maps[0] : NULL;
    if (job->media)
        pass_view_set(job, pass);
}

const struct photon_map *render_job_pass_map(const struct render_job *job, uint32_t pass)
{
    return job->pass_maps && pass < job->num_passes ? job->pass_maps[pass] : NULL;
}

void render_job_fini(struct render_job *job)
{
    if (!job->scene)
        return;
    mips_fini(job);
    motion_vis_free(&job->motion_vis);
    accel_fini(&job->accel);
    light_table_fini(&job->lights);
    media_job_free(&job->media);
    free(job->pass_media);
    pass_maps_free(job);
    memset(job, 0, sizeof *job);
}
