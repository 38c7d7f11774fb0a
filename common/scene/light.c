/* Light table, light sampling and light pdfs (see light.h). Triangles are sampled
 * uniformly by area; spheres by the cone of directions they subtend (uniform by area
 * when the shading point is inside), which is what light_pdf mirrors. */
#include "scene/light.h"
#include "base/cdf.h"
#include "base/log.h"
#include "scene/envmap.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

float light_spot_falloff(const struct light *l, vec3 dir)
{
    return l->type != LIGHT_SPOT ? 1.0f : light_spot_falloff_len(l, dir, v3_length(dir));
}

static vec3 tri_vertex(const struct mesh *m, uint32_t prim, int k)
{
    const float *p = &m->positions[3 * m->indices[3 * prim + k]];
    return v3(p[0], p[1], p[2]);
}

/* In double: a bright light's power (4 pi I) can overflow float even when I does not. */
static double emitted_power(const struct light_entry *e)
{
    double le = ((double)e->emission.x + e->emission.y + e->emission.z) / 3.0;
    switch (e->kind) {
    case LK_POINT:
        return (double)e->area * le; /* area: the solid angle it emits into (4 pi, or a spot's cone) */
    case LK_TRIANGLE:
    case LK_SPHERE:
        return M_PI * (double)e->area * le;
    case LK_ENV:
        return 4.0 * M_PI * (double)e->area * le; /* area: the disc, pi r^2; le: the mean radiance */
    }
    return 0.0;
}

static void add_entry(struct light_table *t, size_t *cap, struct light_entry e)
{
    mem_grow((void **)&t->entries, cap, t->num_entries + 1, sizeof e);
    t->entries[t->num_entries++] = e;
}

/* The sphere around every vertex, sphere and light (radius at least 1e-3). */
static void scene_sphere(const struct scene *s, vec3 *center, float *radius)
{
    vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
#define GROW(p) (lo = v3(f_min(lo.x, (p).x), f_min(lo.y, (p).y), f_min(lo.z, (p).z)), \
                 hi = v3(f_max(hi.x, (p).x), f_max(hi.y, (p).y), f_max(hi.z, (p).z)))
    for (uint32_t mi = 0; mi < s->num_meshes; mi++) {
        const struct mesh *m = &s->meshes[mi];
        const float *pos = m->num_frames > 1 && m->frame_positions ? m->frame_positions : m->positions;
        size_t nv = (size_t)m->num_vertices * (m->num_frames > 1 && m->frame_positions ? m->num_frames : 1);
        for (size_t k = 0; k < nv; k++)
            GROW(v3(pos[3 * k], pos[3 * k + 1], pos[3 * k + 2]));
    }
    for (uint32_t i = 0; i < s->num_spheres; i++) {
        vec3 c = s->spheres[i].center, r = v3(s->spheres[i].radius, s->spheres[i].radius, s->spheres[i].radius);
        GROW(v3_add(c, r));
        GROW(v3_sub(c, r));
    }
    for (uint32_t i = 0; i < s->num_lights; i++)
        GROW(s->lights[i].position);
    GROW(s->camera.position);
#undef GROW
    *center = v3_scale(v3_add(lo, hi), 0.5f);
    float r = 0.5f * v3_length(v3_sub(hi, lo));
    *radius = isfinite(r) && r > 1e-3f ? r : 1e-3f;
    if (!v3_is_finite(*center))
        *center = v3(0, 0, 0);
}

