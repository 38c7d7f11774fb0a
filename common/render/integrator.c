/* Unidirectional path tracer with next-event estimation and multiple importance sampling
 * (power heuristic) between light and BSDF sampling, Russian roulette after the third
 * vertex. max_depth counts shading vertices: 1 = direct lighting only (as Embree's
 * pathtracer counts path length). Hit points are rebuilt from barycentrics and rays leave
 * surfaces with integer-ULP offsets along the geometric normal (Waechter and Binder,
 * Ray Tracing Gems ch. 6), which stays acne-free at any coordinate magnitude. */
#include "render/integrator.h"
#include "base/log.h"
#include "scene/material.h"
#include "render/media_integrator.h"
#include "scene/motion.h"
#include "scene/sampler.h"
#include "render/texshade.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

int render_job_init(struct render_job *job, const struct scene *scene, uint32_t frame, uint32_t threads,
                    char *err, size_t errlen)
{
    memset(job, 0, sizeof *job);
    job->scene = scene;
    job->frame = frame;
    if (accel_build(&job->accel, scene, frame, threads, err, errlen) != 0)
        return -1;
    light_table_build(&job->lights, scene);
    /* Geometric normals once per job rather than a cross product and a square root per hit. */
    job->face_normals = mem_calloc(scene->num_meshes ? scene->num_meshes : 1, sizeof *job->face_normals);
    for (uint32_t i = 0; i < scene->num_meshes; i++) {
        const struct mesh *m = &scene->meshes[i];
        job->face_normals[i] = mem_alloc(sizeof(vec3) * (m->num_triangles ? m->num_triangles : 1));
        for (uint32_t t = 0; t < m->num_triangles; t++) {
            const float *a = &m->positions[3 * m->indices[3 * t]], *b = &m->positions[3 * m->indices[3 * t + 1]],
                        *c = &m->positions[3 * m->indices[3 * t + 2]];
            vec3 va = v3(a[0], a[1], a[2]);
            job->face_normals[i][t] = v3_normalize(v3_cross(v3_sub(v3(b[0], b[1], b[2]), va), v3_sub(v3(c[0], c[1], c[2]), va)));
        }
    }
    camera_init(&job->camera, &scene->camera, scene->settings.width, scene->settings.height);
    camera_set_scene_motion(&job->camera, job->accel.has_motion);
    if (scene->media)
        job->media = media_job_new(job);
    job->mips = texshade_build(scene, &job->textured);
    return 0;
}

int nee_prepare(const struct render_job *job, const struct material *mat, vec3 p, vec3 ns, vec3 ng, vec3 wo,
                float pick, float u, float v, struct nee_sample *n)
{
    light_sample(&job->lights, job->scene, p, pick, u, v, &n->ls);
    if (!(n->ls.pdf > 0.0f) || v3_is_black(n->ls.radiance))
        return 0;
    vec3 to = v3_sub(n->ls.p, p);
    vec3 wi = v3_scale(to, 1.0f / v3_length(to));
    n->bsdf_pdf = 0.0f;
    n->f = v3_dot(wi, ng) > 0.0f ? material_eval(mat, ns, wo, wi, &n->bsdf_pdf) : v3(0, 0, 0);
    if (v3_is_black(n->f))
        return 0;
    const struct light_sample *ls = &n->ls;
    n->target = ls->is_delta ? ls->p : offset_ray_origin(ls->p, v3_dot(ls->n, wi) < 0.0f ? ls->n : v3_neg(ls->n));
    return 1;
}

int render_job_reframe(struct render_job *job, uint32_t frame, uint32_t threads, char *err, size_t errlen)
{
    const struct scene *scene = job->scene;
    accel_free(&job->accel);
    media_job_free(&job->media);
    job->frame = frame;
    if (accel_build(&job->accel, scene, frame, threads, err, errlen) != 0) {
        render_job_free(job);
        return -1;
    }
    camera_init(&job->camera, &scene->camera, scene->settings.width, scene->settings.height);
    camera_set_scene_motion(&job->camera, job->accel.has_motion);
    if (scene->media)
        job->media = media_job_new(job);
    return 0;
}

void render_job_free(struct render_job *job)
{
    for (uint32_t i = 0; job->face_normals && i < job->scene->num_meshes; i++)
        free(job->face_normals[i]);
    free(job->face_normals);
    texshade_free(job->mips, job->scene);
    accel_free(&job->accel);
    light_table_free(&job->lights);
    media_job_free(&job->media);
    memset(job, 0, sizeof *job);
}

