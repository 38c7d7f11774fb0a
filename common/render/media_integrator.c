/* Camera paths through media (see media_integrator.h). VPT: closed-form or tracked free
 * flight, NEE with shadow transmittance and MIS (equiangular toward point lights and points on emissive triangles). March
 * (Jensen): jittered steps, single scattering to every light when there are at most
 * MARCH_ALL_LIGHTS point lights + the k-nearest photon estimate; beam: one beam query per
 * segment (in homogeneous media camera segments take points instead of a march when lights
 * are picked one at a time, and long segments' beams one random piece); at the first diffuse vertex a final gather (surface photon map after one
 * bounce, sampled toward glowing lights and the media too: gather_bounce) or, with path-traced indirect light, VPT from there on. Random numbers: one key
 * per (seed, frame, pixel, sample) and a fixed layout of dimensions per vertex, so pixels
 * do not depend on threads, tiles or workers. Surfaces take their textures (texshade.h)
 * over footprints of the camera's ray differentials carried along the path. */
#include "render/media_integrator.h"
#include "render/media_track.h"
#include "render/photon_map.h"
#include "render/photon_beams.h"
#include "render/photon_trace.h"
#include "render/surface.h"
#include "render/texshade.h"
#include "base/cdf.h"
#include "base/rng.h"
#include "scene/grid.h"
#include "scene/material.h"
#include <math.h>
#include <string.h>

#define MAX_CROSSINGS 256
#define MAX_STEPS 100000
#define DIMS_PER_VERTEX 16
/* Single-scattering points on a camera segment in a homogeneous medium (beam, lights picked
 * one at a time; gather_segment). */
#define CAMERA_POINTS 8u
/* gather_segment's beam query: at most BEAM_PIECES pieces, each at least BEAM_PIECE_RADII
 * gather radii long. */
#define BEAM_PIECES 4u
#define BEAM_PIECE_RADII 8.0f
/* Jensen's per-step estimate: maximum radius of the k-nearest query, in gather radii. */
#define KNN_RADIUS_FACTOR 4.0f

struct rngs {
    uint64_t key;
};

/* Equiangular sampling (Kulla and Fajardo 2012) of t in [0, tend) on o + t d toward the
 * point c: pdf proportional to 1 / distance^2, which cancels a point light's singularity.
 * pdf 0 when the ray passes through c or the segment is empty. The angle the segment
 * subtends from c, span = atan((tend - delta) / dist) - atan(-delta / dist), is one atan2
 * of the tangent of the difference (in (0, pi), so atan2 needs no branch): a pdf needs
 * only this; a sample also needs the start angle (equi_sample). */
struct equi { float delta, dist, span; };

static int equi_init(struct equi *e, vec3 o, vec3 d, vec3 c, float tend, float eps)
{
    vec3 oc = v3_sub(c, o);
    e->delta = v3_dot(oc, d);
    e->dist = v3_length(v3_sub(oc, v3_scale(d, e->delta)));
    if (!(e->dist > eps) || !(tend > 0.0f) || !isfinite(tend))
        return 0;
    /* tan(span) = tend dist / (dist^2 - delta (tend - delta)), both terms over dist */
    e->span = atan2f(tend, e->dist - e->delta * ((tend - e->delta) / e->dist));
    return e->span > 0.0f && isfinite(e->span);
}

static float equi_pdf(const struct equi *e, float t)
{
    float x = t - e->delta;
    return e->dist / (e->span * (e->dist * e->dist + x * x));
}

static float equi_sample(const struct equi *e, float u)
{
    return e->delta + e->dist * tanf(atan2f(-e->delta, e->dist) + u * e->span);
}

/* The segment a distance sample ran over, for the MIS between its NEE and equiangular
 * sampling of point and area lights: VPT's free flight (FL_FREE; its NEE is also weighted
 * against phase sampling), the final gather's one point per segment (FL_TRUNC: an
 * exponential truncated to [0, tend)), or march's jittered steps (FL_MARCH: one sample
 * per dx, a density of 1 / dx); cut: phase without the forward cone. */
enum { FL_FREE, FL_TRUNC, FL_MARCH };
/* count: FL_TRUNC's number of stratified points on the segment (their joint density is
 * count x the truncated exponential's). */
struct flight_ctx { vec3 o, d; float tend, t; vec3 chan; const struct medium *md; float eps; int trunc, cut; float dx; float count; float mass; };

/* The truncated exponential's coefficient: sigma_t averaged over the channels (the weight
 * Tr(t) / pdf(t) is per channel). */
static float trunc_sigma(const struct medium *md)
{
    return (md->sigma_t.x + md->sigma_t.y + md->sigma_t.z) / 3.0f;
}

/* The truncated exponential's mass on [0, tend), 1 - exp(-s tend): expm1 keeps it exact in
 * thin media. Computed once per segment for trunc_pdf and trunc_sample. */
static float trunc_mass(float s, float tend)
{
    return -expm1f(-s * tend);
}

/* pdf of t in [0, tend) under exp(-s t) restricted to the segment (uniform when s tend is
 * 0); mass: trunc_mass(s, tend). */
static float trunc_pdf(float s, float mass, float tend, float t)
{
    return mass > 0.0f ? s * expf(-s * t) / mass : 1.0f / tend;
}

static float trunc_sample(float s, float mass, float tend, float u)
{
    float t = mass > 0.0f ? -log1pf(-u * mass) / s : u * tend;
    return t < tend ? t : nextafterf(tend, 0.0f);
}

/* Density of the distance sample at t, for MIS. */
static float flight_pdf(const struct flight_ctx *fc, float t)
{
    if (fc->trunc == FL_MARCH)
        return 1.0f / fc->dx;
    return fc->trunc == FL_TRUNC ? fc->count * trunc_pdf(trunc_sigma(fc->md), fc->mass, fc->tend, t)
                                 : medium_flight_pdf(fc->md, fc->chan, t);
}

static float rnd(const struct rngs *r, uint32_t vertex, uint32_t k)
{
    return rng_uniform(r->key, vertex * DIMS_PER_VERTEX + k);
}

/* Whether light table entry i takes an equiangular sample: point (and spot) lights and
 * emissive triangles, whose points are sampled whatever the shading point. */
static int equi_light(const struct light_table *lt, uint32_t i)
{
    enum light_kind k = lt->entries[i].kind;
    return k == LK_POINT || k == LK_TRIANGLE;
}

/* Light arriving at x (in `medium`) from one sampled light, times the phase function for
 * light leaving along d_out (cut: without the forward cone, photon_map.h); *pdf_light
 * gets the sample's pdf for MIS (0 = delta). */
static vec3 scatter_nee(const struct render_job *job, vec3 x, vec3 d_out, uint32_t medium, float g, int cut, float u0,
                        float u1, float u2, float time01, uint64_t key, uint64_t *rays, int mis,
                        const struct flight_ctx *fc)
{
    const struct scene *sc = job->scene;
    if (job->lights.num_entries == 0)
        return v3(0, 0, 0);
    struct light_sample ls;
    light_sample(&job->lights, sc, x, u0, u1, u2, &ls);
    if (!(ls.pdf > 0.0f) || v3_is_black(ls.radiance))
        return v3(0, 0, 0);
    vec3 to = v3_sub(ls.p, x);
    if (!(v3_dot(to, to) > 0.0f))
        return v3(0, 0, 0);
    vec3 wi = ls.wi; /* light_sample's (p - x) / |p - x|, the same bits */
    float ph = cut ? phase_hg_cut(v3_dot(v3_neg(wi), d_out), g) : phase_hg(v3_dot(v3_neg(wi), d_out), g);
    vec3 target = ls.is_delta ? ls.p : offset_ray_origin(ls.p, v3_dot(ls.n, wi) < 0.0f ? ls.n : v3_neg(ls.n));
    vec3 tr = media_shadow_transmittance(job->media, x, target, medium, time01, key, rays);
    if (v3_is_black(tr))
        return v3(0, 0, 0);
    float w = (ls.is_delta || !mis) ? 1.0f : power_heuristic(ls.pdf, ph);
    struct equi e;
    if (fc && equi_light(&job->lights, ls.entry) && equi_init(&e, fc->o, fc->d, ls.p, fc->tend, fc->eps) &&
        fc->t < fc->tend) {
        /* Balance heuristic against equiangular sampling of the same light point (its
         * density, the pick times 1 / area for a triangle, is the same in both strategies
         * and cancels), within this NEE's share of the MIS against phase sampling. */
        float pf = flight_pdf(fc, fc->t), pe = equi_pdf(&e, fc->t);
        w *= pf / (pf + pe);
    }
    return v3_scale(v3_mul(ls.radiance, tr), ph * w / ls.pdf);
}