void light_table_init(struct light_table *t, const struct scene *s)
{
    memset(t, 0, sizeof *t);
    size_t cap = 0;
    t->env_entry = LIGHT_NONE;
    for (uint32_t i = 0; i < s->num_lights; i++) {
        const struct light *l = &s->lights[i];
        float omega = l->type == LIGHT_SPOT ? 2.0f * (float)M_PI * (1.0f - l->cos_outer) : 4.0f * (float)M_PI;
        struct light_entry e = {.kind = LK_POINT, .index = i, .emission = l->intensity, .area = omega};
        if (!v3_is_black(e.emission))
            add_entry(t, &cap, e);
    }
    t->num_meshes = s->num_meshes;
    if (s->num_meshes)
        t->tri_light = mem_calloc(s->num_meshes, sizeof *t->tri_light);
    for (uint32_t mi = 0; mi < s->num_meshes; mi++) {
        const struct mesh *m = &s->meshes[mi];
        if (m->num_keys > 0 || m->num_frames > 1)
            continue; /* moving emitters: found by BSDF sampling only (integrator.c) */
        for (uint32_t p = 0; p < m->num_triangles; p++) {
            vec3 em = s->materials[m->material_ids[p]].emission;
            if (v3_is_black(em))
                continue;
            vec3 a = tri_vertex(m, p, 0), b = tri_vertex(m, p, 1), c = tri_vertex(m, p, 2);
            float area = 0.5f * v3_length_rescaled(v3_cross(v3_sub(b, a), v3_sub(c, a)));
            if (!(area > 0.0f))
                continue; /* degenerate: can neither be hit nor sampled */
            if (!t->tri_light[mi]) {
                t->tri_light[mi] = mem_alloc(sizeof(uint32_t) * m->num_triangles);
                for (uint32_t k = 0; k < m->num_triangles; k++)
                    t->tri_light[mi][k] = LIGHT_NONE;
            }
            t->tri_light[mi][p] = t->num_entries;
            struct light_entry e = {.kind = LK_TRIANGLE, .index = mi, .prim = p, .emission = em, .area = area,
                                     .v = {a, b, c}, .n = v3_normalize(v3_cross(v3_sub(b, a), v3_sub(c, a)))};
            add_entry(t, &cap, e);
            t->num_surface++;
        }
    }
    for (uint32_t i = 0; i < s->num_spheres; i++) {
        vec3 em = s->materials[s->spheres[i].material_id].emission;
        if (v3_is_black(em) || s->spheres[i].num_keys > 0)
            continue;
        if (!t->sphere_light) {
            t->sphere_light = mem_alloc(sizeof(uint32_t) * s->num_spheres);
            for (uint32_t k = 0; k < s->num_spheres; k++)
                t->sphere_light[k] = LIGHT_NONE;
        }
        float r = s->spheres[i].radius;
        t->sphere_light[i] = t->num_entries;
        add_entry(t, &cap, (struct light_entry){.kind = LK_SPHERE, .index = i, .emission = em, .area = 4.0f * (float)M_PI * r * r});
        t->num_surface++;
    }
    if (s->env && s->env->marg_int > 0.0f && s->env->strength > 0.0f) {
        scene_sphere(s, &t->env_center, &t->env_radius);
        t->env_entry = t->num_entries;
        float disc = (float)M_PI * t->env_radius * t->env_radius;
        add_entry(t, &cap, (struct light_entry){.kind = LK_ENV, .emission = s->env->mean, .area = disc});
    }
    if (t->num_entries == 0) {
        t->pick_pdf = mem_calloc(1, sizeof(float)); /* light_pick's 0, never sampled */
        return;
    }
    t->points_only = 1;
    for (uint32_t i = 0; i < t->num_entries; i++)
        t->points_only &= t->entries[i].kind == LK_POINT;
    /* Summed in double so the cdf of many small emitters stays monotone and ends at 1. */
    double total = 0.0, env_power = 0.0;
    for (uint32_t i = 0; i < t->num_entries; i++)
        total += emitted_power(&t->entries[i]);
    /* The environment's share is at most LIGHT_ENV_MAX_PICK when other lights exist (light.h). */
    if (t->env_entry != LIGHT_NONE && t->num_entries > 1 && total > 0.0 && isfinite(total)) {
        env_power = emitted_power(&t->entries[t->env_entry]);
        double rest = total - env_power;
        if (rest > 0.0 && env_power / total > LIGHT_ENV_MAX_PICK)
            total = rest / (1.0 - LIGHT_ENV_MAX_PICK);
        else
            env_power = 0.0;
    }
    t->cdf = mem_alloc(sizeof(float) * (t->num_entries + 1));
    t->pick_pdf = mem_alloc(sizeof(float) * t->num_entries);
    double acc = 0.0;
    t->cdf[0] = 0.0f;
    for (uint32_t i = 0; i < t->num_entries; i++) {
        double p = total > 0.0 && isfinite(total) ? emitted_power(&t->entries[i]) / total : 1.0 / t->num_entries;
        if (env_power > 0.0 && i == t->env_entry)
            p = LIGHT_ENV_MAX_PICK;
        t->pick_pdf[i] = (float)p;
        acc += p;
        t->cdf[i + 1] = (float)acc;
    }
    t->cdf[t->num_entries] = 1.0f;
}

