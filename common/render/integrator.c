/* Unidirectional path tracer with next-event estimation and multiple importance sampling
 * (power heuristic) between light and BSDF sampling, Russian roulette after the third
 * vertex. max_depth counts shading vertices: 1 = direct lighting only (as Embree's
 * pathtracer counts path length). Rays leave surfaces (surface.c) with integer-ULP offsets
 * along the geometric normal (Waechter and Binder, Ray Tracing Gems ch. 6). */
#include "render/integrator.h"
#include "base/log.h"
#include "render/aov.h"
#include "render/media_integrator.h"
#include "render/motion_vis.h"
#include "render/packet.h"
#include "render/surface.h"
#include "render/texshade.h"
#include "scene/material.h"
#include "scene/sampler.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Radiance a front-facing emitter sends back along -dir. */
static vec3 emitted(const struct render_job *job, const struct surface *s, vec3 dir)
{
    if (v3_dot(s->ng, dir) >= 0.0f)
        return v3(0, 0, 0); /* one-sided emitters: seen from behind */
    return job->scene->materials[s->material].emission;
}

/* The offset origin of a ray leaving s into the side opposite ng. */
static vec3 behind(const struct surface *s, vec3 ng)
{
    return offset_ray_origin(v3_sub(s->p, v3_scale(ng, s->p_err)), v3_neg(ng));
}

/* The AOVs of the first hit h of the camera ray (org, dir) at surface s, shading normal ns
 * on the ray's side. */
static void aov_first_hit(const struct render_job *job, const struct accel_hit *h, const struct surface *s, vec3 ns,
                          struct aov_sample *aov)
{
    const struct scene *sc = job->scene;
    aov->z = h->t; /* camera rays have unit directions */
    aov->n = ns;
    aov->p = v3((float)((double)s->p.x + sc->origin[0]), (float)((double)s->p.y + sc->origin[1]),
                (float)((double)s->p.z + sc->origin[2]));
    aov->id_object = (float)aov_object_id(sc, h->geom, job->accel.sphere_geom, h->prim);
    aov->id_material = (float)s->material;
}

/* AOVs in media scenes: the first surface along the camera ray, media ignored, shaded as
 * the media integrator shades its first hit (texshade_surface) (textures, bump and normal maps; rd: the camera
 * ray's differentials when the job is textured), the albedo of a non-specular first hit
 * (docs/scene-format.md). Returns whether the ray hit, and the hit in *h, for the path to
 * start from. */
static int aov_trace(const struct render_job *job, vec3 org, vec3 dir, float time01, const struct raydiff *rd,
                     struct aov_sample *aov, struct accel_hit *h)
{
    if (!accel_intersect(&job->accel, org, dir, INFINITY, time01, h))
        return 0;
    struct surface s;
    surface_from_hit(&job->accel, &job->lights, org, dir, h, time01, &s);
    struct material tex_mat;
    const struct material *mat =
        texshade_surface(job, org, dir, h, time01, rd, &s, &job->scene->materials[s.material], &tex_mat, NULL);
    aov_first_hit(job, h, &s, v3_dot(s.ns, dir) > 0.0f ? v3_neg(s.ns) : s.ns, aov);
    if (!material_is_delta(mat))
        aov->albedo = aov_material_albedo(mat);
    return 1;
}

/* Next-event estimation's light sample at the vertex whose dimensions start at d0, drawing
 * only the dimensions light_sample reads (light_sample_reads_pick, _point). */
static inline __attribute__((always_inline)) int nee_prepare_smp(const struct render_job *job, const struct material *mat, vec3 p, vec3 ns, vec3 ng,
                                  vec3 wo, int front, const struct sampler *smp, uint32_t d0, struct nee_sample *n)
{
    const struct light_table *lt = &job->lights;
    float pick = light_sample_reads_pick(lt) ? sampler_get(smp, d0 + DIM_LIGHT_PICK) : 0.0f, lu = 0.0f, lv = 0.0f;
    if (light_sample_reads_point(lt))
        sampler_get_2d(smp, d0 + DIM_LIGHT_U, &lu, &lv);
    return nee_prepare(lt, job->scene, mat, p, ns, ng, wo, front, 1, pick, lu, lv, n);
}

