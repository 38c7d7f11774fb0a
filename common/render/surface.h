/* The surface interaction: a ray's hit rebuilt as a surface point (position, normals,
 * material, emitter) at the ray's time, and next-event set-up toward one light sample.
 * It reads only the frame's geometry (accel) and light table, so everything that shades
 * a hit (path tracer, media tracking and estimators, photon tracing) sits above it and the
 * render job can use it while it is being built. */
#ifndef BRUME_SURFACE_H
#define BRUME_SURFACE_H
#include <stdint.h>
#include "render/accel.h"
#include "scene/light.h"
#include "scene/material.h"

struct surface {
    vec3 p;
    vec3 ng;            /* unit geometric normal as the geometry defines it (emission side) */
    vec3 ns;            /* unit shading normal, same side as ng */
    uint32_t material;
    uint32_t light;     /* light entry, or LIGHT_NONE */
    float p_err;        /* bound on how far p may lie off the true surface (triangles: only near the origin) */
};

/* The point and normals of hit h on triangle mesh m as stored (no time steps): barycentrics
 * of the stored vertices, the face normal, the interpolated vertex normal as ns where it
 * is usable. */
static inline void surface_triangle_still(const struct accel *acc, const struct mesh *m, const struct accel_hit *h,
                                          struct surface *s)
{
    const uint32_t *idx = &m->indices[3 * h->prim];
    float w = 1.0f - h->u - h->v;
    const float *a = &m->positions[3 * idx[0]], *b = &m->positions[3 * idx[1]], *c = &m->positions[3 * idx[2]];
    vec3 va = v3(a[0], a[1], a[2]), vb = v3(b[0], b[1], b[2]), vc = v3(c[0], c[1], c[2]);
    s->p = v3_add(v3_add(v3_scale(va, w), v3_scale(vb, h->u)), v3_scale(vc, h->v));
    s->ng = acc->face_normals[h->geom][h->prim];
    s->ns = s->ng;
    if (m->normals) {
        const float *na = &m->normals[3 * idx[0]], *nb = &m->normals[3 * idx[1]], *nc = &m->normals[3 * idx[2]];
        vec3 n = v3_add(v3_add(v3_scale(v3(na[0], na[1], na[2]), w), v3_scale(v3(nb[0], nb[1], nb[2]), h->u)),
                        v3_scale(v3(nc[0], nc[1], nc[2]), h->v));
        n = v3_normalize(n);
        if (v3_is_finite(n) && v3_dot(n, n) > 0.5f)
            s->ns = v3_dot(n, s->ng) < 0.0f ? v3_neg(n) : n;
    }
}

/* How far a triangle hit p (|p| < 0.5) may lie off the triangle (surface.c). */
float surface_triangle_p_err_(uint32_t geom, uint32_t prim, const struct accel *acc, const struct accel_motion *mo,
                              float time01);

/* A triangle hit's p_err (0 at |p| >= 0.5, where the fixed offsets cover it), material and
 * emitter entry; mo: the mesh's motion, or NULL. */
static inline void surface_triangle_finish(const struct accel *acc, const struct light_table *lt,
                                           const struct mesh *m, const struct accel_hit *h,
                                           const struct accel_motion *mo, float time01, struct surface *s)
{
    s->p_err = v3_max_abs_ge(s->p, 0.5f) ? 0.0f : surface_triangle_p_err_(h->geom, h->prim, acc, mo, time01);
    s->material = m->material_ids[h->prim];
    s->light = lt->tri_light && lt->tri_light[h->geom] ? lt->tri_light[h->geom][h->prim] : LIGHT_NONE;
}

void surface_from_hit_slow_(const struct accel *acc, const struct light_table *lt, vec3 org, vec3 dir,
                            const struct accel_hit *h, float time01, struct surface *s);

/* Hit h of the ray (org, dir) at time01 of accel acc as a surface point; lt gives the
 * emitter entry of the hit primitive. Triangles of still meshes inline (one comparison
 * when nothing moves, accel.still_tri when something does); spheres and meshes with
 * motion data in surface.c. */