void light_table_fini(struct light_table *t)
{
    free(t->entries);
    free(t->cdf);
    free(t->pick_pdf);
    for (uint32_t i = 0; t->tri_light && i < t->num_meshes; i++)
        free(t->tri_light[i]);
    free(t->tri_light);
    free(t->sphere_light);
    memset(t, 0, sizeof *t);
}

uint32_t light_pick_cdf_(const struct light_table *t, float u)
{
    uint32_t lo = cdf_cell(t->cdf, t->num_entries, u);
    /* Skip zero-probability entries that float rounding could land on. */
    while (lo + 1 < t->num_entries && t->pick_pdf[lo] == 0.0f)
        lo++;
    return lo;
}

/* 1 - cos(theta_max) of the cone a sphere subtends, without cancellation for far spheres. */
static float sphere_cone_one_minus_cos(float r, float dist)
{
    float sin2 = (r * r) / (dist * dist);
    float cos_max = sqrtf(f_max(0.0f, 1.0f - sin2));
    return sin2 / (1.0f + cos_max);
}

void light_triangle_vertices(const struct light_table *t, uint32_t entry, vec3 v[3], vec3 *n)
{
    const struct light_entry *e = &t->entries[entry];
    v[0] = e->v[0], v[1] = e->v[1], v[2] = e->v[2];
    *n = e->n;
}

void light_triangle_point(const struct light_table *t, uint32_t entry, float u1, float u2,
                          vec3 *p, vec3 *n)
{
    vec3 v[3];
    light_triangle_vertices(t, entry, v, n);
    vec3 a = v[0], b = v[1], c = v[2];
    float su = sqrtf(u1);
    float b0 = 1.0f - su, b1 = u2 * su;
    *p = v3_add(v3_add(v3_scale(a, b0), v3_scale(b, b1)), v3_scale(c, 1.0f - b0 - b1));
}