/* One camera path between its vertices (no media): what the next vertex needs, and the
 * shadow ray a vertex leaves pending (its contribution added once its visibility is
 * known, before the next vertex adds anything, so L sums in the same order whether shadow
 * rays go one by one or in a packet). */
struct path {
    struct sampler smp;
    vec3 L, beta, org, dir, prev_p;
    float prev_pdf;             /* solid-angle pdf of the BSDF sample that produced dir */
    float time01;               /* the ray's time in [0, 1] across the shutter */
    int prev_delta;             /* camera rays count as specular: no MIS on what they hit */
    uint32_t vertex;            /* the vertex the next hit makes (1: the camera ray's) */
    int hit_any;
    struct aov_sample *aov;     /* NULL once the AOVs are set (or when there are none) */
    struct raydiff rd;          /* texture footprints, only when a material has a texture */
    int shadow;                 /* a shadow ray (so, sd) is pending, carrying sl */
    vec3 so, sd, sl;
};

static void path_start(const struct render_job *job, struct path *p, struct sampler smp,
                       const struct camera_sample *cs, struct aov_sample *aov)
{
    p->smp = smp;
    p->L = v3(0, 0, 0);
    p->beta = v3(1, 1, 1);
    p->org = p->prev_p = cs->o;
    p->dir = cs->d;
    p->prev_pdf = 0.0f;
    p->time01 = cs->time01;
    p->prev_delta = 1;
    p->vertex = 1;
    p->hit_any = 0;
    p->aov = aov;
    p->shadow = 0;
    if (job->textured)
        texshade_camera(job, cs, &p->smp, &p->rd);
}

/* The vertex the path's ray (org, dir) makes at hit h (found: whether it hit): emission,
 * next-event set-up (p->shadow with the shadow ray when a light sample needs one) and the
 * BSDF sample that gives the next ray. Returns whether the path goes on. Always inline:
 * the single-ray loop and the packet's first vertices share it. */
