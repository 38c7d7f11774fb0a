/* The surface interaction and next-event set-up (see surface.h). Hit points are rebuilt
 * from barycentrics of the stored vertices (exact to rounding), not from o + t d, so the
 * integer-ULP ray offsets of vec.h stay acne-free at any coordinate magnitude; near the
 * origin p_err carries the scale of the triangle (surface_triangle_p_err_). */
#include "render/surface.h"
#include "scene/material.h"
#include "scene/motion.h"
#include <math.h>

/* Vertex k of a deforming mesh as a ray at time01 sees it: Embree's blend of the two
 * time steps around time01, by the same formula, so the rebuilt point lies on what was hit. */
static vec3 step_vertex(const struct accel_motion *mo, uint32_t num_vertices, uint32_t k, float time01)
{
    const float *a = &mo->steps[3 * (size_t)k];
    if (mo->num_steps <= 1)
        return v3(a[0], a[1], a[2]);
    float ft = time01 * (float)(mo->num_steps - 1), fi = floorf(ft);
    fi = fi < 0.0f ? 0.0f : (fi > (float)(mo->num_steps - 2) ? (float)(mo->num_steps - 2) : fi);
    float f = ft - fi;
    a += (size_t)fi * 3 * num_vertices;
    const float *b = a + 3 * (size_t)num_vertices;
    return v3((1.0f - f) * a[0] + f * b[0], (1.0f - f) * a[1] + f * b[1], (1.0f - f) * a[2] + f * b[2]);
}

/* How far a triangle hit may lie off the triangle (and an intersection test against it
 * may err) below half a unit of coordinate magnitude, where offset_ray_origin's fixed step
 * shrinks with |p|: a point near the origin of a triangle whose vertices lie far away has
 * the vertices' rounding, not its own. 0 at larger magnitudes, where the fixed step
 * (2^-16) and the ulp offsets already cover it. */
float surface_triangle_p_err_(uint32_t geom, uint32_t prim, const struct accel *acc, const struct accel_motion *mo,
                              float time01)
{
    const struct mesh *m = &acc->desc->meshes[geom];
    const uint32_t *idx = &m->indices[3 * prim];
    float mag = 0.0f;
    for (int k = 0; k < 3; k++) {
        vec3 v;
        if (mo && mo->num_steps > 0) {
            v = step_vertex(mo, m->num_vertices, idx[k], time01);
        } else {
            const float *a = &m->positions[3 * idx[k]];
            v = v3(a[0], a[1], a[2]);
        }
        mag = f_max(mag, v3_max_abs(v));
    }
    return f_min(mag, 0.5f) * 0x1p-20f;
}

/* The hit as a surface point at the ray's time. Still geometry: barycentrics of the
 * stored vertices (exact to rounding). Rigid motion: the same in object space, then the
 * instance transform at time01 (from Embree, so it matches what was intersected), normals
 * by its cofactor matrix. Deformation: vertices blended at time01, flat normals. */
void surface_from_hit_slow_(const struct accel *acc, const struct light_table *lt, vec3 org, vec3 dir,
                            const struct accel_hit *h, float time01, struct surface *s)
{
    const struct scene *sc = acc->desc;
    struct xform x;
    s->p_err = 0.0f;
    int moving = accel_object_xform(acc, h->geom, h->prim, time01, &x);
    if (h->geom == acc->sphere_geom && sc->num_spheres > 0) {
        const struct sphere *sp = &sc->spheres[h->prim];
        vec3 p = v3_add(org, v3_scale(dir, h->t));
        if (moving) {
            struct xform xi = motion_xform_inverse(&x);
            vec3 n = v3_normalize(v3_sub(xform_point(&xi, p), sp->center));
            s->p = xform_point(&x, v3_add(sp->center, v3_scale(n, sp->radius)));
            s->ng = s->ns = v3_normalize(motion_xform_normal(&x, n));
            s->p_err = (v3_max_abs(s->p) + v3_max_abs(sp->center) + sp->radius) * 0x1p-20f;
        } else {
            vec3 n = v3_normalize(v3_sub(p, sp->center));
            s->p = v3_add(sp->center, v3_scale(n, sp->radius)); /* re-project onto the surface */
            s->ng = s->ns = n;
            /* center + r n rounds at the scale of |center| and r, not of |p|: a floor made of
             * a huge sphere needs an offset of that size, or its shadow rays self-hit in rings. */
            s->p_err = (v3_max_abs(sp->center) + sp->radius) * 0x1p-21f;
        }
        s->material = sp->material_id;
        s->light = lt->sphere_light ? lt->sphere_light[h->prim] : LIGHT_NONE;
        return;
    }
    const struct mesh *m = &sc->meshes[h->geom];
    const uint32_t *idx = &m->indices[3 * h->prim];
    const struct accel_motion *mo = acc->mesh_motion ? &acc->mesh_motion[h->geom] : NULL;
    float w = 1.0f - h->u - h->v;
    if (mo && mo->num_steps > 0) {
        vec3 va = step_vertex(mo, m->num_vertices, idx[0], time01), vb = step_vertex(mo, m->num_vertices, idx[1], time01),
             vc = step_vertex(mo, m->num_vertices, idx[2], time01);
        s->p = v3_add(v3_add(v3_scale(va, w), v3_scale(vb, h->u)), v3_scale(vc, h->v));
        s->ng = v3_normalize(v3_cross(v3_sub(vb, va), v3_sub(vc, va)));
        s->ns = s->ng;
    } else {
        surface_triangle_still(acc, m, h, s);
    }
    if (moving) {
        s->p = xform_point(&x, s->p);
        s->ng = v3_normalize(motion_xform_normal(&x, s->ng));
        s->ns = v3_normalize(motion_xform_normal(&x, s->ns));
    }
    surface_triangle_finish(acc, lt, m, h, mo, time01, s);
}