static void emitter_sample(const struct light_table *t, const struct scene *s, uint32_t i, vec3 ref, float u1, float u2,
                           struct light_sample *out)
{
    const struct light_entry *e = &t->entries[i];
    switch (e->kind) {
    case LK_POINT:
        return; /* light_sample's */
    case LK_TRIANGLE: {
        vec3 p, n;
        light_triangle_point(t, i, u1, u2, &p, &n);
        out->p = p;
        out->n = n;
        out->pdf = light_pdf(t, s, i, ref, p, n);
        out->radiance = out->pdf > 0.0f ? e->emission : v3(0, 0, 0);
        return;
    }
    case LK_SPHERE: {
        const struct sphere *sp = &s->spheres[e->index];
        vec3 to_c = v3_sub(sp->center, ref);
        float dc = v3_length(to_c);
        vec3 p;
        if (dc <= sp->radius * 1.0001f) {
            /* Inside (or on) the sphere: uniform by area. */
            float z = 1.0f - 2.0f * u1, r = sqrtf(f_max(0.0f, 1.0f - z * z)), sphi, cphi;
            sincos_2pi(u2, &sphi, &cphi);
            p = v3_add(sp->center, v3_scale(v3(r * cphi, r * sphi, z), sp->radius));
        } else {
            float omc = sphere_cone_one_minus_cos(sp->radius, dc);
            float one_minus_cos = u1 * omc;
            float cos_t = 1.0f - one_minus_cos;
            float sin_t = sqrtf(f_max(0.0f, one_minus_cos * (2.0f - one_minus_cos)));
            float sphi, cphi;
            sincos_2pi(u2, &sphi, &cphi);
            vec3 w = v3_scale(to_c, 1.0f / dc), tx, ty;
            v3_basis(w, &tx, &ty);
            vec3 dir = v3_add(v3_scale(w, cos_t), v3_add(v3_scale(tx, sin_t * cphi), v3_scale(ty, sin_t * sphi)));
            /* Nearest intersection of the sampled direction with the sphere. */
            float disc = sp->radius * sp->radius - dc * dc * sin_t * sin_t;
            float ds = dc * cos_t - sqrtf(f_max(0.0f, disc));
            p = v3_add(ref, v3_scale(dir, ds));
        }
        vec3 n = v3_normalize(v3_sub(p, sp->center));
        out->p = p;
        out->n = n;
        out->pdf = light_pdf(t, s, i, ref, p, n);
        out->radiance = out->pdf > 0.0f ? e->emission : v3(0, 0, 0);
        return;
    }
    case LK_ENV: {
        float pdf;
        vec3 d = envmap_sample(s->env, u1, u2, &pdf);
        if (!(pdf > 0.0f))
            return;
        /* A point beyond everything, seen from ref: the shadow ray crosses the whole scene. */
        float far = v3_length(v3_sub(ref, t->env_center)) + 2.0f * t->env_radius;
        out->p = v3_add(ref, v3_scale(d, far));
        out->n = v3_neg(d);
        out->pdf = t->pick_pdf[i] * pdf;
        out->radiance = envmap_eval(s->env, d);
        return;
    }
    }
}

void light_sample_emitter_(const struct light_table *t, const struct scene *s, uint32_t i, vec3 ref, float u1,
                           float u2, struct light_sample *out)
{
    emitter_sample(t, s, i, ref, u1, u2, out);
    if (!(out->pdf > 0.0f))
        return; /* no sample: its callers stop here */
    vec3 to = v3_sub(out->p, ref);
    out->wi = v3_scale(to, 1.0f / v3_length(to));
}

vec3 light_env_radiance(const struct light_table *t, const struct scene *s, vec3 d)
{
    (void)t;
    return s->env ? envmap_eval(s->env, d) : v3(0, 0, 0);
}

float light_env_pdf(const struct light_table *t, const struct scene *s, vec3 d)
{
    if (t->env_entry == LIGHT_NONE || !s->env)
        return 0.0f;
    return t->pick_pdf[t->env_entry] * envmap_pdf(s->env, d);
}

float light_pdf(const struct light_table *t, const struct scene *s, uint32_t entry, vec3 ref, vec3 p_light,
                vec3 n_light)
{
    if (entry >= t->num_entries)
        return 0.0f;
    const struct light_entry *e = &t->entries[entry];
    float pick_pdf = t->pick_pdf[entry];
    vec3 d = v3_sub(p_light, ref);
    float d2 = v3_dot(d, d);
    if (!(d2 > 0.0f))
        return 0.0f;
    float cos_l = -v3_dot(n_light, d) / sqrtf(d2);
    switch (e->kind) {
    case LK_POINT:
        return 0.0f; /* cannot be hit by chance */
    case LK_ENV:
        return pick_pdf * envmap_pdf(s->env, v3_scale(d, 1.0f / sqrtf(d2)));
    case LK_TRIANGLE:
        if (cos_l <= 0.0f)
            return 0.0f; /* back side emits nothing */
        return pick_pdf * d2 / (cos_l * e->area);
    case LK_SPHERE: {
        const struct sphere *sp = &s->spheres[e->index];
        float dc = v3_length(v3_sub(sp->center, ref));
        if (dc <= sp->radius * 1.0001f) {
            if (cos_l <= 0.0f)
                return 0.0f;
            return pick_pdf * d2 / (cos_l * e->area);
        }
        if (cos_l <= 0.0f)
            return 0.0f;
        return pick_pdf / (2.0f * (float)M_PI * sphere_cone_one_minus_cos(sp->radius, dc));
    }
    }
    return 0.0f;
}
