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

/* The radiance along camera ray cs; aov (NULL when the frame has no AOVs) gets its AOVs,
 * set to a miss by the caller. cp: NULL, or the packet whose slot holds cs and its first
 * hit (packet.h). */
static vec3 camera_path(const struct render_job *job, uint32_t pass, uint32_t px, uint32_t py, struct sampler smp,
                        struct camera_sample cs, const struct camera_packet *cp, uint32_t slot, uint64_t *rays,
                        int *hit_any, struct aov_sample *aov)
{
    const struct scene *sc = job->scene;
    const struct render_settings *rs = &sc->settings;
    /* time01 is the ray's time in [0, 1] across the shutter (0 when nothing needs time),
     * for motion-blurred geometry. */
    float time01 = cs.time01;
    vec3 org = cs.o, dir = cs.d;
    struct raydiff rd;          /* texture footprints, only when a material has a texture */
    if (job->textured)
        texshade_camera(job, &cs, &smp, &rd);
    if (job->media) {
        struct accel_hit h0;
        int found0 = aov ? aov_trace(job, org, dir, time01, job->textured ? &rd : NULL, aov, &h0) : 0;
        return media_sample_path_pass(job, pass, &smp, px, py, org, dir, time01, aov ? &h0 : NULL, found0,
                                      job->textured ? &rd : NULL, rays, hit_any);
    }

    vec3 L = v3(0, 0, 0), beta = v3(1, 1, 1);
    float prev_pdf = 0.0f;      /* solid-angle pdf of the BSDF sample that produced dir */
    vec3 prev_p = org;
    int prev_delta = 1;         /* camera rays count as specular: no MIS on what they hit */
    *hit_any = 0;
    for (uint32_t vertex = 1;; vertex++) {
        struct accel_hit h;
        (*rays)++;
        int found;
        if (vertex == 1 && cp) {
            found = cp->found[slot];
            h = cp->hit[slot];
        } else {
            found = accel_intersect(&job->accel, org, dir, INFINITY, time01, &h);
        }
        if (!found) {
            /* Escaped: the environment light, weighted against its light samples. */
            if (sc->env) {
                vec3 le = light_env_radiance(&job->lights, sc, dir);
                float w = prev_delta ? 1.0f : power_heuristic(prev_pdf, light_env_pdf(&job->lights, sc, dir));
                L = v3_add(L, v3_mul(beta, v3_scale(le, w)));
            }
            break;
        }
        if (vertex == 1)
            *hit_any = 1;
        struct surface s;
        surface_from_hit(&job->accel, &job->lights, org, dir, &h, time01, &s);

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
        if (material_is_anisotropic(mat)) /* the roughness axes follow the uv map */
            mat = material_with_axis(mat, surface_dpdu(&job->accel, org, dir, &h, time01), &tex_mat);
        if (aov) {
            if (vertex == 1)
                aov_first_hit(job, &h, &s, ns, aov);
            if (!material_is_delta(mat)) { /* the first non-specular hit: albedo, then no more AOVs */
                aov->albedo = v3_mul(beta, aov_material_albedo(mat));
                aov = NULL;
            }
        }
        vec3 p_off = offset_ray_origin(v3_add(s.p, v3_scale(ng, s.p_err)), ng);
        uint32_t d0 = sampler_bounce_dim(vertex - 1, 0);

        /* Next-event estimation; a delta BSDF is zero toward any sampled light point. */
        if (job->lights.num_entries > 0 && !material_is_delta(mat)) {
            float lu, lv;
            sampler_get_2d(&smp, d0 + DIM_LIGHT_U, &lu, &lv);
            struct nee_sample n;
            if (nee_prepare(&job->lights, sc, mat, s.p, ns, ng, wo, front, 1, sampler_get(&smp, d0 + DIM_LIGHT_PICK), lu, lv, &n)) {
                (*rays)++;
                vec3 o = n.transmitted ? behind(&s, ng) : p_off;
                if (!accel_occluded(&job->accel, o, v3_sub(n.target, o), 1.0f - 0x1p-12f, time01)) {
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
        org = bs.transmitted ? behind(&s, ng) : p_off;
        dir = bs.wi;
    }
    return L;
}

/* One camera sample's radiance: pixel jitter, lens and shutter time. With analytic motion
 * blur the ray's pixel and lens point stay and the shutter is cut where the visible
 * object changes; each part is shaded at a time inside it, weighted by its share of the
 * shutter curve (motion_vis.h). *cover gets the share of the sample that hit something (0
 * or 1 with one time). With parts, aov gets their AOVs weighted the same way (N, albedo, P),
 * and Z with the ids of the nearest part's hit, as a pixel folds its samples (aov.h).
 * cp: NULL, or the packet whose slot holds this sample's camera sample and first hit. */
static vec3 sample_path(const struct render_job *job, uint32_t pass, uint32_t px, uint32_t py, struct sampler smp,
                        const struct camera_packet *cp, uint32_t slot, uint64_t *rays, double *cover,
                        struct aov_sample *aov)
{
    struct camera_sample cs;
    int hit;
    vec3 L;
    if (cp) { /* packets only where nothing moves: no strata */
        L = camera_path(job, pass, px, py, smp, cp->cs[slot], cp, slot, rays, &hit, aov);
        *cover = hit;
        return L;
    }
    camera_generate(&job->camera, &smp, job->frame, px, py, &cs);
    struct mv_strata st;
    if (!job->motion_vis ||
        motion_vis_strata(job->motion_vis, &job->camera, &cs, sampler_get(&smp, DIM_TIME), &st) <= 1) {
        L = camera_path(job, pass, px, py, smp, cs, NULL, 0, rays, &hit, aov);
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
        ck.time = (double)job->frame + job->camera.shutter_open +
                  (double)ck.time01 * (job->camera.shutter_close - job->camera.shutter_open);
        vec3 l = camera_path(job, pass, px, py, smp, ck, NULL, 0, rays, &hit, aov ? &ak : NULL);
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

/* Whether camera rays go in packets (packet.h): where they give the same hits (decided
 * when the job's frame is set up, render_job.c). */
static int packets_on(const struct render_job *job)
{
    return job->packets;
}

/* The sampler of sample si of a pixel's run of samples [s0, end); with packets, taken from
 * the packet cp that holds si's camera ray (slot (si - s0) mod ACCEL_PACKET), traced when
 * si starts one. */
static struct sampler sample_start(const struct render_job *job, int packets, struct sampler_pixel *sp, uint32_t px,
                                   uint32_t py, uint32_t s0, uint32_t end, uint32_t si, struct camera_packet *cp)
{
    if (!packets)
        return sampler_start_pixel(sp, si);
    uint32_t slot = (si - s0) % ACCEL_PACKET;
    if (slot == 0)
        camera_packet_trace(job, sp, px, py, si, end - si < ACCEL_PACKET ? end - si : ACCEL_PACKET, cp);
    return cp->smp[slot];
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
    double sum[3] = {0, 0, 0}, hits = 0.0;
    *n = 0;
    /* A photon-map pass always has its map (the master's streams count agrees). */
    uint32_t streams = integrator_streams(render_job_pass_map(job, pass) != NULL);
    if (sp->streams != streams)
        sampler_pixel_set_streams(sp, streams);
    sampler_pixel_set_pass(sp, pass);
    if (aacc)
        aov_accum_reset(aacc);
    struct camera_packet cp;
    const int packets = packets_on(job);
    for (uint32_t si = pass * k; si < (pass + 1) * k; si++) {
        double hit_any;
        struct aov_sample as;
        if (aacc)
            aov_sample_miss(&as);
        vec3 l = sample_path(job, pass, px_x, px_y, sample_start(job, packets, sp, px_x, px_y, pass * k, (pass + 1) * k, si, &cp),
                             packets ? &cp : NULL, (si - pass * k) % ACCEL_PACKET, &stats->rays, &hit_any,
                             aacc ? &as : NULL);
        stats->samples++;
        if (!v3_is_finite(l)) {
            stats->nan_samples++;
            continue;
        }
        sum[0] += l.x;
        sum[1] += l.y;
        sum[2] += l.z;
        hits += hit_any;
        (*n)++;
        if (aacc)
            aov_accum_add(aacc, &as);
    }
    for (int c = 0; c < 3; c++)
        m[c] = *n ? sum[c] / *n : 0.0;
    *cover = *n ? hits / *n : 0.0;
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
    struct camera_packet cp;
    const int packets = packets_on(job);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            double sum[3] = {0, 0, 0}, sum2[3] = {0, 0, 0}, lum_sum = 0.0, lum_sum2 = 0.0, cover = 0.0;
            uint32_t n = 0;
            /* The pixel's sampler set-up and seeds are shared by its samples (the values
             * of sampler_start_type per sample, a fraction of the cost). */
            struct sampler_pixel sp;
            sampler_pixel_init(&sp, rs->sampler, rs->seed, job->frame, (uint64_t)(y0 + y) * rs->width + (x0 + x),
                               spp);
            if (lay.aovs)
                aov_accum_reset(&aacc);
            for (uint32_t si = 0; si < spp; si++) {
                double hit_any;
                struct aov_sample as;
                if (lay.aovs)
                    aov_sample_miss(&as);
                vec3 l = sample_path(job, 0, x0 + x, y0 + y, sample_start(job, packets, &sp, x0 + x, y0 + y, 0, spp, si, &cp),
                                     packets ? &cp : NULL, si % ACCEL_PACKET, &stats->rays, &hit_any, lay.aovs ? &as : NULL);
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
                if (lay.aovs)
                    aov_accum_add(&aacc, &as);
            }
            float *px = &pixels[((size_t)y * w + x) * lay.num_channels];
            if (lay.aovs)
                aov_accum_write(&aacc, n, &lay, px);
            double mean[3], var_mean[3];
            for (int k = 0; k < 3; k++) {
                mean[k] = n ? sum[k] / n : 0.0;
                /* Variance of the mean from the sample variance (unbiased, n-1). */
                double var = n > 1 ? (sum2[k] - n * mean[k] * mean[k]) / (n - 1) : 0.0;
                var_mean[k] = n > 1 ? fmax(0.0, var) / n : 0.0;
                px[CH_R + k] = (float)mean[k];
                px[CH_VAR_R + k] = tile_variance_value(var_mean[k]);
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