/* dP/du of the triangle (a, b, c) with texture coordinates uv0..2: e1 dv2 - e2 dv1 over
 * the uv triangle's determinant; zero when the uv triangle has no area. */
static vec3 triangle_dpdu(vec3 a, vec3 b, vec3 c, const float *uv0, const float *uv1, const float *uv2)
{
    float du1 = uv1[0] - uv0[0], dv1 = uv1[1] - uv0[1], du2 = uv2[0] - uv0[0], dv2 = uv2[1] - uv0[1];
    float det = du1 * dv2 - du2 * dv1, scale = fmaxf(fabsf(du1 * dv2), fabsf(du2 * dv1));
    if (!(fabsf(det) > 1e-6f * scale) || !isfinite(det))
        return v3(0, 0, 0);
    vec3 e1 = v3_sub(b, a), e2 = v3_sub(c, a);
    vec3 t = v3_scale(v3_sub(v3_scale(e1, dv2), v3_scale(e2, dv1)), 1.0f / det);
    return v3_is_finite(t) ? t : v3(0, 0, 0);
}

vec3 surface_dpdu(const struct accel *acc, vec3 org, vec3 dir, const struct accel_hit *h, float time01)
{
    const struct scene *sc = acc->desc;
    struct xform x;
    int moving = accel_object_xform(acc, h->geom, h->prim, time01, &x);
    vec3 t;
    if (h->geom == acc->sphere_geom && sc->num_spheres > 0) {
        const struct sphere *sp = &sc->spheres[h->prim];
        vec3 p = v3_add(org, v3_scale(dir, h->t));
        struct xform xi;
        if (moving) {
            xi = motion_xform_inverse(&x);
            p = xform_point(&xi, p);
        }
        /* dP/du of u = 0.5 + atan2(x, z) / 2 pi: 2 pi r (z, 0, -x) / |q| in object space */
        vec3 n = v3_normalize(v3_sub(p, sp->center));
        t = v3_scale(v3(n.z, 0.0f, -n.x), 2.0f * (float)M_PI * sp->radius);
    } else {
        const struct mesh *m = &sc->meshes[h->geom];
        if (!m->uvs)
            return v3(0, 0, 0);
        const uint32_t *idx = &m->indices[3 * h->prim];
        const struct accel_motion *mo = acc->mesh_motion ? &acc->mesh_motion[h->geom] : NULL;
        vec3 v[3];
        for (int k = 0; k < 3; k++) {
            if (mo && mo->num_steps > 0) {
                v[k] = step_vertex(mo, m->num_vertices, idx[k], time01);
            } else {
                const float *a = &m->positions[3 * idx[k]];
                v[k] = v3(a[0], a[1], a[2]);
            }
        }
        t = triangle_dpdu(v[0], v[1], v[2], &m->uvs[2 * idx[0]], &m->uvs[2 * idx[1]], &m->uvs[2 * idx[2]]);
    }
    return moving ? xform_vector(&x, t) : t;
}