static inline __attribute__((always_inline)) int path_vertex(const struct render_job *job, struct path *p, int found,
                                                             const struct accel_hit *h, uint64_t *rays)
{
    const struct scene *sc = job->scene;
    const uint32_t vertex = p->vertex;
    vec3 org = p->org, dir = p->dir;
    p->shadow = 0;
    if (!found) {
        /* Escaped: the environment light, weighted against its light samples. */
        if (sc->env) {
            vec3 le = light_env_radiance(&job->lights, sc, dir);
            float w = p->prev_delta ? 1.0f : power_heuristic(p->prev_pdf, light_env_pdf(&job->lights, sc, dir));
            p->L = v3_add(p->L, v3_mul(p->beta, v3_scale(le, w)));
        }
        return 0;
    }
    if (vertex == 1)
        p->hit_any = 1;
    struct surface s;
    surface_from_hit(&job->accel, &job->lights, org, dir, h, p->time01, &s);

    /* Emitters the light table cannot sample (on moving geometry) and emitters seen
     * after a delta bounce are found only this way: full weight, no MIS. */
    /* Only emitters in the light table, or any surface when moving emitters exist. */
    if (s.light != LIGHT_NONE || job->accel.has_motion) {
        vec3 le = emitted(job, &s, dir);
        if (!v3_is_black(le)) {
            float w = 1.0f;
            if (!p->prev_delta && s.light != LIGHT_NONE) {
                float lp = light_pdf(&job->lights, sc, s.light, p->prev_p, s.p, s.ng);
                w = power_heuristic(p->prev_pdf, lp);
            }
            p->L = v3_add(p->L, v3_mul(p->beta, v3_scale(le, w)));
        }
    }
    if (vertex > sc->settings.max_depth)
        return 0;

    const struct material *mat = &sc->materials[s.material];
    struct material tex_mat;
    struct raydiff_hit dh;
    if (job->textured) {
        texshade_hit(job, org, dir, h, p->time01, &p->rd, &dh);
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
    if (material_is_anisotropic(mat)) /* the roughness axes follow the uv map */
        mat = material_with_axis(mat, surface_dpdu(&job->accel, org, dir, h, p->time01), &tex_mat);
    if (p->aov) {
        if (vertex == 1)
            aov_first_hit(job, h, &s, ns, p->aov);
        if (!material_is_delta(mat)) { /* the first non-specular hit: albedo, then no more AOVs */
            p->aov->albedo = v3_mul(p->beta, aov_material_albedo(mat));
            p->aov = NULL;
        }
    }
    vec3 p_off = offset_ray_origin(v3_add(s.p, v3_scale(ng, s.p_err)), ng);
    uint32_t d0 = sampler_bounce_dim(vertex - 1, 0);

    /* Next-event estimation; a delta BSDF is zero toward any sampled light point. */
    if (job->lights.num_entries > 0 && !material_is_delta(mat)) {
        struct nee_sample n;
        if (nee_prepare_smp(job, mat, s.p, ns, ng, wo, front, &p->smp, d0, &n)) {
            (*rays)++;
            p->shadow = 1;
            p->so = n.transmitted ? behind(&s, ng) : p_off;
            p->sd = v3_sub(n.target, p->so);
            float w = n.ls.is_delta ? 1.0f : power_heuristic(n.ls.pdf, n.bsdf_pdf);
            p->sl = v3_mul(p->beta, v3_scale(v3_mul(n.f, n.ls.radiance), w / n.ls.pdf));
        }
    }

    /* The last vertex's next ray could only find light by hitting an emitter or missing
     * into the environment: without either, it is not traced (the same pixels at a given
     * spp, fewer rays; every random number is a pure function of its dimension, so none
     * moves; adaptive rounds, which count rays as cost, may split their passes otherwise). */
    if (vertex == sc->settings.max_depth && !job->rays_find_light)
        return 0;
    /* BSDF sampling for the next vertex (also the MIS partner of the NEE above). */
    struct bsdf_sample bs;
    float bu, bv;
    sampler_get_2d(&p->smp, d0 + DIM_BSDF_U, &bu, &bv);
    material_sample(mat, ns, wo, front, bu, bv, &bs);
    /* A direction on the wrong side of the true surface (shading normals) ends the path. */
    float side = v3_dot(bs.wi, ng);
    if (bs.pdf <= 0.0f || (bs.transmitted ? side >= 0.0f : side <= 0.0f))
        return 0;
    vec3 beta = v3_mul(p->beta, bs.weight);
    if (vertex >= 3) {
        float q = 1.0f - v3_max_component(beta);
        q = q > 0.05f ? q : 0.05f;
        if (sampler_get(&p->smp, d0 + DIM_RR) < q)
            return 0;
        beta = v3_scale(beta, 1.0f / (1.0f - q));
    }
    p->beta = beta;
    if (v3_is_black(beta))
        return 0;
    if (job->textured)
        texshade_scatter(&p->rd, mat, &bs, front, dir, ns, &dh);
    p->prev_pdf = bs.pdf;
    p->prev_p = s.p;
    p->prev_delta = bs.is_delta;
    /* A refracted ray leaves from the other side of the surface. */
    p->org = bs.transmitted ? behind(&s, ng) : p_off;
    p->dir = bs.wi;
    p->vertex = vertex + 1;
    return 1;
}

/* The pending shadow ray's contribution, given whether it was blocked. */
static inline void path_shadow_done(struct path *p, int occluded)
{
    if (p->shadow && !occluded)
        p->L = v3_add(p->L, p->sl);
    p->shadow = 0;
}

/* The rest of the path from its current ray, one ray at a time. */
static void path_run(const struct render_job *job, struct path *p, uint64_t *rays)
{
    for (;;) {
        struct accel_hit h;
        (*rays)++;
        int found = accel_intersect(&job->accel, p->org, p->dir, INFINITY, p->time01, &h);
        int more = path_vertex(job, p, found, &h, rays);
        if (p->shadow)
            path_shadow_done(p, accel_occluded(&job->accel, p->so, p->sd, 1.0f - 0x1p-12f, p->time01));
        if (!more)
            return;
    }
}

/* The radiance along camera ray cs; aov (NULL when the frame has no AOVs) gets its AOVs,
 * set to a miss by the caller. */
static vec3 camera_path(const struct render_job *job, uint32_t pass, uint32_t px, uint32_t py, struct sampler smp,
                        struct camera_sample cs, uint64_t *rays, int *hit_any, struct aov_sample *aov)
{
    if (job->media) {
        struct raydiff rd; /* texture footprints, only when a material has a texture */
        if (job->textured)
            texshade_camera(job, &cs, &smp, &rd);
        struct accel_hit h0;
        int found0 = aov ? aov_trace(job, cs.o, cs.d, cs.time01, job->textured ? &rd : NULL, aov, &h0) : 0;
        const uint32_t k = job->direct_samples;
        vec3 direct;
        vec3 L = media_sample_path_pass(job, pass, &smp, px, py, cs.o, cs.d, cs.time01, aov ? &h0 : NULL, found0,
                                        job->textured ? &rd : NULL, k > 1 ? &direct : NULL, rays, hit_any);
        if (k > 1) {
            /* The light seen straight from the camera, averaged over k rays: this one and
             * k - 1 more with the pixel jitter shifted by the R2 lattice (job->direct_shift),
             * each uniform over the pixel, so the mean is unbiased and its rays stratified. */
            for (uint32_t i = 1; i < k; i++) {
                struct camera_sample c2;
                camera_generate_shifted(&job->camera, &smp, job->frame, px, py, &cs, job->direct_shift[i][0],
                                        job->direct_shift[i][1], &c2);
                direct = v3_add(direct, media_direct_light(job, pass, c2.o, c2.d, c2.time01, rays));
            }
            L = v3_add(L, v3_scale(direct, 1.0f / (float)k));
        }
        return L;
    }
    struct path p;
    path_start(job, &p, smp, &cs, aov);
    path_run(job, &p, rays);
    *hit_any = p.hit_any;
    return p.L;
}

/* One camera sample's radiance: pixel jitter, lens and shutter time. With analytic motion
 * blur the ray's pixel and lens point stay and the shutter is cut where the visible
 * object changes; each part is shaded at a time inside it, weighted by its share of the
 * shutter curve (motion_vis.h). *cover gets the share of the sample that hit something (0
 * or 1 with one time). With parts, aov gets their AOVs weighted the same way (N, albedo, P),
 * and Z with the ids of the nearest part's hit, as a pixel folds its samples (aov.h). */
static vec3 sample_path(const struct render_job *job, uint32_t pass, uint32_t px, uint32_t py, struct sampler smp,
                        uint64_t *rays, double *cover, struct aov_sample *aov)
{
    struct camera_sample cs;
    int hit;
    vec3 L;
    camera_generate(&job->camera, &smp, job->frame, px, py, &cs);
    struct mv_strata st;
    if (!job->motion_vis ||
        motion_vis_strata(job->motion_vis, &job->camera, &cs, sampler_get(&smp, DIM_TIME), &st) <= 1) {
        L = camera_path(job, pass, px, py, smp, cs, rays, &hit, aov);
        *cover = hit;
        return L;
    }
    L = v3(0, 0, 0);
    *cover = 0.0;
    for (uint32_t k = 0; k < st.n; k++) {
        struct camera_sample ck = cs;
        struct aov_sample ak;
        if (aov)
            aov_sample_miss(&ak);
        ck.time01 = st.time01[k];
        vec3 l = camera_path(job, pass, px, py, smp, ck, rays, &hit, aov ? &ak : NULL);
        const float w = (float)st.weight[k];
        L = v3_add(L, v3_scale(l, w));
        *cover += st.weight[k] * hit;
        if (aov) {
            /* aov arrives set to a miss: zero vectors, Z +inf, ids -1. */
            aov->n = v3_add(aov->n, v3_scale(ak.n, w));
            aov->albedo = v3_add(aov->albedo, v3_scale(ak.albedo, w));
            aov->p = v3_add(aov->p, v3_scale(ak.p, w));
            if (ak.z < aov->z) {
                aov->z = ak.z;
                aov->id_object = ak.id_object;
                aov->id_material = ak.id_material;
            }
        }
    }
    return L;
}

/* The samples of one block of a pixel: up to ACCEL_PACKET consecutive samples, rendered
 * together (radiance, coverage and AOVs per sample, in sample order). */
struct sample_block {
    vec3 L[ACCEL_PACKET];
    double cover[ACCEL_PACKET];
    struct aov_sample aov[ACCEL_PACKET];
};

/* Samples [s0, s0 + n) of pixel (px, py), n <= ACCEL_PACKET, sp set up for the pixel's
 * pass; aovs: whether to fill b->aov. Where the job takes packets (decided when its frame
 * is set up, render_job.c), the camera rays go as one packet (packet.h), each path's first
 * vertex is made, their shadow rays go as one packet too, and then each path goes on alone;
 * every shadow ray's contribution is added before the path's next vertex, so the pixels
 * are those of single rays bit for bit. */
static void render_block(const struct render_job *job, struct sampler_pixel *sp, uint32_t pass, uint32_t px,
                         uint32_t py, uint32_t s0, uint32_t n, int aovs, struct sample_block *b, uint64_t *rays)
{
    for (uint32_t k = 0; aovs && k < n; k++)
        aov_sample_miss(&b->aov[k]);
    if (!job->packets) {
        for (uint32_t k = 0; k < n; k++)
            b->L[k] = sample_path(job, pass, px, py, sampler_start_pixel(sp, s0 + k), rays, &b->cover[k],
                                  aovs ? &b->aov[k] : NULL);
        return;
    }
    struct camera_packet cp;
    camera_packet_trace(job, sp, px, py, s0, n, &cp);
    struct path p[ACCEL_PACKET];
    int more[ACCEL_PACKET], blocked[ACCEL_PACKET];
    vec3 so[ACCEL_PACKET], sd[ACCEL_PACKET];
    float time01[ACCEL_PACKET];
    uint32_t slot[ACCEL_PACKET], ns = 0;
    /* Every path is started before the first is continued: path_vertex's first loads of a
     * path's ray then find path_start's stores written through, not still queued (a load
     * that several queued stores must feed waits for them, on every sample). */
    for (uint32_t k = 0; k < n; k++)
        path_start(job, &p[k], cp.smp[k], &cp.cs[k], aovs ? &b->aov[k] : NULL);
    for (uint32_t k = 0; k < n; k++) {
        (*rays)++;
        more[k] = path_vertex(job, &p[k], cp.found[k], &cp.hit[k], rays);
        if (p[k].shadow) {
            so[ns] = p[k].so;
            sd[ns] = p[k].sd;
            time01[ns] = p[k].time01;
            slot[ns++] = k;
        }
    }
    if (ns > 0)
        accel_occluded_packet(&job->accel, ns, so, sd, 1.0f - 0x1p-12f, time01, blocked);
    for (uint32_t j = 0; j < ns; j++)
        path_shadow_done(&p[slot[j]], blocked[j]);
    for (uint32_t k = 0; k < n; k++) {
        if (more[k])
            path_run(job, &p[k], rays);
        b->L[k] = p[k].L;
        b->cover[k] = p[k].hit_any;
    }
}

/* The sums of a pixel's kept samples (NaN and Inf are dropped, counted in the stats). */
struct pixel_sums {
    double sum[3], sum2[3], lum_sum, lum_sum2, cover;
    uint32_t n;
};

/* Samples [s0, s1) of pixel (px, py), in blocks of ACCEL_PACKET, added to *ps in sample
 * order; aacc (NULL without AOVs) gets their AOVs. */
static void pixel_samples(const struct render_job *job, struct sampler_pixel *sp, uint32_t pass, uint32_t px,
                          uint32_t py, uint32_t s0, uint32_t s1, struct aov_accum *aacc, struct pixel_sums *ps,
                          struct tile_stats *stats)
{
    memset(ps, 0, sizeof *ps);
    struct sample_block b;
    for (uint32_t si = s0; si < s1; si += ACCEL_PACKET) {
        uint32_t n = s1 - si < ACCEL_PACKET ? s1 - si : ACCEL_PACKET;
        render_block(job, sp, pass, px, py, si, n, aacc != NULL, &b, &stats->rays);
        for (uint32_t k = 0; k < n; k++) {
            stats->samples++;
            if (!v3_is_finite(b.L[k])) {
                stats->nan_samples++;
                continue;
            }
            double c[3] = {b.L[k].x, b.L[k].y, b.L[k].z};
            for (int j = 0; j < 3; j++) {
                ps->sum[j] += c[j];
                ps->sum2[j] += c[j] * c[j];
            }
            double lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
            ps->lum_sum += lum;
            ps->lum_sum2 += lum * lum;
            ps->cover += b.cover[k];
            ps->n++;
            if (aacc)
                aov_accum_add(aacc, &b.aov[k]);
        }
    }
}

void pass_batch_add(struct pass_batch *b, uint32_t stream, const double m[3])
{
    CHECK(stream < SAMPLER_MAX_STREAMS);
    double *sum = b->sum[stream];
    for (int k = 0; k < 3; k++)
        sum[k] += m[k];
    sum[3] += 0.2126 * m[0] + 0.7152 * m[1] + 0.0722 * m[2];
    b->count[stream]++;
    b->n++;
    /* The average of the stream means, recomputed in stream order (the same bits whatever
     * the passes so far). */
    double acc[4] = {0, 0, 0, 0};
    uint32_t q = 0;
    for (uint32_t s = 0; s < SAMPLER_MAX_STREAMS; s++)
        if (b->count[s]) {
            for (int k = 0; k < 4; k++)
                acc[k] += b->sum[s][k] / b->count[s];
            q++;
        }
    for (int k = 0; k < 3; k++)
        b->mean[k] = acc[k] / q;
    b->lum_mean = acc[3] / q;
}

double pass_batch_var_of_mean(const struct pass_batch *b, int k)
{
    double mean = k < 3 ? b->mean[k] : b->lum_mean, ss = 0.0;
    uint32_t q = 0;
    for (uint32_t s = 0; s < SAMPLER_MAX_STREAMS; s++)
        if (b->count[s]) {
            double d = b->sum[s][k] / b->count[s] - mean;
            ss += d * d;
            q++;
        }
    return q > 1 ? ss / (q - 1) / q : 0.0;
}

/* One pass of a pixel (job->num_passes >= 2): pass p takes sample indices
 * [p k, (p + 1) k), which the sampler makes block p / R of stream p mod R (for sobol, the next k points of the stream's one scrambled
 * sequence), and the pass's photon map. *n gets the samples kept (NaN and Inf are
 * dropped), m their mean, *cover the share that hit something. */
static void render_pixel_pass(const struct render_job *job, struct sampler_pixel *sp, uint32_t pass, uint32_t px_x,
                              uint32_t px_y, double m[3], double *cover, uint32_t *n, struct aov_accum *aacc,
                              struct tile_stats *stats)
{
    const uint32_t k = sp->spp; /* samples per pass: sampler_pixel_for set the pixel's pass size */
    /* A photon-map pass always has its map (the master's streams count agrees). */
    uint32_t streams = integrator_streams(render_job_pass_map(job, pass) != NULL);
    if (sp->streams != streams)
        sampler_pixel_set_streams(sp, streams);
    sampler_pixel_set_pass(sp, pass);
    if (aacc)
        aov_accum_reset(aacc);
    struct pixel_sums ps;
    pixel_samples(job, sp, pass, px_x, px_y, pass * k, (pass + 1) * k, aacc, &ps, stats);
    *n = ps.n;
    for (int c = 0; c < 3; c++)
        m[c] = ps.n ? ps.sum[c] / ps.n : 0.0;
    *cover = ps.n ? ps.cover / ps.n : 0.0;
}

static void sampler_pixel_for(const struct render_job *job, uint32_t px_x, uint32_t px_y, struct sampler_pixel *sp)
{
    const struct render_settings *rs = &job->scene->settings;
    const uint32_t k = (rs->spp + job->num_passes - 1) / job->num_passes;
    sampler_pixel_init(sp, rs->sampler, rs->seed, job->frame, (uint64_t)px_y * rs->width + px_x, k);
}

void pass_pixel_fold(struct pass_pixel *pp, uint32_t stream, const float *px)
{
    if (px[CH_A] < 0.0f)
        return; /* every sample of the pass dropped: the other passes make the pixel */
    double m[3] = {px[CH_R], px[CH_G], px[CH_B]};
    pass_batch_add(&pp->b, stream, m);
    pp->cover += px[CH_A];
}

void pass_pixel_finish(const struct pass_pixel *pp, float *px, struct tile_stats *stats)
{
    const struct pass_batch *b = &pp->b;
    for (int c = 0; c < 3; c++) {
        px[CH_R + c] = (float)b->mean[c];
        px[CH_VAR_R + c] = tile_variance_value(pass_batch_var_of_mean(b, c));
    }
    px[CH_A] = b->n ? (float)(pp->cover / b->n) : 0.0f;
    if (b->lum_mean > 0.0 && b->n > 1) {
        stats->sum_rel_stderr += sqrt(pass_batch_var_of_mean(b, 3)) / b->lum_mean;
        stats->rel_stderr_pixels++;
    }
}

/* The pass's channels of one pixel: its mean, its coverage (PASS_ALPHA_NONE when every
 * sample was dropped), variance 0 (batch means are taken over the passes). */
static void pass_pixel_channels(const double m[3], double cover, uint32_t n, float *px)
{
    for (int c = 0; c < 3; c++) {
        px[CH_R + c] = n ? (float)m[c] : 0.0f;
        px[CH_VAR_R + c] = 0.0f;
    }
    px[CH_A] = n ? (float)cover : PASS_ALPHA_NONE;
}

/* A pixel rendered in all its passes: the pass means, rounded to float as a worker sends
 * them, folded in pass order exactly as the master folds units (pass_pixel_fold), so a
 * whole-tile render and a render unit by unit give the same bits. */
static void render_pixel_passes(const struct render_job *job, const struct tile_layout *lay, uint32_t px_x,
                                uint32_t px_y, float *px, struct tile_stats *stats)
{
    struct sampler_pixel sp;
    sampler_pixel_for(job, px_x, px_y, &sp);
    struct pass_pixel pp;
    memset(&pp, 0, sizeof pp);
    struct aov_accum aacc;
    struct aov_pixel ap;
    aov_pixel_init(&ap);
    for (uint32_t p = 0; p < job->num_passes; p++) {
        double m[3], cover;
        uint32_t n;
        float ch[TILE_MAX_CHANNELS];
        render_pixel_pass(job, &sp, p, px_x, px_y, m, &cover, &n, lay->aovs ? &aacc : NULL, stats);
        pass_pixel_channels(m, cover, n, ch);
        pass_pixel_fold(&pp, p % sp.streams, ch);
        if (lay->aovs) {
            aov_accum_write(&aacc, n, lay, ch);
            aov_pixel_fold(&ap, lay, ch);
        }
    }
    pass_pixel_finish(&pp, px, stats);
    if (lay->aovs)
        aov_pixel_finish(&ap, lay, px);
}

void integrator_render_tile_pass(const struct render_job *job, uint32_t pass, uint32_t x0, uint32_t y0, uint32_t w,
                                 uint32_t h, float *pixels, struct tile_stats *stats)
{
    memset(stats, 0, sizeof *stats);
    struct tile_layout lay;
    tile_layout_init(&lay, job->scene->settings.aovs);
    struct aov_accum aacc;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            struct sampler_pixel sp;
            double m[3], cover;
            uint32_t n;
            float *px = &pixels[((size_t)y * w + x) * lay.num_channels];
            sampler_pixel_for(job, x0 + x, y0 + y, &sp);
            render_pixel_pass(job, &sp, pass, x0 + x, y0 + y, m, &cover, &n, lay.aovs ? &aacc : NULL, stats);
            pass_pixel_channels(m, cover, n, px);
            if (lay.aovs)
                aov_accum_write(&aacc, n, &lay, px);
        }
}