/* Solid-angle sampling of an emissive triangle (Arvo 1995, "Stratified sampling of
 * spherical triangles") for NEE from gather_segment's points. Area sampling has the density
 * d^2 / (A cos) in solid angle, whose ratio to the integrand is unbounded for points next
 * to the lamp or at grazing angles (a heavy tail on and beside the lamp); uniform in the
 * solid angle the triangle subtends, the ratio is the phase function times that solid
 * angle. Below SPH_MIN_OMEGA steradians (a far lamp, where the two densities agree and the
 * spherical formulas lose precision) the point keeps area sampling. Computed in double. */
#define SPH_MIN_OMEGA 1e-4
struct sph_tri { double a[3], b[3], c[3]; double omega; };

static void d3_sub(double *r, vec3 p, vec3 x)
{
    r[0] = (double)p.x - x.x, r[1] = (double)p.y - x.y, r[2] = (double)p.z - x.z;
}
static double d3_dot(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static void d3_cross(double *r, const double *a, const double *b)
{
    r[0] = a[1] * b[2] - a[2] * b[1], r[1] = a[2] * b[0] - a[0] * b[2], r[2] = a[0] * b[1] - a[1] * b[0];
}
static double d3_len(const double *a) { return sqrt(d3_dot(a, a)); }
/* r = normalize(a - dot(a, e) e) for unit e (0 when a is parallel to e) */
static int d3_orth(double *r, const double *a, const double *e)
{
    double k = d3_dot(a, e);
    for (int i = 0; i < 3; i++)
        r[i] = a[i] - k * e[i];
    double l = d3_len(r);
    if (!(l > 0.0))
        return 0;
    for (int i = 0; i < 3; i++)
        r[i] /= l;
    return 1;
}
/* The triangle (v0, v1, v2) seen from x: unit directions and the solid angle (Van Oosterom
 * and Strackee 1983). 0 when x is on the plane or the solid angle is below SPH_MIN_OMEGA. */
static int sph_init(struct sph_tri *t, vec3 x, vec3 v0, vec3 v1, vec3 v2)
{
    double la, lb, lc, bc[3];
    d3_sub(t->a, v0, x), d3_sub(t->b, v1, x), d3_sub(t->c, v2, x);
    la = d3_len(t->a), lb = d3_len(t->b), lc = d3_len(t->c);
    if (!(la > 0.0 && lb > 0.0 && lc > 0.0))
        return 0;
    d3_cross(bc, t->b, t->c);
    double num = fabs(d3_dot(t->a, bc));
    double den = la * lb * lc + d3_dot(t->a, t->b) * lc + d3_dot(t->a, t->c) * lb + d3_dot(t->b, t->c) * la;
    t->omega = 2.0 * atan2(num, den);
    for (int i = 0; i < 3; i++)
        t->a[i] /= la, t->b[i] /= lb, t->c[i] /= lc;
    return t->omega >= SPH_MIN_OMEGA && isfinite(t->omega);
}

/* A direction uniform in the spherical triangle from two uniforms (Arvo's construction:
 * u1 picks the sub-triangle (a, b, c') of area u1 omega, u2 a point on the arc b c'). The
 * angle alpha at a enters only through its cosine and sine, taken from the normals of the
 * planes (a, b) and (a, c), and sin, cos of (u1 omega - alpha) by the difference formulas:
 * one sincos a sample. */
static int sph_sample(const struct sph_tri *t, double u1, double u2, double *w)
{
    double nb[3], nc[3], x[3];
    d3_cross(nb, t->a, t->b);
    d3_cross(nc, t->a, t->c);
    d3_cross(x, nb, nc);
    double sa = d3_len(x), ca = d3_dot(nb, nc), r = sqrt(sa * sa + ca * ca);
    if (!(r > 0.0))
        return 0;
    sa /= r, ca /= r;
    double A = u1 * t->omega, sA = sin(A), cA = cos(A);
    double s = sA * ca - cA * sa, tt = cA * ca + sA * sa; /* sin, cos of (u1 omega - alpha) */
    double u = tt - ca, v = s + sa * d3_dot(t->a, t->b);
    double den = (v * s + u * tt) * sa;
    if (!(fabs(den) > 0.0))
        return 0;
    double q = ((v * tt - u * s) * ca - v) / den;
    q = q < -1.0 ? -1.0 : q > 1.0 ? 1.0 : q;
    double e[3], ch[3], f[3];
    if (!d3_orth(e, t->c, t->a))
        return 0;
    double sq = sqrt(fmax(0.0, 1.0 - q * q));
    for (int i = 0; i < 3; i++)
        ch[i] = q * t->a[i] + sq * e[i];
    double z = 1.0 - u2 * (1.0 - d3_dot(ch, t->b));
    z = z < -1.0 ? -1.0 : z > 1.0 ? 1.0 : z;
    if (!d3_orth(f, ch, t->b)) {
        memcpy(w, t->b, sizeof f);
        return 1;
    }
    double sz = sqrt(fmax(0.0, 1.0 - z * z));
    for (int i = 0; i < 3; i++)
        w[i] = z * t->b[i] + sz * f[i];
    return 1;
}

/* The solid-angle density gather_segment's NEE gives the point c (normal n) of emissive
 * triangle i seen from x, with the pick: pick / omega when the triangle is sampled by solid
 * angle from x, else light_pdf's (area sampling); 0 from behind the lamp. */
static float point_nee_pdf(const struct render_job *job, uint32_t i, vec3 x, vec3 c, vec3 n)
{
    vec3 v[3], nn;
    struct sph_tri t;
    light_triangle_vertices(&job->lights, i, v, &nn);
    if (v3_dot(nn, v3_sub(x, v[0])) > 0.0f && sph_init(&t, x, v[0], v[1], v[2]))
        return (float)(job->lights.pick_pdf[i] / t.omega);
    return light_pdf(&job->lights, job->scene, i, x, c, n);
}

/* gather_segment's NEE at the point x = o + fc->t d: an emissive triangle is sampled by
 * solid angle where point_nee_pdf says so, every other light as scatter_nee samples it.
 * Balance heuristic against the segment's equiangular sample toward the same light point,
 * with both densities in solid angle at x: the points' flight_pdf x point_nee_pdf against
 * the equiangular pdf x the area density (light_pdf). Returns the estimate times the
 * points' flight_pdf (the caller divides by it), phase function without the forward cone. */
static vec3 point_nee(const struct render_job *job, vec3 x, vec3 d_out, uint32_t medium, float g, float u0, float u1,
                      float u2, float time01, uint64_t key, uint64_t *rays, const struct flight_ctx *fc)
{
    uint32_t i = light_pick(&job->lights, u0);
    if (job->lights.num_entries == 0 || job->lights.entries[i].kind != LK_TRIANGLE || !(job->lights.pick_pdf[i] > 0.0f))
        return scatter_nee(job, x, d_out, medium, g, 1, u0, u1, u2, time01, key, rays, 0, fc);
    vec3 v[3], n;
    struct sph_tri t;
    light_triangle_vertices(&job->lights, i, v, &n);
    if (!(v3_dot(n, v3_sub(x, v[0])) > 0.0f))
        return v3(0, 0, 0); /* behind the lamp: its back emits nothing */
    if (!sph_init(&t, x, v[0], v[1], v[2]))
        return scatter_nee(job, x, d_out, medium, g, 1, u0, u1, u2, time01, key, rays, 0, fc);
    double w[3];
    if (!sph_sample(&t, u1, u2, w))
        return v3(0, 0, 0);
    /* the direction's hit on the triangle's plane */
    double pv[3], nd[3] = {n.x, n.y, n.z};
    d3_sub(pv, v[0], x);
    double wn = d3_dot(w, nd), dist = d3_dot(pv, nd) / wn;
    if (!(wn < 0.0) || !(dist > 0.0) || !isfinite(dist))
        return v3(0, 0, 0);
    vec3 wi = v3((float)w[0], (float)w[1], (float)w[2]);
    vec3 c = v3((float)(x.x + dist * w[0]), (float)(x.y + dist * w[1]), (float)(x.z + dist * w[2]));
    float lp_s = (float)(job->lights.pick_pdf[i] / t.omega), lp_a = light_pdf(&job->lights, job->scene, i, x, c, n);
    float ph = phase_hg_cut(v3_dot(v3_neg(wi), d_out), g);
    vec3 tr = media_shadow_transmittance(job->media, x, offset_ray_origin(c, n), medium, time01, key, rays);
    if (v3_is_black(tr))
        return v3(0, 0, 0);
    struct equi e;
    float pf = flight_pdf(fc, fc->t), pe = 0.0f;
    if (equi_init(&e, fc->o, fc->d, c, fc->tend, fc->eps) && fc->t < fc->tend)
        pe = equi_pdf(&e, fc->t);
    float den = pf * lp_s + pe * lp_a;
    if (!(den > 0.0f) || !isfinite(den))
        return v3(0, 0, 0);
    return v3_scale(v3_mul(job->lights.entries[i].emission, tr), ph * pf / den);
}

#define MARCH_ALL_LIGHTS 4
/* Jensen's methods sample every light when the scene has at most MARCH_ALL_LIGHTS, all
 * point or spot lights. */
static int march_all_points(const struct render_job *job)
{
    if (job->lights.num_entries == 0 || job->lights.num_entries > MARCH_ALL_LIGHTS)
        return 0;
    for (uint32_t i = 0; i < job->lights.num_entries; i++)
        if (job->lights.entries[i].kind != LK_POINT)
            return 0;
    return 1;
}

/* Single scattering toward every light of a table of point lights at x (light leaving
 * along d_out): sum of I falloff / d^2 x phase (without the forward cone) x shadow
 * transmittance. */
static vec3 point_lights_all(const struct render_job *job, vec3 x, vec3 d_out, uint32_t medium, float g, float time01,
                             uint64_t key, uint64_t *rays)
{
    const struct scene *sc = job->scene;
    vec3 sum = v3(0, 0, 0);
    for (uint32_t i = 0; i < job->lights.num_entries; i++) {
        const struct light_entry *e = &job->lights.entries[i];
        if (e->kind != LK_POINT)
            continue;
        const struct light *l = &sc->lights[e->index];
        vec3 to = v3_sub(l->position, x);
        float d2 = v3_dot(to, to);
        if (!(d2 > 0.0f))
            continue;
        float len = sqrtf(d2);
        vec3 li = v3_scale(e->emission, light_spot_falloff_len(l, v3_neg(to), len) / d2);
        if (v3_is_black(li))
            continue;
        float ph = phase_hg_cut(v3_dot(v3_scale(to, -1.0f / len), d_out), g);
        vec3 tr = media_shadow_transmittance(job->media, x, l->position, medium, time01, rng_mix64(key + i), rays);
        sum = v3_add(sum, v3_scale(v3_mul(li, tr), ph));
    }
    return sum;
}

/* Single scattering of one light (picked as NEE picks) along the segment: a point light's
 * position, or a point on an emissive triangle (uniform by area, as NEE samples it), then
 * t sampled equiangularly toward that point, weighted against free-flight NEE (in VPT
 * within NEE's share of the MIS against phase sampling); times beta outside. Spheres take
 * none (NEE samples them by the cone seen from the shading point). */
static vec3 equiangular(const struct render_job *job, const struct rngs *r, uint32_t vertex,
                        const struct flight_ctx *fc, uint32_t medium, float time01, uint64_t *rays)
{
    const struct scene *sc = job->scene;
    uint32_t i = light_pick(&job->lights, rnd(r, vertex, 8));
    const struct light_entry *e = &job->lights.entries[i];
    float pick = job->lights.pick_pdf[i];
    if (!(pick > 0.0f) || (e->kind != LK_POINT && e->kind != LK_TRIANGLE))
        return v3(0, 0, 0);
    vec3 c, n = v3(0, 0, 0);
    if (e->kind == LK_POINT) {
        c = sc->lights[e->index].position;
    } else {
        uint64_t k = rng_mix64(r->key ^ (0x4154ull << 48) ^ vertex);
        light_triangle_point(&job->lights, i, rng_uniform(k, 0), rng_uniform(k, 1), &c, &n);
    }
    struct equi q;
    if (!equi_init(&q, fc->o, fc->d, c, fc->tend, fc->eps))
        return v3(0, 0, 0);
    float t = equi_sample(&q, rnd(r, vertex, 9));
    if (!(t >= 0.0f && t < fc->tend))
        return v3(0, 0, 0);
    float pe = equi_pdf(&q, t), pf = flight_pdf(fc, t);
    vec3 x = v3_add(fc->o, v3_scale(fc->d, t));
    vec3 to = v3_sub(c, x);
    float d2 = v3_dot(to, to);
    if (!(d2 > 0.0f) || !(pe > 0.0f))
        return v3(0, 0, 0);
    float len = sqrtf(d2);
    vec3 wi = v3_scale(to, 1.0f / len);
    /* light travels along -wi, then back along -d toward the segment's origin */
    float cos_t = v3_dot(wi, fc->d);
    float ph = fc->cut ? phase_hg_cut(cos_t, fc->md->g) : phase_hg(cos_t, fc->md->g);
    float w = pe / (pe + pf);
    vec3 li, target = c;
    if (e->kind == LK_POINT) {
        /* I falloff / d^2 over the pick */
        li = v3_scale(e->emission, light_spot_falloff_len(&sc->lights[e->index], v3_neg(to), len) / (d2 * pick));
    } else {
        /* L_e G / (pick / area) = L_e / (the solid-angle pdf NEE would give this point) */
        float lp = light_pdf(&job->lights, sc, i, x, c, n);
        if (!(lp > 0.0f))
            return v3(0, 0, 0);
        li = v3_scale(e->emission, 1.0f / lp);
        if (fc->trunc == FL_FREE)
            w *= power_heuristic(lp, ph);
        if (fc->trunc == FL_TRUNC) {
            /* gather_segment's points may sample the lamp by solid angle (point_nee): the
             * balance heuristic with both densities in solid angle at x */
            float lq = point_nee_pdf(job, i, x, c, n);
            double de = (double)pe * lp, dp = (double)pf * lq;
            w = (float)(de / (de + dp));
        }
        target = offset_ray_origin(c, v3_dot(n, wi) < 0.0f ? n : v3_neg(n));
    }
    if (v3_is_black(li))
        return v3(0, 0, 0);
    vec3 tr = media_shadow_transmittance(job->media, x, target, medium, time01,
                                         rng_mix64(r->key ^ (0x4551ull << 48) ^ vertex), rays);
    vec3 f = v3_mul(v3_mul(medium_transmittance(fc->md, t), fc->md->sigma_s), v3_mul(li, tr));
    return v3_scale(f, ph * w / pe);
}

/* max_depth counts the scattering and surface events of the whole path. After `depth`
 * camera events, in-scattering on a segment is one more (nee: 1 when single scattering
 * still fits), and a photon that arrived after k events makes the path depth + 1 + k long:
 * the largest k a volume lookup may count, or 0 for none (photons have k >= 1). */
static uint32_t volume_photon_depth_max(uint32_t max_depth, uint32_t depth, int *nee)
{
    *nee = depth < max_depth;
    return depth + 1 < max_depth ? max_depth - depth - 1 : 0;
}

/* Jensen's march along [0, len) of o + t d in medium md after `depth` camera events:
 * emission, single scattering and the photon estimate, each attenuated to the camera (beta
 * outside); *seg_tr gets the segment's transmittance. Homogeneous media: closed-form
 * transmittance to each step. Grids: the optical depth accumulates step by step (a table
 * of it serves the beam). */
#define TAU_TABLE 4096
/* A march stops where the transmittance to the camera falls below this: what lies beyond
 * adds less than this fraction of its own radiance. */
#define MARCH_TR_MIN 1e-6f
/* Where the table's optical depth reaches tau (its t, in the table's frame). */
static float tau_table_at(const struct photon_tau *tt, float tau)
{
    const float *tab = tt->tau;
    if (!(tau > tab[0]))
        return tt->t0;
    if (!(tau < tab[tt->n - 1]))
        return tt->t0 + (float)(tt->n - 1) * tt->dt;
    uint32_t j = cdf_cell(tab, tt->n - 1, tau); /* tab[j] <= tau < tab[j + 1] */
    return tt->t0 + ((float)j + (tau - tab[j]) / (tab[j + 1] - tab[j])) * tt->dt;
}

/* A gather segment's beam query in a grid over one of `pieces` parts of [e0, e1) of equal
 * transmittance mass (1 - Tr on sigma_t st, from the march's table tt, in the same frame as
 * e0 and e1), picked by u: [*q0, *q1). 0 when the segment holds too little mass to cut. */
static int tau_table_piece(const struct photon_tau *tt, float st, float e0, float e1, uint32_t pieces, float u,
                           float *q0, float *q1)
{
    float a = expf(-st * photon_tau_depth(tt, e0)), m = a - expf(-st * photon_tau_depth(tt, e1));
    if (!(m > 1e-6f) || !(st > 0.0f))
        return 0;
    float v = u * (float)pieces;
    uint32_t k = v < (float)pieces ? (uint32_t)v : pieces - 1;
    *q0 = k == 0 ? e0 : fmaxf(e0, tau_table_at(tt, -logf(a - m * (float)k / (float)pieces) / st));
    *q1 = k + 1 == pieces ? e1 : fminf(e1, tau_table_at(tt, -logf(a - m * (float)(k + 1) / (float)pieces) / st));
    return 1;
}

static vec3 march_segment(const struct render_job *job, const struct media_job *mj, const struct rngs *r,
                          uint32_t vertex, uint32_t depth, vec3 o, vec3 d, float len, uint32_t medium, float time01,
                          uint64_t *rays, vec3 *seg_tr)
{
    int nee;
    const uint32_t kmax = volume_photon_depth_max(job->scene->settings.max_depth, depth, &nee);
    const struct photon_map *map = kmax > 0 ? mj->map : NULL;
    /* The forward cone is no scattering: camera rays see sigma_t less its share. */
    const struct medium *md = &mj->cut[medium];
    const int het = md->grid != NULL, emissive = !v3_is_black(md->emission);
    vec3 L = het ? v3(0, 0, 0) : medium_emission_integral(md, len);
    *seg_tr = medium_transmittance(md, len);
    float c0 = 0.0f, c1 = len;
    if (het) {
        *seg_tr = v3(1, 1, 1);
        if (!medium_clip(md, o, d, len, &c0, &c1))
            return L; /* empty space: nothing to march */
    }
    if (v3_is_black(md->sigma_s) && !het)
        return L;
    /* Jittered steps estimate the integral without bias at any dx: after the first vertex
     * (paths already spread over the hemisphere) four times longer steps cost less for
     * the same image variance. */
    const float step = media_step(mj, md), nee_step = vertex == 0 ? step : 4.0f * step;
    float dx = medium_march_step(md, nee_step);
    float span = c1 - c0;
    if (span / dx > (float)(het ? TAU_TABLE - 2 : MAX_STEPS))
        dx = span / (float)(het ? TAU_TABLE - 2 : MAX_STEPS);
    /* Grids: the optical depth takes steps of at most half a voxel, the in-scattering only
     * the march's step: it is taken at every `every`-th step, from step next_nee (a random
     * residue) on, counted `every` times. One uniform gives both the residue and the
     * steps' jitter. */
    const uint32_t every = het && nee_step > dx ? (uint32_t)fmaxf(1.0f, floorf(nee_step / dx * 1.0001f)) : 1u;
    float jitter = rnd(r, vertex, 10) * (float)every;
    uint32_t next_nee = jitter < (float)every ? (uint32_t)jitter : every - 1u; /* the first NEE step */
    jitter -= (float)next_nee;
    const float dx_nee = dx * (float)every;
    /* A few point lights: every one at every step (no pick noise; the shadow cache makes
     * each cheap). Otherwise one light picked in proportion to power. */
    const int all_points = march_all_points(job);
    /* Homogeneous media, lights sampled one at a time: each step's NEE is weighted against
     * one equiangular sample per segment (the steps' density is 1 / dx), which takes the
     * 1/d^2 peak next to a point or area light. */
    struct flight_ctx fc = {o, d, len, 0.0f, v3(1, 1, 1), md, 1e-7f * mj->scene_size, FL_MARCH, 1, dx, 1.0f, 0.0f};
    const int equi = nee && !het && !all_points && job->lights.num_entries > 0;
    if (equi)
        L = v3_add(L, equiangular(job, r, vertex, &fc, medium, time01, rays));
    uint64_t seg_key = rng_mix64(r->key ^ ((uint64_t)(vertex + 1) << 40));
    float tau_tab[TAU_TABLE];   /* grids: optical depth (per unit sigma_t) at c0 + k dx */
    uint32_t ntab = 0;
    float tau = 0.0f;
    int cut = 0; /* a grid's march stopped where the transmittance fell below MARCH_TR_MIN */
    if (het)
        tau_tab[ntab++] = 0.0f;
    for (uint32_t k = 0;; k++) {
        float t = c0 + ((float)k + jitter) * dx;
        if (!(t < c1))
            break;
        vec3 x = v3_add(o, v3_scale(d, t));
        float rho = 1.0f;
        vec3 tr;
        if (het) {
            rho = grid_density(md->grid, x);
            float tau_here = tau + rho * jitter * dx;
            tr = medium_tr_tau(md, tau_here);
            tau += rho * dx;
            if (ntab < TAU_TABLE)
                tau_tab[ntab++] = tau;
            /* Emission, e times the density (homogeneous media: closed form above). */
            if (emissive)
                L = v3_add(L, v3_scale(v3_mul(tr, md->emission), rho * dx));
        } else {
            tr = medium_transmittance(md, t);
        }
        if (v3_max_component(tr) < MARCH_TR_MIN) {
            cut = het;
            break; /* nothing beyond reaches the camera */
        }
        if (k != next_nee)
            continue;
        next_nee += every;
        if (!(rho > 0.0f))
            continue;
        fc.t = t;
        vec3 ls = !nee ? v3(0, 0, 0) : all_points ? point_lights_all(job, x, v3_neg(d), medium, md->g, time01,
                                                rng_mix64(seg_key ^ (0x5348ull << 48) ^ k), rays)
                             : scatter_nee(job, x, v3_neg(d), medium, md->g, 1, rng_uniform(seg_key, 3 * k),
                                           rng_uniform(seg_key, 3 * k + 1), rng_uniform(seg_key, 3 * k + 2), time01,
                                           rng_mix64(seg_key ^ (0x5348ull << 48) ^ k), rays, 0, equi ? &fc : NULL);
        vec3 in = v3_scale(v3_mul(md->sigma_s, ls), rho);
        if (mj->sm->method == MEDIA_MARCH_STEPS && map)
            in = v3_add(in, photon_map_gather_knn(map, x, v3_neg(d), md->g, mj->sm->knn, KNN_RADIUS_FACTOR * map->radius,
                                                  kmax, rho, het ? md->grid->max_density : 0.0f));
        L = v3_add(L, v3_scale(v3_mul(tr, in), dx_nee));
    }
    if (het)
        *seg_tr = medium_tr_tau(md, tau);
    if ((mj->sm->method == MEDIA_MARCH_BEAM || mj->sm->method == MEDIA_MARCH_BEAMS) && map) {
        if (het) {
            /* Photons and beams lie in the occupied box (stored only where the density is
             * non-zero): the query need only walk the part of the ray within r of its box. */
            vec3 blo, bhi;
            grid_world_box(md->grid, &blo, &bhi);
            float rad = map->radius, e0 = 0.0f, e1 = len;
            vec3 pad = v3(rad, rad, rad);
            if (cut) /* photons past the march's end: transmittance below MARCH_TR_MIN */
                e1 = fminf(e1, c0 + (float)(ntab - 1) * dx);
            if (v3_clip_box(o, d, v3_sub(blo, pad), v3_add(bhi, pad), &e0, &e1) && e0 < e1) {
                /* After the first vertex (the final gather's segments) the point map's beam
                 * over one of `pieces` parts of equal transmittance mass, picked at random,
                 * counts `pieces` times, as in homogeneous media (gather_segment): the
                 * query's cost follows the length it walks. Camera segments keep the whole
                 * beam (docs/media.md, "Gathering toward the media"). */
                float nf = floorf((e1 - e0) / (BEAM_PIECE_RADII * rad)), q0 = e0, q1 = e1, wq = 1.0f;
                uint32_t pieces = vertex == 0 || map->beams || !(nf > 1.0f) ? 1u
                                  : nf < (float)BEAM_PIECES                ? (uint32_t)nf
                                                                           : BEAM_PIECES;
                const struct photon_tau whole = {tau_tab, ntab, c0, dx}; /* t along o + t d */
                if (pieces > 1 && tau_table_piece(&whole, trunc_sigma(md), e0, e1, pieces, rnd(r, vertex, 15), &q0, &q1))
                    wq = (float)pieces;
                if (q0 < q1) {
                    struct photon_tau tt = {tau_tab, ntab, c0 - q0, dx};
                    vec3 oq = v3_add(o, v3_scale(d, q0));
                    L = v3_add(L, v3_scale(photon_map_beam(map, oq, d, q1 - q0, md, &tt, kmax), wq));
                    if (map->beams)
                        L = v3_add(L, photon_beams_estimate(map->beams, oq, d, q1 - q0, md, &tt, kmax));
                }
            }
        } else {
            L = v3_add(L, photon_map_beam(map, o, d, len, md, NULL, kmax));
            if (map->beams)
                L = v3_add(L, photon_beams_estimate(map->beams, o, d, len, md, NULL, kmax));
        }
    }
    return L;
}

/* Where a ray that hits nothing stops being marched: the exit from the scene's bounds. */
static float exit_distance(const struct media_job *mj, vec3 o, vec3 d)
{
    float t1 = INFINITY;
    float oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
    float lo[3] = {mj->bounds_lo.x, mj->bounds_lo.y, mj->bounds_lo.z}, hi[3] = {mj->bounds_hi.x, mj->bounds_hi.y, mj->bounds_hi.z};
    for (int a = 0; a < 3; a++) {
        if (dd[a] == 0.0f)
            continue;
        float t = ((dd[a] > 0.0f ? hi[a] : lo[a]) - oo[a]) / dd[a];
        t1 = fminf(t1, t);
    }
    return t1 > 0.0f ? t1 : 0.0f;
}

/* Where march and beam stop a ray that hits nothing: the exit from the bounds, or in a
 * homogeneous fog photon_fog_reach past it (the bounds rule: photons are kept as far). */
static float march_reach(const struct media_job *mj, const struct medium *md, vec3 o, vec3 d)
{
    float t = exit_distance(mj, o, d), reach = photon_fog_reach(md, mj->scene_size);
    return reach > 0.0f ? t + reach : t;
}

/* March and beam in a homogeneous medium wherever a march is not needed: single
 * scattering from `points` points instead of a march, t stratified in an exponential
 * truncated to the segment (so the points lie inside it even in thin fog), NEE at each
 * (point_nee: an emissive triangle sampled by solid angle) weighted against one
 * equiangular sample toward a point light or a point on an area light as in VPT, times
 * Tr(t) / (points pdf(t)). After the first non-delta bounce (the final
 * gather's bounce and any segment after it) one point: these paths, spread over the
 * hemisphere, average the extra noise away. On camera segments when lights are picked one
 * at a time, CAMERA_POINTS points: a march's step takes one shadow ray per step (about 170
 * on cornell_fog's camera rays), while the equiangular sample carries the light's 1/d^2
 * peak and the rest of the in-scattering is smooth along the segment. Multiple
 * scattering: the beam, over one random piece of a long segment (below). */
static vec3 gather_segment(const struct render_job *job, const struct media_job *mj, const struct rngs *r,
                           uint32_t vertex, uint32_t depth, vec3 o, vec3 d, float len, uint32_t medium, vec3 chan,
                           float time01, uint32_t points, uint64_t *rays)
{
    const struct medium *md = &mj->cut[medium];
    vec3 L = medium_emission_integral(md, len);
    if (v3_is_black(md->sigma_s) || !(len > 0.0f) || !isfinite(len))
        return L;
    int nee;
    const uint32_t kmax = volume_photon_depth_max(job->scene->settings.max_depth, depth, &nee);
    float s = trunc_sigma(md), mass = trunc_mass(s, len), jitter = rnd(r, vertex, 11);
    struct flight_ctx fc = {o, d, len, 0.0f, chan, md, 1e-7f * mj->scene_size, FL_TRUNC, 1, 0.0f, (float)points, mass};
    if (nee && job->lights.num_entries > 0) {
        vec3 ss = v3(0, 0, 0);
        for (uint32_t k = 0; k < points; k++) {
            /* stratum k of the truncated exponential's CDF (one point: the plain sample) */
            fc.t = trunc_sample(s, mass, len, ((float)k + jitter) / (float)points);
            vec3 x = v3_add(o, v3_scale(d, fc.t));
            float u0, u1, u2;
            uint64_t skey = rng_mix64(r->key ^ (0x4753ull << 48) ^ vertex);
            if (k == 0) {
                u0 = rnd(r, vertex, 12), u1 = rnd(r, vertex, 13), u2 = rnd(r, vertex, 14);
            } else {
                uint64_t pk = rng_mix64(r->key ^ (0x4750ull << 48) ^ ((uint64_t)vertex << 24) ^ k);
                u0 = rng_uniform(pk, 0), u1 = rng_uniform(pk, 1), u2 = rng_uniform(pk, 2);
                skey = rng_mix64(skey ^ ((uint64_t)k << 32));
            }
            vec3 in = v3_mul(md->sigma_s, point_nee(job, x, v3_neg(d), medium, md->g, u0, u1, u2, time01, skey, rays,
                                                    &fc));
            ss = v3_add(ss, v3_scale(v3_mul(medium_transmittance(md, fc.t), in),
                                     1.0f / ((float)points * trunc_pdf(s, mass, len, fc.t))));
        }
        L = v3_add(L, equiangular(job, r, vertex, &fc, medium, time01, rays));
        L = v3_add(L, ss);
    }
    /* Multiple scattering keeps the beam (a one-point estimate, photons within r of a
     * single point, made the sample values heavy-tailed where photons are sparse). */
    if (kmax > 0 && mj->map) {
        /* The beam over one of `pieces` parts of the segment of equal transmittance mass,
         * picked at random, times `pieces`: the query's cost follows the length it walks,
         * and the in-scattered radiance varies slowly along a segment, so the pick adds
         * little noise. Segments shorter than BEAM_PIECE_RADII gather radii a piece take
         * the whole beam. */
        float rad = mj->map->radius, nf = rad > 0.0f ? floorf(len / (BEAM_PIECE_RADII * rad)) : 1.0f;
        uint32_t pieces = mj->map->beams || !(nf > 1.0f) ? 1u : nf < (float)BEAM_PIECES ? (uint32_t)nf : BEAM_PIECES;
        if (pieces > 1) {
            float u = rnd(r, vertex, 15) * (float)pieces;
            uint32_t k = u < (float)pieces ? (uint32_t)u : pieces - 1;
            float t0 = k == 0 ? 0.0f : trunc_sample(s, mass, len, (float)k / (float)pieces);
            float t1 = k + 1 == pieces ? len : trunc_sample(s, mass, len, (float)(k + 1) / (float)pieces);
            if (t1 > t0) {
                vec3 b = photon_map_beam(mj->map, v3_add(o, v3_scale(d, t0)), d, t1 - t0, md, NULL, kmax);
                L = v3_add(L, v3_scale(v3_mul(medium_transmittance(md, t0), b), (float)pieces));
            }
        } else {
            L = v3_add(L, photon_map_beam(mj->map, o, d, len, md, NULL, kmax));
            if (mj->map->beams)
                L = v3_add(L, photon_beams_estimate(mj->map->beams, o, d, len, md, NULL, kmax));
        }
    }
    return L;
}

vec3 media_glow_sample(vec3 c, float u1, float u2)
{
    float st, ct, sp, cp;
    sincos_2pi(0.25f * u1, &st, &ct); /* theta = (pi / 2) u1 */
    sincos_2pi(u2, &sp, &cp);
    vec3 t, b;
    v3_basis(c, &t, &b);
    return v3_normalize(v3_add(v3_scale(c, ct), v3_add(v3_scale(t, st * cp), v3_scale(b, st * sp))));
}

/* Below this sine the density stays at its value there (a finite pdf along c itself, whose
 * square the MIS weights take). */
#define GLOW_MIN_SIN 1e-12f

float media_glow_pdf(vec3 c, vec3 w)
{
    if (!(v3_dot(c, w) > 0.0f))
        return 0.0f;
    float s = v3_length(v3_cross(c, w)); /* sin(theta), exact near theta = 0 */
    return (float)(1.0 / (M_PI * M_PI)) / fmaxf(s, GLOW_MIN_SIN);
}

/* The final gather's bounce at a diffuse vertex of march or beam: the direction from a
 * mixture of cosine sampling and, where they apply, glow sampling toward each glowing light
 * on the vertex's side (media_job's glow; GLOW_SHARE in equal parts; media_glow_sample)
 * and, with GATHER_MEDIA_SHARE, toward the media: where they are grids toward their
 * density (grid_aim, in equal parts), else the cone toward their bounding sphere from a
 * vertex outside it. That is the light the media send back to the surface, from a small
 * bright solid angle (a cloud over a floor: docs/media.md, "Final gather"). Weighted by the
 * mixture's density (one-sample MIS, balance heuristic), which is also the bounce's pdf
 * for the MIS of NEE and emitters. */
#define GLOW_SHARE 0.25f
#define GATHER_MEDIA_SHARE 0.25f
struct gather_mix {
    const struct media_job *mj; /* its aims: toward each grid's density (then no cone) */
    vec3 p;                 /* the vertex */
    uint32_t n;
    vec3 c[MEDIA_GLOW_MAX]; /* unit directions from the vertex to the glowing lights */
    int cone;               /* the cone toward the media's bounding sphere: axis, cosine of its half-angle */
    vec3 cone_axis;
    float cone_cos;
    float share_cos, share_glow, share_media;
};

/* 1 when the vertex has a strategy besides cosine sampling. */
static int gather_mix_init(struct gather_mix *g, const struct media_job *mj, vec3 p, vec3 ng)
{
    g->mj = mj;
    g->p = p;
    g->n = 0;
    for (uint32_t k = 0; k < mj->num_glow; k++) {
        vec3 to = v3_sub(mj->glow[k], p);
        float d = v3_length(to);
        if (d > 0.0f && v3_dot(to, ng) > 0.0f)
            g->c[g->n++] = v3_scale(to, 1.0f / d);
    }
    g->cone = 0;
    if (mj->num_aims == 0 && mj->aim) { /* no grid: the cone, from outside the sphere, not wholly below the surface */
        vec3 to = v3_sub(mj->aim_center, p);
        float d = v3_length(to), sn = mj->aim_radius / d;
        if (d > mj->aim_radius && v3_dot(to, ng) > -mj->aim_radius) {
            g->cone_axis = v3_scale(to, 1.0f / d);
            g->cone_cos = sqrtf(fmaxf(0.0f, 1.0f - sn * sn));
            g->cone = g->cone_cos < 1.0f;
        }
    }
    g->share_glow = g->n > 0 ? GLOW_SHARE : 0.0f;
    g->share_media = g->cone || mj->num_aims > 0 ? GATHER_MEDIA_SHARE : 0.0f;
    g->share_cos = 1.0f - g->share_glow - g->share_media;
    return g->n > 0 || g->share_media > 0.0f;
}

/* The mixture's density at wi, given the cosine lobe's (material_eval's pdf). */
static float gather_mix_pdf(const struct gather_mix *g, float cos_pdf, vec3 wi)
{
    float p = g->share_cos * cos_pdf;
    if (g->n > 0) {
        float s = 0.0f;
        for (uint32_t k = 0; k < g->n; k++)
            s += media_glow_pdf(g->c[k], wi);
        p += g->share_glow * s / (float)g->n;
    }
    if (g->cone && v3_dot(wi, g->cone_axis) >= g->cone_cos)
        p += g->share_media / (2.0f * (float)M_PI * (1.0f - g->cone_cos));
    const uint32_t na = g->mj->num_aims;
    if (na > 0) {
        float s = 0.0f;
        for (uint32_t k = 0; k < na; k++)
            s += grid_aim_pdf(&g->mj->aims[k], g->p, wi);
        p += g->share_media * s / (float)na;
    }
    return p;
}

/* One bounce from the mixture (mat diffuse): u0 picks the strategy. */
static void gather_bounce(const struct gather_mix *g, const struct material *mat, vec3 ns, vec3 wo, int front, float u0,
                          float u1, float u2, float u3, struct bsdf_sample *bs)
{
    vec3 wi;
    if (u0 < g->share_cos) {
        material_sample(mat, ns, wo, front, u1, u2, bs);
        if (!(bs->pdf > 0.0f))
            return;
        wi = bs->wi;
    } else if (u0 < g->share_cos + g->share_glow) {
        float v = (u0 - g->share_cos) / g->share_glow * (float)g->n;
        uint32_t k = v < (float)g->n ? (uint32_t)v : g->n - 1;
        wi = media_glow_sample(g->c[k], u1, u2);
    } else if (g->mj->num_aims > 0) {
        const uint32_t na = g->mj->num_aims;
        float v = (u0 - g->share_cos - g->share_glow) / g->share_media * (float)na;
        uint32_t k = v < (float)na ? (uint32_t)v : na - 1;
        wi = grid_aim_sample(&g->mj->aims[k], g->p, fminf(v - (float)k, 0x1.fffffep-1f), u1, u2, u3);
    } else {
        wi = v3_cone_sample(g->cone_axis, g->cone_cos, u1, u2);
    }
    float pc;
    vec3 f = material_eval(mat, ns, wo, wi, front, &pc);
    float pdf = gather_mix_pdf(g, pc, wi);
    bs->wi = wi;
    bs->is_delta = 0;
    bs->transmitted = 0;
    bs->eta2 = 1.0f;
    bs->pdf = v3_is_black(f) || !(pdf > 0.0f) ? 0.0f : pdf;
    bs->weight = bs->pdf > 0.0f ? v3_scale(f, 1.0f / pdf) : v3(0, 0, 0);
}

/* The emission of the surface a ray along dir hit, MIS-weighted against NEE from the
 * vertex before (prev_p; its sampling pdf prev_pdf unless it was a delta bounce). */
static vec3 hit_emission(const struct render_job *job, const struct surface *s, vec3 dir, int prev_delta,
                         float prev_pdf, vec3 prev_p)
{
    if (s->light == LIGHT_NONE || !(v3_dot(s->ng, dir) < 0.0f))
        return v3(0, 0, 0);
    const struct scene *sc = job->scene;
    float w = 1.0f;
    if (!prev_delta)
        w = power_heuristic(prev_pdf, light_pdf(&job->lights, sc, s->light, prev_p, s->p, s->ng));
    return v3_scale(sc->materials[s->material].emission, w);
}

vec3 media_sample_path(const struct render_job *job, const struct sampler *smp, uint32_t px, uint32_t py, vec3 org,
                       vec3 dir, float time01, uint64_t *rays, int *hit_any)
{
    return media_sample_path_pass(job, 0, smp, px, py, org, dir, time01, NULL, 0, NULL, NULL, rays, hit_any);
}

/* march and beam: a homogeneous segment's transmittance to its end o + t d, over the exact
 * length from the segment's true start (a boundary point, not the offset origin o), in
 * the cut medium; t = INFINITY: nothing was hit. */
static vec3 segment_end_tr(const struct media_job *mj, uint32_t medium, vec3 seg_start, vec3 o, vec3 d, float t)
{
    float exact = t < INFINITY ? v3_length(v3_sub(v3_add(o, v3_scale(d, t)), seg_start)) : INFINITY;
    return medium_transmittance(&mj->cut[medium], exact);
}

vec3 media_direct_light(const struct render_job *job, uint32_t pass, vec3 org, vec3 dir, float time01, uint64_t *rays)
{
    const struct scene *sc = job->scene;
    const struct media_job *mj = render_job_pass_media(job, pass);
    const uint32_t medium = mj->camera_medium;
    struct accel_hit h;
    (*rays)++;
    if (!accel_intersect(&job->accel, org, dir, INFINITY, time01, &h))
        return medium == MEDIUM_NONE && sc->env ? light_env_radiance(&job->lights, sc, dir) : v3(0, 0, 0);
    struct surface s;
    surface_from_hit(&job->accel, &job->lights, org, dir, &h, time01, &s);
    if (s.light == LIGHT_NONE || media_is_interface(job->media, s.material))
        return v3(0, 0, 0);
    vec3 le = hit_emission(job, &s, dir, 1, 0.0f, org);
    if (medium == MEDIUM_NONE || v3_is_black(le))
        return le;
    /* The transmittance each method gives the camera segment's end (media_sample_path_pass). */
    if (mj->sm->method == MEDIA_VPT)
        return v3_mul(medium_transmittance(&mj->sm->media[medium], h.t), le);
    return v3_mul(segment_end_tr(mj, medium, org, org, dir, h.t), le);
}

vec3 media_sample_path_pass(const struct render_job *job, uint32_t pass, const struct sampler *smp, uint32_t px,
                            uint32_t py, vec3 org, vec3 dir, float time01, const struct accel_hit *first,
                            int first_found, const struct raydiff *camera_rd, vec3 *direct, uint64_t *rays,
                            int *hit_any)
{
    const struct scene *sc = job->scene;
    const struct media_job *mj = render_job_pass_media(job, pass); /* the pass's photon map */
    const struct scene_media *sm = mj->sm;
    const struct render_settings *rs = &sc->settings;
    struct rngs r;
    uint64_t pixel = (uint64_t)py * rs->width + px;
    /* The pass-local index would give every pixel only as many sequences as streams. */
    uint32_t sample = sampler_sample_id(smp);
    r.key = rng_mix64(smp->key ^ rng_mix64(smp->pixel_key ^ rng_key(rs->seed ^ 0x6d65646961ull, job->frame, pixel, sample)));
    /* vpt: the path is the volumetric path tracer's from here on: always with the vpt
     * method; with march and beam and path-traced indirect light, from the first diffuse
     * vertex's bounce on (the photon maps then serve the segments before it only). */
    int vpt = sm->method == MEDIA_VPT;
    const int path_indirect = !vpt && sm->indirect == MEDIA_INDIRECT_PATH;
    const int few_points = march_all_points(job);
    const uint32_t camera_points =
        !vpt && sm->method != MEDIA_MARCH_STEPS && !few_points && job->lights.num_entries > 0 ? CAMERA_POINTS : 0;
    uint32_t medium = mj->camera_medium;
    vec3 L = v3(0, 0, 0), beta = v3(1, 1, 1);
    float prev_pdf = 0.0f;
    vec3 prev_p = org;
    int prev_delta = 1;
    uint32_t depth = 0, crossings = 0, vertex = 0;
    int gathered = 0;       /* the final gather's bounce is taken: the next diffuse vertex looks up */
    int spread = 0;         /* a non-delta bounce was taken: segments take one point (gather_segment) */
    vec3 seg_start = org;   /* exact start of the segment (boundary point, not the offset origin) */
    /* Textures: the ray's differentials, carried as integrator.c carries them, and across
     * media boundaries and volume scattering (texshade.h); zero without the camera's. */
    struct raydiff rd;
    if (job->textured) {
        static const struct raydiff point;
        rd = camera_rd ? *camera_rd : point;
    }
    *hit_any = 0;
    if (direct)
        *direct = v3(0, 0, 0);
    for (;;) {
        struct accel_hit h;
        struct surface s;
        int s_ready = 0, emitted = 0;
        /* The camera segment's light seen straight along it goes to *direct (the caller averages it) */
        const int to_direct = direct && vertex == 0 && crossings == 0;
        (*rays)++;
        int hit;
        if (first) { /* the camera ray, traced by the caller */
            hit = first_found;
            if (hit)
                h = *first;
            first = NULL;
        } else {
            hit = accel_intersect(&job->accel, org, dir, INFINITY, time01, &h);
        }
        if (hit && vertex == 0 && crossings == 0)
            *hit_any = 1;
        if (medium != MEDIUM_NONE) {
            const struct medium *md = &sm->media[medium];
            if (vpt) {
                float tmax = hit ? h.t : INFINITY, t;
                vec3 w;
                L = v3_add(L, v3_mul(beta, medium_emission_segment(md, org, dir, tmax,
                                                                   rng_mix64(r.key ^ (0x454dull << 48) ^ vertex))));
                vec3 chan = beta;
                int scatter = medium_sample_flight(md, org, dir, tmax, chan, rng_mix64(r.key ^ (0x464cull << 48) ^ vertex), &t, &w);
                /* Homogeneous media: one equiangular sample toward a point light or a point on
                 * an emissive triangle per segment. */
                struct flight_ctx fc = {org, dir, hit ? h.t : exit_distance(mj, org, dir), t, chan, md,
                                        1e-7f * mj->scene_size, FL_FREE, 0, 0.0f, 1.0f, 0.0f};
                int equi = !md->grid && !v3_is_black(md->sigma_s) && job->lights.num_entries > 0 && depth < rs->max_depth;
                if (equi)
                    L = v3_add(L, v3_mul(beta, equiangular(job, &r, vertex, &fc, medium, time01, rays)));
                if (hit && !md->grid && job->lights.num_surface > 0) {
                    /* An emitter at the segment's end: its light times the segment's
                     * transmittance, the expected value of what the flight's pass-through
                     * (probability and weight) would give it; the surface below then adds
                     * no emission. Seen straight through a thin fog, the light otherwise
                     * flickers with the flight's choice (the brightest pixels' noise). */
                    surface_from_hit(&job->accel, &job->lights, org, dir, &h, time01, &s);
                    s_ready = 1;
                    if (!media_is_interface(job->media, s.material)) {
                        emitted = 1;
                        vec3 le = hit_emission(job, &s, dir, prev_delta, prev_pdf, prev_p);
                        if (to_direct)
                            *direct = v3_mul(medium_transmittance(md, h.t), le);
                        else if (!v3_is_black(le))
                            L = v3_add(L, v3_mul(v3_mul(beta, medium_transmittance(md, h.t)), le));
                    }
                }
                beta = v3_mul(beta, w);
                if (v3_is_black(beta) || !v3_is_finite(beta))
                    break;
                if (scatter) {
                    vec3 x = v3_add(org, v3_scale(dir, t));
                    if (++depth > rs->max_depth)
                        break;
                    L = v3_add(L, v3_mul(beta, scatter_nee(job, x, v3_neg(dir), medium, md->g, 0, rnd(&r, vertex, 2),
                                                           rnd(&r, vertex, 3), rnd(&r, vertex, 4), time01,
                                                           rng_mix64(r.key ^ (0x5348ull << 48) ^ vertex), rays, 1,
                                                           equi ? &fc : NULL)));
                    vec3 nd;
                    float ph = phase_hg_sample(dir, md->g, rnd(&r, vertex, 5), rnd(&r, vertex, 6), &nd);
                    if (depth >= 3) {
                        float q = fmaxf(0.05f, 1.0f - v3_max_component(beta));
                        if (rnd(&r, vertex, 7) < q)
                            break;
                        beta = v3_scale(beta, 1.0f / (1.0f - q));
                    }
                    if (job->textured)
                        texshade_scatter_volume(&rd, dir, t, nd);
                    prev_pdf = ph;
                    prev_p = x;
                    prev_delta = 0;
                    org = x;
                    seg_start = x;
                    dir = nd;
                    vertex++;
                    continue;
                }
            } else {
                const struct medium *mdc = &mj->cut[medium];
                float len = hit ? h.t : march_reach(mj, mdc, org, dir);
                vec3 seg_tr = v3(1, 1, 1);
                /* Points instead of a march (gather_segment): after a non-delta bounce, and
                 * on camera segments when lights are picked one at a time (the equiangular
                 * sample then takes the light's peak); `march` needs its steps (a photon
                 * lookup at each). */
                uint32_t points = spread ? 1u : camera_points;
                if (!md->grid && points > 0)
                    L = v3_add(L, v3_mul(beta, gather_segment(job, mj, &r, vertex, depth, org, dir, len, medium, beta,
                                                              time01, points, rays)));
                else
                    L = v3_add(L, v3_mul(beta, march_segment(job, mj, &r, vertex, depth, org, dir, len, medium, time01,
                                                             rays, &seg_tr)));
                beta = v3_mul(beta, md->grid ? seg_tr : segment_end_tr(mj, medium, seg_start, org, dir, hit ? h.t : INFINITY));
                if (v3_is_black(beta))
                    break;
            }
        }
        if (!hit) {
            /* Escaped: the environment light, weighted as an emitter hit below is. */
            if (to_direct && medium == MEDIUM_NONE) {
                if (sc->env)
                    *direct = light_env_radiance(&job->lights, sc, dir);
            } else if (sc->env && !v3_is_black(beta)) {
                float w = prev_delta ? 1.0f : power_heuristic(prev_pdf, light_env_pdf(&job->lights, sc, dir));
                L = v3_add(L, v3_mul(beta, v3_scale(light_env_radiance(&job->lights, sc, dir), w)));
            }
            break;
        }
        if (!s_ready)
            surface_from_hit(&job->accel, &job->lights, org, dir, &h, time01, &s);
        if (media_is_interface(job->media, s.material)) {
            if (++crossings > MAX_CROSSINGS)
                break;
            medium = media_after_crossing(job->media, &h, s.ng, dir);
            vec3 n = v3_dot(dir, s.ng) > 0.0f ? s.ng : v3_neg(s.ng);
            if (job->textured)
                texshade_cross(&rd, dir, h.t, s.ng);
            org = offset_ray_origin(v3_add(s.p, v3_scale(n, s.p_err)), n);
            seg_start = s.p;
            continue;
        }
        if (vertex == 0)
            *hit_any = 1;
        if (to_direct) {
            if (!emitted)
                *direct = v3_mul(beta, hit_emission(job, &s, dir, prev_delta, prev_pdf, prev_p));
        } else if (!emitted) {
            L = v3_add(L, v3_mul(beta, hit_emission(job, &s, dir, prev_delta, prev_pdf, prev_p)));
        }
        if (++depth > rs->max_depth)
            break;
        const struct material *mat = &sc->materials[s.material];
        struct material tex_mat;
        struct raydiff_hit dh;
        if (job->textured)
            mat = texshade_surface(job, org, dir, &h, time01, &rd, &s, mat, &tex_mat, &dh);
        if (material_is_anisotropic(mat)) /* the roughness axes follow the uv map */
            mat = material_with_axis(mat, surface_dpdu(&job->accel, org, dir, &h, time01), &tex_mat);
        vec3 wo = v3_neg(dir);
        int front = v3_dot(s.ng, wo) >= 0.0f;
        vec3 ng = front ? s.ng : v3_neg(s.ng);
        vec3 ns = v3_dot(s.ns, ng) < 0.0f ? v3_neg(s.ns) : s.ns;
        vec3 p_off = offset_ray_origin(v3_add(s.p, v3_scale(ng, s.p_err)), ng);
        /* Jensen's methods with a surface photon map: final gather. At the first diffuse
         * vertex the path takes one more diffuse bounce (cosine-sampled, marched through
         * the media like any segment); at the next diffuse vertex the indirect light is the
         * map's estimate and the path ends there, so that vertex's direct light is
         * next-event estimation's alone (full weight, no MIS partner). Looked up at the
         * first vertex directly, the map's noise shows as blotches. Without room for one
         * more vertex (max_depth) the path ends at the first vertex too; its lookup then
         * finds no photon short enough (max_depth bounds the light path as well). */
        const int diffuse_map = !vpt && !path_indirect && mj->map && mj->map->surface && mat->type == MATERIAL_DIFFUSE;
        const int surface_map = diffuse_map && (gathered || depth >= rs->max_depth);
        if (diffuse_map)
            gathered = 1;
        /* The gather's bounce toward glowing lights and the media too (gather_bounce): its
         * segment's equiangular sample toward a light in fog is ~ 1 / (the distance it
         * passes the light at), and a bright cloud seen from a floor fills a small solid
         * angle, both heavy-tailed under cosine sampling alone. */
        struct gather_mix mix;
        int mixed = diffuse_map && !surface_map && gather_mix_init(&mix, mj, s.p, ng);
        if (!vpt && few_points && !material_is_delta(mat)) {
            /* Jensen's methods, a few point lights: every one (no pick noise). */
            for (uint32_t li = 0; li < job->lights.num_entries; li++) {
                const struct light *l = &sc->lights[job->lights.entries[li].index];
                vec3 to = v3_sub(l->position, s.p);
                float d2 = v3_dot(to, to);
                if (!(d2 > 0.0f))
                    continue;
                float len = sqrtf(d2);
                vec3 wi = v3_scale(to, 1.0f / len);
                float bpdf;
                vec3 f = v3_dot(wi, ng) > 0.0f ? material_eval(mat, ns, wo, wi, front, &bpdf) : v3(0, 0, 0);
                vec3 rad = v3_scale(job->lights.entries[li].emission, light_spot_falloff_len(l, v3_neg(to), len) / d2);
                if (v3_is_black(f) || v3_is_black(rad))
                    continue;
                vec3 tr = media_shadow_transmittance(job->media, p_off, l->position, medium, time01,
                                                     rng_mix64(r.key ^ (0x5353ull << 48) ^ vertex ^ ((uint64_t)li << 32)), rays);
                L = v3_add(L, v3_mul(beta, v3_mul(v3_mul(f, rad), tr)));
            }
        } else if (job->lights.num_entries > 0 && !material_is_delta(mat)) {
            struct nee_sample n;
            if (nee_prepare(&job->lights, sc, mat, s.p, ns, ng, wo, front, 0, rnd(&r, vertex, 2), rnd(&r, vertex, 3), rnd(&r, vertex, 4), &n)) {
                vec3 tr = media_shadow_transmittance(job->media, p_off, n.target, medium, time01,
                                                     rng_mix64(r.key ^ (0x5353ull << 48) ^ vertex), rays);
                if (!v3_is_black(tr)) {
                    float bp = n.bsdf_pdf;
                    if (mixed && !n.ls.is_delta)
                        bp = gather_mix_pdf(&mix, bp, v3_normalize(v3_sub(n.ls.p, s.p)));
                    float w = n.ls.is_delta || surface_map ? 1.0f : power_heuristic(n.ls.pdf, bp);
                    L = v3_add(L, v3_mul(beta, v3_scale(v3_mul(v3_mul(n.f, n.ls.radiance), tr), w / n.ls.pdf)));
                }
            }
        }
        if (surface_map) {
            /* photons of at most max_depth - depth events: depth counts this vertex */
            vec3 e = photon_map_surface(mj->map, s.p, ng, rs->max_depth - depth);
            L = v3_add(L, v3_mul(beta, v3_mul(mat->albedo, v3_scale(e, (float)(1.0 / M_PI)))));
            break;
        }
        struct bsdf_sample bs;
        if (mixed)
            gather_bounce(&mix, mat, ns, wo, front, rnd(&r, vertex, 0), rnd(&r, vertex, 5), rnd(&r, vertex, 6),
                          rnd(&r, vertex, 1), &bs);
        else
            material_sample(mat, ns, wo, front, rnd(&r, vertex, 5), rnd(&r, vertex, 6), &bs);
        float side = v3_dot(bs.wi, ng);
        if (bs.pdf <= 0.0f || (bs.transmitted ? side >= 0.0f : side <= 0.0f))
            break;
        beta = v3_mul(beta, bs.weight);
        if (depth >= 3) {
            float q = fmaxf(0.05f, 1.0f - v3_max_component(beta));
            if (rnd(&r, vertex, 7) < q)
                break;
            beta = v3_scale(beta, 1.0f / (1.0f - q));
        }
        if (v3_is_black(beta))
            break;
        if (job->textured)
            texshade_scatter(&rd, mat, &bs, front, dir, ns, &dh);
        prev_pdf = bs.pdf;
        prev_p = s.p;
        prev_delta = bs.is_delta || bs.transmitted; /* NEE samples wo's side only (surface.h) */
        spread |= !bs.is_delta;
        /* Path-traced indirect light: after a non-delta bounce VPT covers all the light
         * arriving at this vertex (its medium's in-scattering by free flight, surfaces by
         * BSDF sampling with MIS, as the NEE above weighted it), so nothing of the photon
         * maps may join it. The camera segments before this vertex keep march and beam:
         * their in-scattering (single scattering and the photons' multiple scattering) is
         * light that left the path there, which VPT's part never counts. depth has
         * counted this path's surface vertices and goes on counting VPT's events. */
        vpt |= path_indirect && !bs.is_delta;
        if (bs.transmitted) {
            medium = media_after_crossing(job->media, &h, s.ng, dir);
            org = offset_ray_origin(v3_sub(s.p, v3_scale(ng, s.p_err)), v3_neg(ng));
        } else {
            org = p_off;
        }
        dir = bs.wi;
        seg_start = s.p;
        vertex++;
    }
    return L;
}
