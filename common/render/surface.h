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

/* Hit h of the ray (org, dir) at time01 of accel acc as a surface point; lt gives the
 * emitter entry of the hit primitive. */
void surface_from_hit(const struct accel *acc, const struct light_table *lt, vec3 org, vec3 dir,
                      const struct accel_hit *h, float time01, struct surface *s);

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
static inline int nee_prepare(const struct light_table *lt, const struct scene *sc, const struct material *mat,
                              vec3 p, vec3 ns, vec3 ng, vec3 wo, int front, int through, float pick, float u, float v,
                              struct nee_sample *n)
{
    if (lt->points_only) /* the same sample, inline */
        light_sample_point(lt, sc, lt->num_entries == 1 ? 0 : light_pick(lt, pick), p, &n->ls);
    else
        light_sample(lt, sc, p, pick, u, v, &n->ls);
    if (!(n->ls.pdf > 0.0f) || v3_is_black(n->ls.radiance))
        return 0;
    vec3 to = v3_sub(n->ls.p, p);
    vec3 wi = v3_scale(to, 1.0f / v3_length(to));
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
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

#endif
