/* Rendering of scenes with participating media: what a render_job adds for them (which
 * medium the camera and each light sit in, the scene's bounds, the photon map) and the
 * camera-path estimators: the volumetric path tracer (reference) and Jensen's ray marching
 * with per-step photon lookups or the beam radiance estimate. Rays track the medium they
 * are in across object boundaries (media do not nest: outside every medium object is the
 * fog, or vacuum). Called by integrator.c (sample_path hands media scenes over) and by
 * photonmap.c (medium queries for photon tracing). */
#ifndef BRUME_MEDIA_INTEGRATOR_H
#define BRUME_MEDIA_INTEGRATOR_H
#include <stdint.h>
#include "render/integrator.h"
#include "scene/medium.h"
#include "scene/sampler.h"

struct media_job {
    const struct scene_media *sm;
    uint32_t camera_medium;
    uint32_t *light_medium;     /* per light-table entry: the medium it emits into */
    vec3 bounds_lo, bounds_hi;  /* geometry, lights and camera */
    float scene_size;           /* diagonal of the bounds */
    float step;                 /* marching step used */
    float radius;               /* gather radius used */
    const struct photon_map *map; /* NULL: single scattering only (skipped, or VPT) */
    struct shadow_caches *shadow; /* march / beam: per (point light, grid medium) tr_cache, filled on first use */
};

/* A hit as the media code sees it (integrator.c's surface, copied out). */
struct media_surface {
    vec3 p, ng, ns;
    uint32_t material, light;
    float p_err;
};

/* Built by render_job_init when scene->media is set. */
struct media_job *media_job_new(const struct render_job *job);
void media_job_free(struct media_job **mj);

/* The medium at point p (a ray toward a fixed direction finds the medium object it is
 * inside, if any), or the fog. */
uint32_t media_at(const struct render_job *job, vec3 p);
/* Medium on the far side after a ray travelling along dir crosses the boundary hit h. */
uint32_t media_after_crossing(const struct render_job *job, const struct accel_hit *h, vec3 ng, vec3 dir);
int media_is_interface(const struct render_job *job, uint32_t material);
/* Transmittance from p to target through boundaries (invisible medium boundaries are
 * crossed; any other surface blocks: 0). */
vec3 media_shadow_transmittance(const struct render_job *job, vec3 p, vec3 target, uint32_t medium, float time01,
                                uint64_t key, uint64_t *rays);

/* integrator.c: its surface reconstruction, for this module. */
void integrator_media_surface(const struct render_job *job, vec3 org, vec3 dir, const struct accel_hit *h,
                              float time01, struct media_surface *out);

/* One camera sample of a media scene, from the camera ray (org, dir) at time01. */
vec3 media_sample_path(const struct render_job *job, const struct sampler *smp, uint32_t px, uint32_t py, vec3 org,
                       vec3 dir, float time01, uint64_t *rays, int *hit_any);

#endif