static inline __attribute__((always_inline)) void surface_from_hit(const struct accel *acc,
                                                                   const struct light_table *lt, vec3 org,
                                                                   vec3 dir, const struct accel_hit *h,
                                                                   float time01, struct surface *s)
{
    if (h->geom >= acc->still_geoms && !acc->still_tri[h->geom]) {
        surface_from_hit_slow_(acc, lt, org, dir, h, time01, s);
        return;
    }
    const struct mesh *m = &acc->desc->meshes[h->geom];
    surface_triangle_still(acc, m, h, s);
    surface_triangle_finish(acc, lt, m, h, NULL, time01, s);
}

/* dP/du of the uv map at hit h of the ray (org, dir) at time01 (world space, not unit): the
 * u axis of anisotropic roughness (material_with_axis), computed only for anisotropic
 * materials. Triangles: per triangle, from its vertices as the ray sees them at time01
 * (blended time steps of a deforming mesh, the instance transform of a rigid one) and
 * their uvs, as pbrt-v4 and Cycles take the tangent; zero without uvs or where the uv
 * triangle has no area. Spheres: the longitude direction of their parametrisation
 * (u = 0.5 + atan2(x, z) / 2 pi about the object's y axis, as raydiff_sphere_uv), zero at
 * the poles. Zero means the arbitrary frame (material_frame). */
vec3 surface_dpdu(const struct accel *acc, vec3 org, vec3 dir, const struct accel_hit *h, float time01);

/* Next-event estimation toward one light point sampled with (pick, u, v) from surface point
 * p (material mat, shading normal ns and geometric normal ng on wo's side): the sample, the
 * BSDF value f toward it (cosine included) and its pdf, and the point a shadow ray aims at
 * (off an area light's surface). 0 when no light can arrive that way. Visibility is the
 * caller's: an occlusion ray (integrator.c) or transmittance (media_integrator.c). With
 * `through`, a light point behind a rough dielectric is taken too (n->transmitted: the
 * shadow ray leaves from the other side); without it only light on wo's side is sampled,
 * and the caller gives transmitted BSDF samples full weight (no MIS partner). */
struct nee_sample {
    struct light_sample ls;
    vec3 f, target;
    float bsdf_pdf;
    int transmitted;
};
static inline __attribute__((always_inline)) int nee_prepare(const struct light_table *lt, const struct scene *sc,
                                                             const struct material *mat, vec3 p, vec3 ns, vec3 ng,
                                                             vec3 wo, int front, int through, float pick, float u,
                                                             float v, struct nee_sample *n)
{
    light_sample(lt, sc, p, pick, u, v, &n->ls);
    if (!(n->ls.pdf > 0.0f) || v3_is_black(n->ls.radiance))
        return 0;
    vec3 wi = n->ls.wi;
    n->bsdf_pdf = 0.0f;
    float side = v3_dot(wi, ng);
    n->transmitted = side < 0.0f;
    int ok = side > 0.0f || (through && side < 0.0f && mat->type == MATERIAL_DIELECTRIC);
    n->f = ok ? material_eval(mat, ns, wo, wi, front, &n->bsdf_pdf) : v3(0, 0, 0);
    if (v3_is_black(n->f))
        return 0;
    const struct light_sample *ls = &n->ls;
    n->target = ls->is_delta ? ls->p : offset_ray_origin(ls->p, v3_dot(ls->n, wi) < 0.0f ? ls->n : v3_neg(ls->n));
    return 1;
}

/* Power heuristic (beta = 2) of MIS between the strategies with pdfs a (the one taken) and b. */
static inline float power_heuristic(float a, float b)
{
    float a2 = a * a, b2 = b * b;
    if (!(a2 + b2 <= 0x1.fffffep127f)) {
        /* A square overflows (a light's area pdf of 1e24 on a sphere of radius 1e12), or a
         * pdf is NaN: the ratio of the smaller to the larger instead of inf / inf. */
        if (a != a || b != b)
            return 0.0f;
        float r = a >= b ? b / a : a / b;
        r = r == r ? r : 1.0f; /* both infinite */
        return a >= b ? 1.0f / (1.0f + r * r) : r * r / (1.0f + r * r);
    }
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

#endif