void integrator_render_tile(const struct render_job *job, uint32_t x0, uint32_t y0, uint32_t w, uint32_t h,
                            float *pixels, struct tile_stats *stats)
{
    const struct render_settings *rs = &job->scene->settings;
    const uint32_t spp = rs->spp;
    memset(stats, 0, sizeof *stats);
    struct tile_layout lay;
    tile_layout_init(&lay, rs->aovs);
    if (job->num_passes > 1) {
        for (uint32_t y = 0; y < h; y++)
            for (uint32_t x = 0; x < w; x++)
                render_pixel_passes(job, &lay, x0 + x, y0 + y, &pixels[((size_t)y * w + x) * lay.num_channels], stats);
        return;
    }
    struct aov_accum aacc;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            /* The pixel's sampler set-up and seeds are shared by its samples (the values
             * of sampler_start_type per sample, a fraction of the cost). */
            struct sampler_pixel sp;
            sampler_pixel_init(&sp, rs->sampler, rs->seed, job->frame, (uint64_t)(y0 + y) * rs->width + (x0 + x),
                               spp);
            if (lay.aovs)
                aov_accum_reset(&aacc);
            struct pixel_sums ps;
            pixel_samples(job, &sp, 0, x0 + x, y0 + y, 0, spp, lay.aovs ? &aacc : NULL, &ps, stats);
            const uint32_t n = ps.n;
            float *px = &pixels[((size_t)y * w + x) * lay.num_channels];
            if (lay.aovs)
                aov_accum_write(&aacc, n, &lay, px);
            double mean[3], var_mean[3];
            for (int k = 0; k < 3; k++) {
                mean[k] = n ? ps.sum[k] / n : 0.0;
                /* Variance of the mean from the sample variance (unbiased, n-1). */
                double var = n > 1 ? (ps.sum2[k] - n * mean[k] * mean[k]) / (n - 1) : 0.0;
                var_mean[k] = n > 1 ? fmax(0.0, var) / n : 0.0;
                px[CH_R + k] = (float)mean[k];
                px[CH_VAR_R + k] = tile_variance_value(var_mean[k]);
            }
            px[CH_A] = n ? (float)(ps.cover / n) : 0.0f;
            /* Relative standard error of the pixel's luminance, from the luminance of each
             * sample (so correlation between channels is accounted for). */
            double lum_mean = n ? ps.lum_sum / n : 0.0;
            if (lum_mean > 0.0 && n > 1) {
                double var_lum = fmax(0.0, (ps.lum_sum2 - n * lum_mean * lum_mean) / (n - 1)) / n;
                stats->sum_rel_stderr += sqrt(var_lum) / lum_mean;
                stats->rel_stderr_pixels++;
            }
        }
}
