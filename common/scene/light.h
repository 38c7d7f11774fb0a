/* Light table of a job: point lights and every emissive triangle and sphere, chosen for
 * next-event estimation in proportion to emitted power. Built once per job from the flat
 * scene; read-only while rendering. Emitters are one-sided: a triangle emits on the side
 * of its right-handed normal (counter-clockwise winding seen from the front), a sphere
 * outwards. Also answers the pdf of hitting an emitter by chance, for MIS. Emitters on
 * moving geometry (keyframes or deformation frames) are left out: their position depends
 * on the ray time, so the integrator counts them when BSDF sampling hits them. The
 * environment (envmap.h) is one more entry, LK_ENV, picked by its power through a disc
 * around the scene (pi r^2 times its integral over the sphere, as pbrt-v4 counts it),
 * but never with more than LIGHT_ENV_MAX_PICK when the scene has other lights: that power
 * grows with the scene's radius squared, while a spot or a small emitter lights the
 * surfaces near it far more than its power share says (a spot lighting a 24 x 36 m floor
 * was picked once in 86 samples, so its light came as rare bright pixels). The cap costs
 * sky-lit points at most twice the variance of always picking the sky. */
#ifndef BRUME_LIGHT_H
#define BRUME_LIGHT_H
#include <stdint.h>
#include "scene/scene.h"
#include "base/vec.h"

#define LIGHT_ENV_MAX_PICK 0.5
#define LIGHT_NONE UINT32_MAX

enum light_kind { LK_POINT, LK_TRIANGLE, LK_SPHERE, LK_ENV };

struct light_entry {
    enum light_kind kind;
    uint32_t index;     /* scene light, mesh, or sphere index */
    uint32_t prim;      /* triangle index within the mesh */
    vec3 emission;      /* radiance (area lights) or intensity (point lights) */
    float area;
    /* LK_TRIANGLE: its vertices and unit normal (emitters do not move), as
     * light_triangle_vertices gives them */
    vec3 v[3], n;
};

struct light_table {
    struct light_entry *entries;
    float *cdf;                 /* num_entries + 1, cdf[0] = 0, cdf[n] = 1 */
    float *pick_pdf;            /* per entry; one 0 when there are none (light_pick's 0) */
    uint32_t num_entries;
    int points_only;            /* every entry is a point or spot light: light_sample ignores u1, u2 */
    uint32_t num_surface;       /* entries that are emissive triangles or spheres (rays can hit them) */
    uint32_t **tri_light;       /* per mesh: per triangle entry index or LIGHT_NONE; NULL if none */
    uint32_t num_meshes;
    uint32_t *sphere_light;     /* per sphere, or NULL */
    /* The environment light (scene.env): its entry or LIGHT_NONE, and the sphere bounding
     * the scene's geometry and lights, which its samples are placed beyond and its photons
     * are aimed at (through a disc of that radius, as pbrt does for infinite lights). */
    uint32_t env_entry;
    vec3 env_center;
    float env_radius;
};

struct light_sample {
    vec3 p;             /* point on the light (position for point lights) */
    vec3 n;             /* light's normal there (zero for point lights) */
    vec3 radiance;      /* emitted radiance toward the shading point, or I / d^2 for points */
    vec3 wi;            /* unit direction from the shading point to p: (p - ref) / |p - ref|; zero when pdf is 0 */
    float pdf;          /* solid-angle pdf including the pick probability; 0 = no sample */
    int is_delta;
    uint32_t entry;     /* the light table entry picked (valid when pdf > 0) */
};

/* A spot light's falloff toward dir (from the light, any length): 0 outside the outer cone,
 * 1 inside the inner one, smoothstep in cos between; 1 for point lights. */
float light_spot_falloff(const struct light *l, vec3 dir);
/* The same for a caller that has dir's length len = v3_length(dir) (sqrtf of the squared
 * distance it took: the same bits): no square root of its own, and inline, so that the
 * march's NEE per step does not wait on one more. */
