/* Media tracking: the frame's media state (which medium the camera and each light sit in,
 * the scene's bounds, step and gather radius, the photon map to use, shadow caches), which
 * medium a point is in, the medium after a boundary crossing, and shadow transmittance
 * through boundaries. Media do not nest: outside every medium object is the fog, or vacuum.
 * Built by render_job_init for scenes with media (before the job is complete, so it reads
 * the accel and light table, not the job); read by the media estimators and photon tracing. */
#ifndef BRUME_MEDIA_TRACK_H
#define BRUME_MEDIA_TRACK_H
#include <stdint.h>
#include "render/surface.h"
#include "scene/grid.h"
#include "scene/medium.h"

struct photon_map;
struct shadow_caches;

/* At most this many glowing lights (point and spot lights inside a scattering medium)
 * per job: the final gather's bounce samples directions toward them (media_integrator.h). */
#define MEDIA_GLOW_MAX 8
#define MEDIA_AIM_MAX 8

struct media_job {
    const struct scene_media *sm;
    const struct accel *accel;      /* the job's: the job must not move while this lives */
    const struct light_table *lights;
    uint32_t camera_medium;
    uint32_t *light_medium;     /* per light-table entry: the medium it emits into */
    vec3 bounds_lo, bounds_hi;  /* geometry, lights and camera */
    float scene_size;           /* diagonal of the bounds */
    float step;                 /* marching step used (in grids only when sm gives one: media_step) */
    float radius;               /* gather radius used */
    const struct photon_map *map; /* the job's map for Jensen's methods; NULL: single scattering only (skipped, or VPT) */
    struct shadow_caches *shadow; /* march / beam: per (point light, grid medium) tr_cache, filled on first use */
    struct medium *cut;         /* per medium: medium_forward_cut of it, what march / beam camera rays see */
    struct grid_aim *aims;      /* scattering grid media, at most MEDIA_AIM_MAX: the final gather's */
    uint32_t num_aims;          /* bounce samples directions toward their density */
    int aim;                    /* media_bounding_sphere found one: aim_center, aim_radius */
    vec3 aim_center;
    float aim_radius;
    uint32_t num_glow;          /* glowing lights: point and spot lights where their medium scatters (a */
    vec3 glow[MEDIA_GLOW_MAX];  /* grid's density not 0), the light table's first MEDIA_GLOW_MAX (positions) */
};

/* Voxels of a grid per in-scattering step of a march when the scene gives no step: the
 * light in a grid changes over voxels, and a march's NEE at every half voxel (its optical
 * depth's step) took 1.12-1.21x the CPU for the same error on scenes/smoke and a thinner
 * cloud (docs/media.md). But light also changes where geometry and lights make it (a
 * spot's cone, a shadow), whatever the grid: so at most GRID_STEP_CAP times the step of a
 * homogeneous medium (a coarse grid's 2 voxels, 1 m across a spot's shaft, had 2.8x the
 * error). */
#define GRID_STEP_VOXELS 2.0f
#define GRID_STEP_CAP 2.0f

/* The in-scattering step of a march through md: the scene's step where it gives one, else
 * 1/200 of the scene's diagonal in a homogeneous medium and GRID_STEP_VOXELS of a grid's
 * voxels, at most GRID_STEP_CAP times that, in a grid. */
static inline float media_step(const struct media_job *mj, const struct medium *md)
{
    if (!md->grid || mj->sm->step > 0.0f) /* no grid, or the scene (or --march-step) gives the step */
        return mj->step;
    float v = GRID_STEP_VOXELS * md->grid->voxel_world, cap = GRID_STEP_CAP * mj->step;
    return v < cap ? v : cap;
}

/* The bounding sphere of where the scene's media are (grids' occupied boxes, medium
 * spheres and meshes; a little padded); 0 when a homogeneous fog fills all space. Photons
 * and the final gather's bounce aim at it. */
int media_bounding_sphere(const struct scene *sc, vec3 *center, float *radius);

/* a, lt: the render job's (outlive the result); map: the job's photon map or NULL. */
struct media_job *media_job_new(const struct accel *a, const struct light_table *lt, const struct photon_map *map);
void media_job_free(struct media_job **mj);

/* The medium at point p (a ray toward a fixed direction finds the medium object it is
 * inside, if any), or the fog. */
uint32_t media_at(const struct media_job *mj, vec3 p);
/* Medium on the far side after a ray travelling along dir crosses the boundary hit h. */
uint32_t media_after_crossing(const struct media_job *mj, const struct accel_hit *h, vec3 ng, vec3 dir);
int media_is_interface(const struct media_job *mj, uint32_t material);
/* Transmittance from p to target through boundaries (invisible medium boundaries are
 * crossed; any other surface blocks: 0). */
vec3 media_shadow_transmittance(const struct media_job *mj, vec3 p, vec3 target, uint32_t medium, float time01,
                                uint64_t key, uint64_t *rays);

#endif