struct surface {
    vec3 p;
    vec3 ng;            /* unit geometric normal as the geometry defines it (emission side) */
    vec3 ns;            /* unit shading normal, same side as ng */
    uint32_t material;
    uint32_t light;     /* light entry, or LIGHT_NONE */
    float p_err;        /* bound on how far p may lie off the true surface; 0 for triangles */
};

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

/* The hit as a surface point at the ray's time. Still geometry: barycentrics of the
 * stored vertices (exact to rounding). Rigid motion: the same in object space, then the
 * instance transform at time01 (from Embree, so it matches what was intersected), normals
 * by its cofactor matrix. Deformation: vertices blended at time01, flat normals. */
static void surface_from_hit(const struct render_job *job, vec3 org, vec3 dir, const struct accel_hit *h,
                             float time01, struct surface *s)
{
    const struct scene *sc = job->scene;
    struct xform x;
    s->p_err = 0.0f;
    int moving = accel_object_xform(&job->accel, h->geom, h->prim, time01, &x);
    if (h->geom == job->accel.sphere_geom && sc->num_spheres > 0) {
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
        s->light = job->lights.sphere_light ? job->lights.sphere_light[h->prim] : LIGHT_NONE;
        return;
    }
    const struct mesh *m = &sc->meshes[h->geom];
    const uint32_t *idx = &m->indices[3 * h->prim];
    const struct accel_motion *mo = job->accel.mesh_motion ? &job->accel.mesh_motion[h->geom] : NULL;
    float w = 1.0f - h->u - h->v;
    if (mo && mo->num_steps > 0) {
        vec3 va = step_vertex(mo, m->num_vertices, idx[0], time01), vb = step_vertex(mo, m->num_vertices, idx[1], time01),
             vc = step_vertex(mo, m->num_vertices, idx[2], time01);
        s->p = v3_add(v3_add(v3_scale(va, w), v3_scale(vb, h->u)), v3_scale(vc, h->v));
        s->ng = v3_normalize(v3_cross(v3_sub(vb, va), v3_sub(vc, va)));
        s->ns = s->ng;
    } else {
        const float *a = &m->positions[3 * idx[0]], *b = &m->positions[3 * idx[1]], *c = &m->positions[3 * idx[2]];
        vec3 va = v3(a[0], a[1], a[2]), vb = v3(b[0], b[1], b[2]), vc = v3(c[0], c[1], c[2]);
        s->p = v3_add(v3_add(v3_scale(va, w), v3_scale(vb, h->u)), v3_scale(vc, h->v));
        s->ng = job->face_normals[h->geom][h->prim];
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
    if (moving) {
        s->p = xform_point(&x, s->p);
        s->ng = v3_normalize(motion_xform_normal(&x, s->ng));
        s->ns = v3_normalize(motion_xform_normal(&x, s->ns));
    }
    s->material = m->material_ids[h->prim];
    s->light = job->lights.tri_light && job->lights.tri_light[h->geom] ? job->lights.tri_light[h->geom][h->prim]
                                                                        : LIGHT_NONE;
}

static float power_heuristic(float a, float b)
{
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

/* Radiance a front-facing emitter sends back along -dir. */
static vec3 emitted(const struct render_job *job, const struct surface *s, vec3 dir)
{
    if (v3_dot(s->ng, dir) >= 0.0f)
        return v3(0, 0, 0); /* one-sided emitters: seen from behind */
    return job->scene->materials[s->material].emission;
}

static vec3 sample_path(const struct render_job *job, uint32_t px, uint32_t py, struct sampler smp, uint64_t *rays,
                        int *hit_any)
{
    const struct scene *sc = job->scene;
    const struct render_settings *rs = &sc->settings;
    /* Pixel jitter, lens and shutter time; time01 is the ray's time in [0, 1] across the
     * shutter (0 when nothing needs time), for motion-blurred geometry. */
    struct camera_sample cs;
    camera_generate(&job->camera, &smp, job->frame, px, py, &cs);
    float time01 = cs.time01;
    vec3 org = cs.o, dir = cs.d;
    if (job->media)
        return media_sample_path(job, &smp, px, py, org, dir, time01, rays, hit_any);
    struct raydiff rd;          /* texture footprints, only when a material has a texture */
    if (job->textured)
        texshade_camera(job, &cs, &smp, &rd);

    vec3 L = v3(0, 0, 0), beta = v3(1, 1, 1);
    float prev_pdf = 0.0f;      /* solid-angle pdf of the BSDF sample that produced dir */
    vec3 prev_p = org;
    int prev_delta = 1;         /* camera rays count as specular: no MIS on what they hit */
    *hit_any = 0;
    for (uint32_t vertex = 1;; vertex++) {
        struct accel_hit h;
        (*rays)++;
        if (!accel_intersect(&job->accel, org, dir, INFINITY, time01, &h))
            break;
        if (vertex == 1)
            *hit_any = 1;
        struct surface s;
        surface_from_hit(job, org, dir, &h, time01, &s);

        /* Emitters the light table cannot sample (on moving geometry) and emitters seen
         * after a delta bounce are found only this way: full weight, no MIS. */
        /* Only emitters in the light table, or any surface when moving emitters exist. */
        if (s.light != LIGHT_NONE || job->accel.has_motion) {
            vec3 le = emitted(job, &s, dir);
            if (!v3_is_black(le)) {
                float w = 1.0f;
                if (!prev_delta && s.light != LIGHT_NONE) {
                    float lp = light_pdf(&job->lights, sc, s.light, prev_p, s.p, s.ng);
                    w = power_heuristic(prev_pdf, lp);
                }
                L = v3_add(L, v3_mul(beta, v3_scale(le, w)));
            }
        }
        if (vertex > rs->max_depth)
            break;

        const struct material *mat = &sc->materials[s.material];
        struct material tex_mat;
        struct raydiff_hit dh;
        if (job->textured) {
            texshade_hit(job, org, dir, &h, time01, &rd, &dh);
            mat = texshade_material(job, mat, &dh, &tex_mat);
        }
        vec3 wo = v3_neg(dir);
        /* Shade on the side the ray came from: surfaces are two-sided for reflection;
         * front (wo outside) tells a dielectric which index is on which side. */
        int front = v3_dot(s.ng, wo) >= 0.0f;
        vec3 ng = front ? s.ng : v3_neg(s.ng);
        vec3 ns = v3_dot(s.ns, ng) < 0.0f ? v3_neg(s.ns) : s.ns;
        if (job->textured)
            ns = texshade_bump(sc, job->mips, mat, &dh, ng, ns);
        vec3 p_off = offset_ray_origin(v3_add(s.p, v3_scale(ng, s.p_err)), ng);
        uint32_t d0 = sampler_bounce_dim(vertex - 1, 0);

        /* Next-event estimation; a delta BSDF is zero toward any sampled light point. */
        if (job->lights.num_entries > 0 && !material_is_delta(mat)) {
            float lu, lv;
            sampler_get_2d(&smp, d0 + DIM_LIGHT_U, &lu, &lv);
            struct nee_sample n;
            if (nee_prepare(job, mat, s.p, ns, ng, wo, sampler_get(&smp, d0 + DIM_LIGHT_PICK), lu, lv, &n)) {
                (*rays)++;
                if (!accel_occluded(&job->accel, p_off, v3_sub(n.target, p_off), 1.0f - 0x1p-12f, time01)) {
                    float w = n.ls.is_delta ? 1.0f : power_heuristic(n.ls.pdf, n.bsdf_pdf);
                    L = v3_add(L, v3_mul(beta, v3_scale(v3_mul(n.f, n.ls.radiance), w / n.ls.pdf)));
                }
            }
        }

        /* BSDF sampling for the next vertex (also the MIS partner of the NEE above). */
        struct bsdf_sample bs;
        float bu, bv;
        sampler_get_2d(&smp, d0 + DIM_BSDF_U, &bu, &bv);
        material_sample(mat, ns, wo, front, bu, bv, &bs);
        /* A direction on the wrong side of the true surface (shading normals) ends the path. */
        float side = v3_dot(bs.wi, ng);
        if (bs.pdf <= 0.0f || (bs.transmitted ? side >= 0.0f : side <= 0.0f))
            break;
        beta = v3_mul(beta, bs.weight);
        if (vertex >= 3) {
            float q = 1.0f - v3_max_component(beta);
            q = q > 0.05f ? q : 0.05f;
            if (sampler_get(&smp, d0 + DIM_RR) < q)
                break;
            beta = v3_scale(beta, 1.0f / (1.0f - q));
        }
        if (v3_is_black(beta))
            break;
        if (job->textured)
            texshade_scatter(&rd, mat, &bs, front, dir, ns, &dh);
        prev_pdf = bs.pdf;
        prev_p = s.p;
        prev_delta = bs.is_delta;
        /* A refracted ray leaves from the other side of the surface. */
        org = bs.transmitted ? offset_ray_origin(v3_sub(s.p, v3_scale(ng, s.p_err)), v3_neg(ng)) : p_off;
        dir = bs.wi;
    }
    return L;
}

vec3 integrator_sample(const struct render_job *job, uint32_t px, uint32_t py, uint32_t sample_index,
                       uint64_t *rays, int *hit_any)
{
    const struct render_settings *rs = &job->scene->settings;
    struct sampler smp = sampler_start_type(rs->sampler, rs->seed, job->frame, (uint64_t)py * rs->width + px,
                                            sample_index, rs->spp);
    return sample_path(job, px, py, smp, rays, hit_any);
}

void integrator_render_tile(const struct render_job *job, uint32_t x0, uint32_t y0, uint32_t w, uint32_t h,
                            float *pixels, struct tile_stats *stats)
{
    const struct render_settings *rs = &job->scene->settings;
    const uint32_t spp = rs->spp;
    memset(stats, 0, sizeof *stats);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            double sum[3] = {0, 0, 0}, sum2[3] = {0, 0, 0}, lum_sum = 0.0, lum_sum2 = 0.0, cover = 0.0;
            uint32_t n = 0;
            /* The pixel's sampler set-up and seeds are shared by its samples (same values
             * as integrator_sample, a fraction of the cost). */
            struct sampler_pixel sp;
            sampler_pixel_init(&sp, rs->sampler, rs->seed, job->frame, (uint64_t)(y0 + y) * rs->width + (x0 + x),
                               spp);
            for (uint32_t si = 0; si < spp; si++) {
                int hit_any;
                vec3 l = sample_path(job, x0 + x, y0 + y, sampler_start_pixel(&sp, si), &stats->rays, &hit_any);
                stats->samples++;
                if (!v3_is_finite(l)) {
                    stats->nan_samples++;
                    continue;
                }
                double c[3] = {l.x, l.y, l.z};
                for (int k = 0; k < 3; k++) {
                    sum[k] += c[k];
                    sum2[k] += c[k] * c[k];
                }
                double lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
                lum_sum += lum;
                lum_sum2 += lum * lum;
                cover += hit_any;
                n++;
            }
            float *px = &pixels[((size_t)y * w + x) * TILE_NUM_CHANNELS];
            double mean[3], var_mean[3];
            for (int k = 0; k < 3; k++) {
                mean[k] = n ? sum[k] / n : 0.0;
                /* Variance of the mean from the sample variance (unbiased, n-1). */
                double var = n > 1 ? (sum2[k] - n * mean[k] * mean[k]) / (n - 1) : 0.0;
                var_mean[k] = n > 1 ? fmax(0.0, var) / n : 0.0;
                px[CH_R + k] = (float)mean[k];
                px[CH_VAR_R + k] = (float)var_mean[k];
            }
            px[CH_A] = n ? (float)(cover / n) : 0.0f;
            /* Relative standard error of the pixel's luminance, from the luminance of each
             * sample (so correlation between channels is accounted for). */
            double lum_mean = n ? lum_sum / n : 0.0;
            if (lum_mean > 0.0 && n > 1) {
                double var_lum = fmax(0.0, (lum_sum2 - n * lum_mean * lum_mean) / (n - 1)) / n;
                stats->sum_rel_stderr += sqrt(var_lum) / lum_mean;
                stats->rel_stderr_pixels++;
            }
        }
}

void integrator_media_surface(const struct render_job *job, vec3 org, vec3 dir, const struct accel_hit *h,
                              float time01, struct media_surface *out)
{
    struct surface s;
    surface_from_hit(job, org, dir, h, time01, &s);
    out->p = s.p;
    out->ng = s.ng;
    out->ns = s.ns;
    out->material = s.material;
    out->light = s.light;
    out->p_err = s.p_err;
}