static inline float light_spot_falloff_len(const struct light *l, vec3 dir, float len)
{
    if (l->type != LIGHT_SPOT)
        return 1.0f;
    if (!(len > 0.0f))
        return 0.0f;
    float c = v3_dot(l->direction, dir) / len;
    if (c <= l->cos_outer)
        return 0.0f;
    if (c >= l->cos_inner)
        return 1.0f;
    float x = (c - l->cos_outer) / (l->cos_inner - l->cos_outer);
    return x * x * (3.0f - 2.0f * x);
}

void light_table_init(struct light_table *t, const struct scene *s);
void light_table_fini(struct light_table *t);

/* The entry whose CDF interval holds u in [0, 1) (never one of probability zero), for
 * callers that pick a light themselves (the media integrator, the photon pass). With one
 * entry (or none) it is 0 and u is not read. */
uint32_t light_pick_cdf_(const struct light_table *t, float u);
static inline uint32_t light_pick(const struct light_table *t, float u)
{
    return t->num_entries <= 1 ? 0 : light_pick_cdf_(t, u);
}

/* The uniforms light_sample reads: u_pick only with more than one entry, u1 and u2 only
 * when some entry is not a point light. Callers drawing them from a sampler skip the rest
 * (every random number is a pure function of its dimension, so skipping one moves no
 * other). */
static inline int light_sample_reads_pick(const struct light_table *t) { return t->num_entries > 1; }
static inline int light_sample_reads_point(const struct light_table *t) { return !t->points_only; }

/* light_sample's body for entry i (picked, pick_pdf > 0, out zeroed with out->entry = i)
 * when it is an area light or the environment (light.c). */
void light_sample_emitter_(const struct light_table *t, const struct scene *s, uint32_t i, vec3 ref, float u1,
                           float u2, struct light_sample *out);

/* Samples one light for shading point ref with three uniforms (see light_sample_reads_*).
 * Inline for the point lights' short path (every NEE, surface and media); area lights and
 * the environment out of line. */
static inline void light_sample(const struct light_table *t, const struct scene *s, vec3 ref, float u_pick, float u1,
                                float u2, struct light_sample *out)
{
    *out = (struct light_sample){.entry = 0};
    uint32_t i = light_pick(t, u_pick);
    float pick_pdf = t->pick_pdf[i];
    if (pick_pdf <= 0.0f)
        return;
    out->entry = i;
    const struct light_entry *e = &t->entries[i];
    if (e->kind != LK_POINT) {
        light_sample_emitter_(t, s, i, ref, u1, u2, out);
        return;
    }
    const struct light *l = &s->lights[e->index];
    vec3 d = v3_sub(l->position, ref);
    float d2 = v3_dot(d, d);
    if (!(d2 > 0.0f))
        return;
    out->p = l->position;
    float len = sqrtf(d2); /* d2 is v3_length's dot: the same bits */
    out->wi = v3_scale(d, 1.0f / len);
    out->radiance = v3_scale(e->emission, light_spot_falloff_len(l, v3_neg(d), len) / d2);
    out->pdf = pick_pdf;
    out->is_delta = 1;
}

/* A point on the emissive triangle `entry` (LK_TRIANGLE) from two uniforms, uniform by
 * area (density pick_pdf / area with the pick), and its normal: the point light_sample
 * takes, whatever the shading point; for callers that choose the light point first
 * (equiangular sampling toward an area light). */
void light_triangle_point(const struct light_table *t, uint32_t entry, float u1, float u2,
                          vec3 *p, vec3 *n);
/* The emissive triangle `entry` (LK_TRIANGLE): its vertices in the mesh's order and its
 * normal (the one light_triangle_point gives). */
void light_triangle_vertices(const struct light_table *t, uint32_t entry, vec3 v[3], vec3 *n);

/* Solid-angle pdf (pick included) that light_sample would have produced point p_light
 * with light normal n_light on emitter `entry`, seen from ref. */
float light_pdf(const struct light_table *t, const struct scene *s, uint32_t entry, vec3 ref, vec3 p_light,
                vec3 n_light);

/* The environment's radiance toward -d (d: a ray's direction that escaped the scene) and
 * the solid-angle pdf, pick included, with which light_sample would have produced it. */
vec3 light_env_radiance(const struct light_table *t, const struct scene *s, vec3 d);
float light_env_pdf(const struct light_table *t, const struct scene *s, vec3 d);

#endif
