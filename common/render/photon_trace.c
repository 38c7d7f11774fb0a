/* Photon tracing (see photon_trace.h): photons leave the lights, are traced through media
 * (media_track.c for boundaries) and off surfaces (surface.c), and are stored in per-block
 * lists that photon_map.c serialises. Photon i draws only from random numbers keyed by
 * (seed, frame, i), so the map is a pure function of the scene. Called by the master. */
#include "render/photon_trace.h"
#include "scene/envmap.h"
#include "base/log.h"
#include "base/rng.h"
#include "render/media_track.h"
#include "render/photon_map.h"
#include "render/photon_beams.h"
#include "render/render_job.h"
#include "render/surface.h"
#include "render/texshade.h"
#include "scene/grid.h"
#include "scene/material.h"
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define PM_BLOCK 1024           /* photon indices per work unit */
#define SALT_PHOTON 0x70686f746f6eull
#define SALT_SPLIT 0x73706c6974ull
/* Splitting heavy photons where they meet a bounded medium (split_count): a photon whose
 * power is over PHOTON_SPLIT_MIN times the reference (trace_ctx.split_ref) splits. */
#define PHOTON_SPLIT_MIN 2.0f
/* Photons traced to find the reference (split_reference). */
#define SPLIT_PILOT 1024u

struct trace_ctx {
    const struct render_job *job;
    const struct media_job *mj;
    uint64_t seed;
    uint64_t emitted;
    float photon_scale;     /* 1 / emitted */
    struct point_emit *point; /* per light entry: a point or spot light's emission constants */
    float split_ref;        /* a typical photon's power in the media (max component): walk splits
                             * heavier ones; 0 = never */
    uint32_t split_max;     /* volume.photon_split: most walkers per split (1: none) */
    float *pilot;           /* split_reference's pilot: powers recorded instead of splitting */
    uint32_t *pilot_n;
    uint32_t num_blocks;
    _Atomic uint32_t next_block;
    struct photon_list *blocks;     /* volume photons per block of indices */
    struct photon_list *surface;    /* surface photons per block (NULL: none kept) */
    struct photon_beam_list *beams; /* the beams method: photon beams per block (NULL: points only) */
    vec3 keep_lo, keep_hi;  /* photons are stored inside this box (the bounds rule) */
    int reach;              /* photons can interact only inside reach_lo..hi (photon_interaction_bounds) */
    vec3 reach_lo, reach_hi;
};

/* Photons of a point light sent into the cone toward the media. The others carry the light
 * that reaches the media after a surface bounce, each with (AIM_SHARE 4 pi / cone + 1 -
 * AIM_SHARE) / (1 - AIM_SHARE) times an aimed photon's power: too few and heavy when most
 * are aimed (docs/media.md, "Aiming point and spot lights": on the smoke 1/4 had 0.72x the
 * error of 3/4 at equal time, 1/2 0.82x, none 0.80x). */
#define AIM_SHARE 0.25f
/* Sky photons aimed at the media's bounding sphere. The rest cross the whole scene: they
 * carry the light that reaches the media after a surface bounce (and the surface map's),
 * each with power 1 / (1 - share) of an unaimed one. On a scattering sphere over a floor
 * under a uniform sky (test_envmap.c's scene, 100,000 photons, 24 seeds) the beam
 * estimate's RMSE against VPT was, for shares 0 / 0.5 / 0.75: 0.054 / 0.040 / 0.053
 * with a floor of albedo 0.5, 0.052 / 0.011 / 0.010 with a black one. */
#define ENV_AIM_SHARE 0.5f

int photon_interaction_bounds(const struct render_job *job, vec3 *lo_out, vec3 *hi_out)
{
    const struct scene_media *sm = job->scene->media;
    if (sm && sm->fog != MEDIUM_NONE && !sm->media[sm->fog].grid)
        return 0; /* a homogeneous fog fills all space */
    struct RTCBounds b;
    vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
    if (job->accel.has_motion) { /* the scene at any time of the shutter lies within both ends' bounds */
        struct RTCLinearBounds lb;
        rtcGetSceneLinearBounds(job->accel.scene, &lb);
        lo = v3(fminf(lb.bounds0.lower_x, lb.bounds1.lower_x), fminf(lb.bounds0.lower_y, lb.bounds1.lower_y),
                fminf(lb.bounds0.lower_z, lb.bounds1.lower_z));
        hi = v3(fmaxf(lb.bounds0.upper_x, lb.bounds1.upper_x), fmaxf(lb.bounds0.upper_y, lb.bounds1.upper_y),
                fmaxf(lb.bounds0.upper_z, lb.bounds1.upper_z));
    } else {
        rtcGetSceneBounds(job->accel.scene, &b);
        lo = v3(b.lower_x, b.lower_y, b.lower_z), hi = v3(b.upper_x, b.upper_y, b.upper_z);
    }
    media_grids_grow_box(sm, &lo, &hi);
    if (!(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z) || !v3_is_finite(lo) || !v3_is_finite(hi))
        return 0;
    float pad = 1e-3f * fmaxf(v3_length(v3_sub(hi, lo)), v3_max_abs(lo) + v3_max_abs(hi));
    *lo_out = v3_sub(lo, v3(pad, pad, pad));
    *hi_out = v3_add(hi, v3(pad, pad, pad));
    return 1;
}

float photon_fog_reach(const struct medium *md, float scene_size)
{
    if (md->grid)
        return 0.0f;
    float smin = INFINITY;
    const float st[3] = {md->sigma_t.x, md->sigma_t.y, md->sigma_t.z};
    for (int c = 0; c < 3; c++)
        if (st[c] > 0.0f)
            smin = fminf(smin, st[c]);
    /* A channel with sigma_t = 0 neither scatters nor absorbs: nothing to gather there. */
    return isfinite(smin) ? fminf(-logf(PHOTON_REACH_EPS) / smin, PHOTON_REACH_MAX * scene_size) : 0.0f;
}

/* The bounds rule: photons go wherever their walk takes them (one that leaves the scene's
 * bounds in a fog can scatter back), and are stored where camera rays can gather them:
 * the bounds, grown by how far march and beam follow a ray past them in the fog
 * (photon_fog_reach) and by the gather radius. */
static int outside_keep(const struct trace_ctx *tc, vec3 p)
{
    return !(p.x >= tc->keep_lo.x && p.y >= tc->keep_lo.y && p.z >= tc->keep_lo.z && p.x <= tc->keep_hi.x &&
             p.y <= tc->keep_hi.y && p.z <= tc->keep_hi.z);
}

static vec3 cosine_dir(vec3 n, float u1, float u2)
{
    float r = sqrtf(u1), sp, cp;
    sincos_2pi(u2, &sp, &cp);
    vec3 t, b;
    v3_basis(n, &t, &b);
    return v3_normalize(v3_add(v3_add(v3_scale(t, r * cp), v3_scale(b, r * sp)), v3_scale(n, sqrtf(f_max(0.0f, 1.0f - u1)))));
}

/* What a point or spot light's photons share (trace_ctx_start): its own emission's axis
 * and cone, the cone toward the media's bounding sphere (cos_aim 2: none), and the axes
 * on which it lies outside the interaction box's slab (side +-1 on them, 0 else; fold 2^m). */
struct point_emit {
    vec3 axis, aim_axis;
    float cos_max, cos_aim, fold;
    float side[3];
};

static void point_emit_init(struct point_emit *pe, const struct trace_ctx *tc, const struct light *l)
{
    pe->cos_max = l->type == LIGHT_SPOT ? l->cos_outer : -1.0f;
    pe->axis = l->type == LIGHT_SPOT ? l->direction : v3(0, 0, 1);
    pe->cos_aim = 2.0f;
    pe->aim_axis = pe->axis;
    if (tc->mj->aim) { /* point lights and the sky aim photons at the media's bounding sphere */
        vec3 to = v3_sub(tc->mj->aim_center, l->position);
        float dist = v3_length(to);
        if (dist > tc->mj->aim_radius) {
            pe->aim_axis = v3_scale(to, 1.0f / dist);
            float s2 = (tc->mj->aim_radius / dist) * (tc->mj->aim_radius / dist);
            pe->cos_aim = sqrtf(fmaxf(0.0f, 1.0f - s2));
        }
    }
    /* A point light outside the slab of the interaction box on an axis sends nothing away
     * from it: its own emission is folded onto the side that faces the slab on each such
     * axis (m axes: pdf 2^m / 4 pi), and photons that would fly off into empty space are
     * not traced at all. */
    pe->side[0] = pe->side[1] = pe->side[2] = 0.0f;
    pe->fold = 1.0f;
    if (tc->reach && l->type != LIGHT_SPOT) {
        const float p[3] = {l->position.x, l->position.y, l->position.z};
        const float lo[3] = {tc->reach_lo.x, tc->reach_lo.y, tc->reach_lo.z};
        const float hi[3] = {tc->reach_hi.x, tc->reach_hi.y, tc->reach_hi.z};
        for (int a = 0; a < 3; a++)
            if (p[a] < lo[a] || p[a] > hi[a]) {
                pe->side[a] = p[a] < lo[a] ? 1.0f : -1.0f;
                pe->fold *= 2.0f;
            }
    }
}

/* Emits photon `index`: origin, direction, power and the medium it starts in. 0 = none. */
static int emit(const struct trace_ctx *tc, uint64_t key, vec3 *o, vec3 *d, vec3 *power, uint32_t *medium)
{
    const struct render_job *job = tc->job;
    const struct scene *sc = job->scene;
    const struct light_table *lt = &job->lights;
    uint32_t i = light_pick(lt, rng_uniform(key, 0));
    const struct light_entry *e = &lt->entries[i];
    float pick = lt->pick_pdf[i];
    if (!(pick > 0.0f))
        return 0;
    float u1 = rng_uniform(key, 1), u2 = rng_uniform(key, 2), u3 = rng_uniform(key, 3), u4 = rng_uniform(key, 4);
    *medium = tc->mj->light_medium[i];
    switch (e->kind) {
    case LK_POINT: {
        /* A mixture: the light's own emission (sphere or spot cone), and, when the light
         * is outside the media's bounding sphere, the cone toward it with share
         * AIM_SHARE. Power is divided by the mixture's pdf, so nothing is biased. */
        const struct light *l = &sc->lights[e->index];
        const struct point_emit *pe = &tc->point[i];
        const float cos_max = pe->cos_max, cos_aim = pe->cos_aim, fold = pe->fold, *side = pe->side;
        const vec3 axis = pe->axis, aim_axis = pe->aim_axis;
        int aimed = cos_aim < 1.0f && rng_uniform(key, 5) < AIM_SHARE;
        *d = v3_cone_sample(aimed ? aim_axis : axis, aimed ? cos_aim : cos_max, u1, u2);
        if (!aimed && fold > 1.0f)
            *d = v3(side[0] != 0.0f ? side[0] * fabsf(d->x) : d->x, side[1] != 0.0f ? side[1] * fabsf(d->y) : d->y,
                    side[2] != 0.0f ? side[2] * fabsf(d->z) : d->z);
        *o = l->position;
        int facing = d->x * side[0] >= 0.0f && d->y * side[1] >= 0.0f && d->z * side[2] >= 0.0f;
        float pdf_own = (l->type != LIGHT_SPOT || v3_dot(*d, axis) >= cos_max) && facing
                            ? fold / (2.0f * (float)M_PI * (1.0f - cos_max))
                            : 0.0f;
        float pdf = pdf_own;
        if (cos_aim < 1.0f) {
            float pdf_aim = v3_dot(*d, aim_axis) >= cos_aim ? 1.0f / (2.0f * (float)M_PI * (1.0f - cos_aim)) : 0.0f;
            pdf = AIM_SHARE * pdf_aim + (1.0f - AIM_SHARE) * pdf_own;
        }
        if (!(pdf > 0.0f))
            return 0;
        *power = v3_scale(e->emission, light_spot_falloff(l, *d) / (pdf * pick) * tc->photon_scale);
        return 1;
    }
    case LK_TRIANGLE: {
        const struct mesh *m = &sc->meshes[e->index];
        const uint32_t *idx = &m->indices[3 * e->prim];
        const float *pa = &m->positions[3 * idx[0]], *pb = &m->positions[3 * idx[1]], *pc = &m->positions[3 * idx[2]];
        vec3 a = v3(pa[0], pa[1], pa[2]), bb = v3(pb[0], pb[1], pb[2]), c = v3(pc[0], pc[1], pc[2]);
        float su = sqrtf(u1), b0 = 1.0f - su, b1 = u2 * su;
        vec3 p = v3_add(v3_add(v3_scale(a, b0), v3_scale(bb, b1)), v3_scale(c, 1.0f - b0 - b1));
        vec3 n = v3_normalize(v3_cross(v3_sub(bb, a), v3_sub(c, a)));
        *o = offset_ray_origin(p, n);
        *d = cosine_dir(n, u3, u4);
        *power = v3_scale(e->emission, (float)M_PI * e->area / pick * tc->photon_scale);
        return 1;
    }
    case LK_SPHERE: {
        const struct sphere *sp = &sc->spheres[e->index];
        float z = 1.0f - 2.0f * u1, r = sqrtf(f_max(0.0f, 1.0f - z * z)), s, co;
        sincos_2pi(u2, &s, &co);
        vec3 n = v3(r * co, r * s, z);
        vec3 p = v3_add(sp->center, v3_scale(n, sp->radius));
        *o = offset_ray_origin(v3_add(p, v3_scale(n, (v3_max_abs(sp->center) + sp->radius) * 0x1p-21f)), n);
        *d = cosine_dir(n, u3, u4);
        *power = v3_scale(e->emission, (float)M_PI * e->area / pick * tc->photon_scale);
        return 1;
    }
    case LK_ENV: {
        /* A line from the sky across the scene's bounding sphere (envmap_emit); when media
         * have bounds (media_job's aim), ENV_AIM_SHARE of the lines cross the media's bounding
         * sphere instead. Unbiased: the power is divided by the mixture's density. */
        const float u[5] = {u1, u2, u3, u4, rng_uniform(key, 5)};
        vec3 flux = envmap_emit(sc->env, lt->env_center, lt->env_radius, tc->mj->aim_center, tc->mj->aim_radius,
                                tc->mj->aim ? ENV_AIM_SHARE : 0.0f, u, o, d);
        *power = v3_scale(flux, tc->photon_scale / pick);
        return !v3_is_black(*power);
    }
    }
    return 0;
}

static uint64_t photon_key(const struct trace_ctx *tc, uint64_t index)
{
    return rng_mix64(rng_key(tc->seed ^ SALT_PHOTON, tc->job->frame, index, 0));
}

/* What emission reads of a pass's context: the job, its seed, each photon's share of the
 * lights' power (1 / emitted) and the aiming sphere. */
static void trace_ctx_start(struct trace_ctx *tc, const struct render_job *job, uint64_t seed, uint64_t emitted)
{
    memset(tc, 0, sizeof *tc);
    tc->job = job;
    tc->mj = job->media;
    tc->seed = seed;
    tc->emitted = emitted;
    tc->photon_scale = emitted ? (float)(1.0 / (double)emitted) : 0.0f;
    tc->reach = photon_interaction_bounds(job, &tc->reach_lo, &tc->reach_hi);
    const struct light_table *lt = &job->lights;
    tc->point = mem_calloc(lt->num_entries ? lt->num_entries : 1, sizeof *tc->point);
    for (uint32_t i = 0; i < lt->num_entries; i++)
        if (lt->entries[i].kind == LK_POINT)
            point_emit_init(&tc->point[i], tc, &job->scene->lights[lt->entries[i].index]);
}

static void trace_ctx_end(struct trace_ctx *tc)
{
    free(tc->point);
    tc->point = NULL;
}

void photon_trace_emit(const struct render_job *job, uint64_t seed, uint64_t first, uint32_t n, struct photon_emitted *out)
{
    struct trace_ctx tc;
    trace_ctx_start(&tc, job, seed, n);
    for (uint32_t k = 0; k < n; k++) {
        uint32_t medium;
        struct photon_emitted *pe = &out[k];
        if (job->lights.num_entries == 0 || !emit(&tc, photon_key(&tc, first + k), &pe->o, &pe->d, &pe->power, &medium))
            pe->o = pe->d = pe->power = v3(0, 0, 0);
    }
    trace_ctx_end(&tc);
}

/* depth: the events (scatterings, surface bounces) before the photon arrived at p;
 * density_rel: in a grid, the density at p over the grid's maximum (the power is then
 * divided by the density: photon_codec.h), else 1. */
static void store(struct photon_list *l, vec3 p, vec3 d, vec3 power, uint32_t depth, float density_rel)
{
    if (!v3_is_finite(power) || v3_is_black(power))
        return;
    mem_grow((void **)&l->a, &l->cap, (size_t)l->n + 1, sizeof *l->a);
    struct photon *ph = &l->a[l->n++];
    ph->p[0] = p.x, ph->p[1] = p.y, ph->p[2] = p.z;
    photon_rgbe_encode(power, ph->rgbe);
    ph->dir = photon_dir_encode(d);
    ph->depth = photon_depth_word(depth, density_rel); /* depth < media_max_photon_depth <= PHOTON_DEPTH_MAX */
}

/* A default photon bound (media_max_photon_depth: the render's max_depth) fits a photon's depth. */
_Static_assert(SCENE_MAX_DEPTH <= PHOTON_DEPTH_MAX, "max_depth bounds photon paths: SCENE_MAX_DEPTH <= PHOTON_DEPTH_MAX");

/* A photon in flight: where it is, where it goes, its power and random numbers. */
struct walker {
    uint64_t key;
    vec3 o, d, power;
    uint32_t medium, depth, crossings;
    int indirect; /* any interaction since the light */
    uint32_t split_n; /* 0: a photon as emitted (it may split); n > 1: one of n walkers of a split
                       * photon, still in its medium; 1: such a walker past it */
};

static void walk(const struct trace_ctx *tc, struct walker w0, float time01, struct photon_list *vol,
                 struct photon_list *surf, struct photon_beam_list *beams);

/* Traces photon `index`: volume photons into vol; when surf is non-NULL, photons arriving
 * at diffuse surfaces after any interaction into surf. */
static void trace_photon(const struct trace_ctx *tc, uint64_t index, struct photon_list *vol,
                         struct photon_list *surf, struct photon_beam_list *beams)
{
    const struct render_job *job = tc->job;
    struct walker w = {.key = photon_key(tc, index)};
    if (!emit(tc, w.key, &w.o, &w.d, &w.power, &w.medium) || v3_is_black(w.power))
        return;
    /* Moving geometry: each photon lives at one time of the frame's shutter, drawn as the
     * camera draws its rays' times, so the map averages the shutter as the image does. */
    const float time01 = job->accel.has_motion ? camera_shutter_warp(&job->camera, rng_uniform(w.key, 6)) : 0.0f;
    walk(tc, w, time01, vol, surf, beams);
}

/* How many walkers a photon of `power` about to fly along o + t d, t < tmax, in medium md
 * goes on as: 1 unless the medium is bounded (a grid, or not the fog) and the ray crosses
 * it, and the photon is over PHOTON_SPLIT_MIN times the reference; then its power over
 * the reference times a bound on its chance to scatter on that flight (walkers that cross
 * a thin medium unscattered only cost: 1 - exp(-tau), tau from sigma_t's largest channel
 * at the grid's largest density over the part of the ray in the medium), rounded up, at
 * most split_max. In the pilot (tc->pilot) the power of the photon's first such flight is
 * recorded instead and 0 returned: the pilot has what it traced the photon for. *clip gets
 * the ray's medium_clip where it was taken (else clip->hit stays -1). */
static uint32_t split_count(const struct trace_ctx *tc, const struct medium *md, uint32_t medium, vec3 o, vec3 d,
                            float tmax, vec3 power, struct medium_clip_memo *clip)
{
    float heavy = tc->split_ref > 0.0f ? v3_max_component(power) / tc->split_ref : 0.0f;
    if (tc->split_max <= 1 || (!tc->pilot && !(heavy > PHOTON_SPLIT_MIN)) ||
        !(md->grid || medium != tc->job->scene->media->fog))
        return 1;
    clip->hit = medium_clip(md, o, d, tmax, &clip->t0, &clip->t1); /* the flight reads it too */
    if (!clip->hit)
        return 1;
    const float k0 = clip->t0, k1 = clip->t1;
    if (tc->pilot) {
        if (*tc->pilot_n < SPLIT_PILOT)
            tc->pilot[(*tc->pilot_n)++] = v3_max_component(power);
        return 0;
    }
    float tau = v3_max_component(md->sigma_t) * (md->grid ? md->grid->max_density : 1.0f) * (k1 - k0);
    float want = heavy * (tau < 30.0f ? -expm1f(-tau) : 1.0f);
    return want < (float)tc->split_max ? (uint32_t)ceilf(want) : tc->split_max;
}

static void walk(const struct trace_ctx *tc, struct walker w0, float time01, struct photon_list *vol,
                 struct photon_list *surf, struct photon_beam_list *beams)
{
    const struct render_job *job = tc->job;
    const struct scene *sc = job->scene;
    const struct scene_media *sm = sc->media;
    const uint64_t key = w0.key;
    vec3 o = w0.o, d = w0.d, power = w0.power;
    uint32_t medium = w0.medium, crossings = w0.crossings, split_n = w0.split_n;
    int indirect = w0.indirect;
    const uint32_t max_events = media_max_photon_depth(sm, sc->settings.max_depth);
    for (uint32_t depth = w0.depth; depth < max_events;) {
        uint32_t dim = 8 + 8 * depth;
        struct accel_hit h;
        int hit = accel_intersect(&job->accel, o, d, INFINITY, time01, &h);
        if (medium != MEDIUM_NONE) {
            const struct medium *md = &sm->media[medium];
            /* A heavy photon about to cross a bounded medium goes on as n walkers of 1/n its
             * power along the same ray, each with its own random numbers from here
             * (split_count; docs/media.md, "Splitting heavy photons"). */
            struct medium_clip_memo clip = {.hit = -1};
            uint32_t n = split_n == 0 ? split_count(tc, md, medium, o, d, hit ? h.t : INFINITY, power, &clip) : 1u;
            if (n == 0)
                return; /* the pilot: its power is recorded, the rest of its path is not wanted */
            if (n > 1) {
                struct walker c = {.o = o, .d = d, .power = v3_scale(power, 1.0f / (float)n), .medium = medium,
                                   .depth = depth, .crossings = crossings, .indirect = indirect, .split_n = n};
                for (uint32_t k = 0; k < n; k++) {
                    c.key = rng_mix64(key ^ SALT_SPLIT ^ ((uint64_t)(k + 1) << 40) ^ depth);
                    walk(tc, c, time01, vol, surf, beams);
                }
                return;
            }
            float t;
            vec3 w;
            int scatter = medium_sample_flight_clip(md, o, d, hit ? h.t : INFINITY, clip.hit >= 0 ? &clip : NULL, power,
                                                    rng_mix64(key ^ ((uint64_t)dim << 32)), &t, &w);
            vec3 before = power;
            power = v3_mul(power, w);
            /* The beams method in a grey medium (the flight's length then has P(length > v)
             * = Tr(v) on every channel): the flight as a short beam with the power it
             * started with, over the part inside the medium's occupied box and the bounds
             * rule's box; other media keep points. */
            int as_beam = beams && md->sigma_t.x == md->sigma_t.y && md->sigma_t.x == md->sigma_t.z;
            if (as_beam && indirect) {
                float c0, c1;
                if (medium_clip(md, o, d, t, &c0, &c1) && v3_clip_box(o, d, tc->keep_lo, tc->keep_hi, &c0, &c1) &&
                    c0 < c1 && c1 < INFINITY)
                    photon_beam_store(beams, v3_add(o, v3_scale(d, c0)), v3_add(o, v3_scale(d, c1)), before, depth);
            }
            if (scatter) {
                vec3 x = v3_add(o, v3_scale(d, t));
                if (indirect && !as_beam && !outside_keep(tc, x)) {
                    /* In a grid the photon carries power / density: an estimate multiplies by
                     * the density where it is taken, so that its kernel blurs the arriving
                     * light, not the grid's edges (docs/media.md, "Photons in grids"). */
                    float rho = md->grid ? grid_density(md->grid, x) : 1.0f;
                    if (rho > 0.0f)
                        store(vol, x, d, md->grid ? v3_scale(power, 1.0f / rho) : power, depth,
                              md->grid ? rho / md->grid->max_density : 1.0f);
                }
                /* Russian roulette keeps the power of survivors near what it was. */
                float q = f_min(1.0f, v3_max_component(power) / f_max(v3_max_component(before), 1e-30f));
                if (!(q > 0.0f) || rng_uniform(key, dim + 2) >= q)
                    return;
                power = v3_scale(power, 1.0f / q);
                vec3 nd;
                phase_hg_sample(d, md->g, rng_uniform(key, dim + 3), rng_uniform(key, dim + 4), &nd);
                o = x;
                d = nd;
                indirect = 1;
                depth++;
                continue;
            }
        }
        if (!hit || v3_is_black(power))
            return;
        struct surface s;
        surface_from_hit(&job->accel, &job->lights, o, d, &h, time01, &s);
        /* A split photon's walker leaving the medium (its first surface, an interface
         * included): Russian roulette, one in n goes on with n times the power, so the
         * path beyond costs what the photon's would have. */
        if (split_n > 1) {
            if (rng_uniform(key, dim + 1) * (float)split_n >= 1.0f)
                return;
            power = v3_scale(power, (float)split_n);
            split_n = 1;
        }
        if (media_is_interface(tc->mj, s.material)) {
            if (++crossings > 256)
                return;
            medium = media_after_crossing(tc->mj, &h, s.ng, d);
            vec3 nn = v3_dot(s.ng, d) > 0.0f ? s.ng : v3_neg(s.ng);
            o = offset_ray_origin(v3_add(s.p, v3_scale(nn, s.p_err)), nn);
            continue;
        }
        const struct material *mat = &sc->materials[s.material];
        struct material tex_mat; /* textures: point lookups, and s.ns bumped (texshade.h) */
        mat = texshade_surface(job, o, d, &h, time01, NULL, &s, mat, &tex_mat, NULL);
        if (material_is_anisotropic(mat)) /* the roughness axes follow the uv map */
            mat = material_with_axis(mat, surface_dpdu(&job->accel, o, d, &h, time01), &tex_mat);
        /* Light reaching a diffuse surface after an interaction: its indirect light (what
         * arrives straight from a light, next-event estimation computes). */
        if (surf && indirect && mat->type == MATERIAL_DIFFUSE && !v3_is_black(mat->albedo))
            store(surf, s.p, d, power, depth, 1.0f);
        vec3 wo = v3_neg(d);
        int front = v3_dot(s.ng, wo) >= 0.0f;
        vec3 ng = front ? s.ng : v3_neg(s.ng);
        vec3 ns = v3_dot(s.ns, ng) < 0.0f ? v3_neg(s.ns) : s.ns;
        struct bsdf_sample bs;
        material_sample(mat, ns, wo, front, rng_uniform(key, dim + 5), rng_uniform(key, dim + 6), &bs);
        float side = v3_dot(bs.wi, ng);
        if (bs.pdf <= 0.0f || (bs.transmitted ? side >= 0.0f : side <= 0.0f))
            return;
        /* Flux crosses an index change unscaled (the 1/eta^2 of bs.weight is for radiance). */
        vec3 w = bs.transmitted && bs.is_delta ? mat->transmittance : v3_scale(bs.weight, 1.0f / bs.eta2);
        float q = f_min(1.0f, v3_max_component(w));
        if (!(q > 0.0f) || rng_uniform(key, dim + 7) >= q)
            return;
        power = v3_scale(v3_mul(power, w), 1.0f / q);
        if (bs.transmitted) {
            medium = media_after_crossing(tc->mj, &h, s.ng, d);
            o = offset_ray_origin(v3_sub(s.p, v3_scale(ng, s.p_err)), v3_neg(ng));
        } else {
            o = offset_ray_origin(v3_add(s.p, v3_scale(ng, s.p_err)), ng);
        }
        d = bs.wi;
        indirect = 1;
        depth++;
    }
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* The splitting's reference: the median power (largest component) of the photons as they
 * first fly through a bounded medium, over the pass's first SPLIT_PILOT photons traced
 * alone up to that flight (their photons thrown away), so the same for any threads. On the smoke that is
 * an aimed photon's power; a photon heavier than PHOTON_SPLIT_MIN times it splits. 0
 * (no splitting) when fewer than 16 of them reach such a medium. */
static float split_reference(struct trace_ctx *tc)
{
    float p[SPLIT_PILOT];
    uint32_t m = 0, n = tc->emitted < SPLIT_PILOT ? (uint32_t)tc->emitted : SPLIT_PILOT;
    struct photon_list vol = {0};
    tc->pilot = p;
    tc->pilot_n = &m;
    for (uint32_t k = 0; k < n; k++) {
        trace_photon(tc, k, &vol, NULL, NULL);
        vol.n = 0;
    }
    tc->pilot = NULL;
    tc->pilot_n = NULL;
    free(vol.a);
    if (m < 16)
        return 0.0f;
    qsort(p, m, sizeof *p, cmp_float);
    return p[m / 2];
}

static atomic_int stop_requested;

void photon_trace_request_stop(void)
{
    atomic_store_explicit(&stop_requested, 1, memory_order_relaxed);
}

static int stopping(void)
{
    return atomic_load_explicit(&stop_requested, memory_order_relaxed) != 0;
}

static void *trace_thread(void *arg)
{
    struct trace_ctx *tc = arg;
    /* The stop flag is polled per block and per photon: a pass stops within one photon. */
    while (!stopping()) {
        uint32_t b = atomic_fetch_add(&tc->next_block, 1);
        if (b >= tc->num_blocks)
            break;
        uint64_t first = (uint64_t)b * PM_BLOCK, last = first + PM_BLOCK;
        last = last < tc->emitted ? last : tc->emitted;
        for (uint64_t i = first; i < last && !stopping(); i++)
            trace_photon(tc, i, &tc->blocks[b], tc->surface ? &tc->surface[b] : NULL,
                         tc->beams ? &tc->beams[b] : NULL);
    }
    return NULL;
}


double photon_trace_indirect_bound(const struct scene *s, float scene_size)
{
    double surf = 0.0, med = 0.0;
    const struct scene_media *sm = s->media;
    for (uint32_t i = 0; i < s->num_materials; i++) {
        const struct material *m = &s->materials[i];
        if (sm && i == sm->interface_material)
            continue;
        vec3 r = m->type == MATERIAL_DIFFUSE ? m->albedo : (m->type == MATERIAL_MIRROR ? m->reflectance : v3(1, 1, 1));
        surf = fmax(surf, (double)v3_max_component(r));
    }
    for (uint32_t i = 0; sm && i < sm->num_media; i++) {
        const struct medium *md = &sm->media[i];
        vec3 st = md->sigma_t, ss = md->sigma_s;
        double alb = 0.0, smax = (double)v3_max_component(st) * (md->grid ? md->grid->max_density : 1.0f);
        if (st.x > 0) alb = fmax(alb, (double)ss.x / st.x);
        if (st.y > 0) alb = fmax(alb, (double)ss.y / st.y);
        if (st.z > 0) alb = fmax(alb, (double)ss.z / st.z);
        med = fmax(med, alb * -expm1(-smax * (double)scene_size));
    }
    return fmax(surf, med);
}

int photon_trace_map(const struct render_job *job, uint64_t seed, uint32_t threads, uint8_t **blob, size_t *size,
                     struct photon_pass_stats *stats, char *err, size_t errlen)
{
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    memset(stats, 0, sizeof *stats);
    const struct scene_media *sm = job->scene->media;
    if (!job->media || !sm) {
        str_fmt(err, errlen, "photon pass: the scene has no media");
        return -1;
    }
    struct trace_ctx tc;
    trace_ctx_start(&tc, job, seed, job->lights.num_entries > 0 ? sm->photons : 0);
    tc.split_max = sm->photon_split ? sm->photon_split : MEDIA_DEFAULT_PHOTON_SPLIT;
    tc.split_ref = tc.split_max > 1 ? split_reference(&tc) : 0.0f;
    tc.num_blocks = (uint32_t)((tc.emitted + PM_BLOCK - 1) / PM_BLOCK);
    float grow = job->media->radius;
    if (sm->fog != MEDIUM_NONE) /* camera rays see the fog without its forward cone (medium.h) */
        grow += photon_fog_reach(&job->media->cut[sm->fog], job->media->scene_size);
    tc.keep_lo = v3_sub(job->media->bounds_lo, v3(grow, grow, grow));
    tc.keep_hi = v3_add(job->media->bounds_hi, v3(grow, grow, grow));
    atomic_init(&tc.next_block, 0);
    tc.blocks = mem_calloc(tc.num_blocks ? tc.num_blocks : 1, sizeof *tc.blocks);
    if (media_wants_surface_photons(sm))
        tc.surface = mem_calloc(tc.num_blocks ? tc.num_blocks : 1, sizeof *tc.surface);
    if (sm->method == MEDIA_MARCH_BEAMS)
        tc.beams = mem_calloc(tc.num_blocks ? tc.num_blocks : 1, sizeof *tc.beams);
    threads = threads < 1 ? 1 : (threads > 256 ? 256 : threads);
    pthread_t *th = mem_alloc(sizeof *th * threads);
    uint32_t started = 0;
    for (uint32_t i = 1; i < threads; i++)
        if (pthread_create(&th[i], NULL, trace_thread, &tc) == 0)
            started = i;
        else
            break;
    trace_thread(&tc);
    for (uint32_t i = 1; i <= started; i++)
        pthread_join(th[i], NULL);
    free(th);
    if (stopping()) {
        for (uint32_t b = 0; b < tc.num_blocks; b++) {
            free(tc.blocks[b].a);
            if (tc.surface)
                free(tc.surface[b].a);
            if (tc.beams)
                free(tc.beams[b].a);
        }
        free(tc.blocks);
        free(tc.surface);
        free(tc.beams);
        trace_ctx_end(&tc);
        str_fmt(err, errlen, "photon pass interrupted (by a signal) before its %llu photons were traced",
                (unsigned long long)tc.emitted);
        return -1;
    }
    float radius = job->media->radius;
    size_t vbytes = 0, sbytes = 0, bbytes = 0;
    uint32_t vn = 0, sn = 0, bn = 0;
    uint8_t *vmap = NULL, *smap = NULL, *bmap = NULL;
    int rc = photon_map_serialise(tc.blocks, tc.num_blocks, radius, tc.emitted, &vmap, &vbytes, &vn, err, errlen);
    if (tc.surface)
        rc |= photon_map_serialise(tc.surface, tc.num_blocks, radius, tc.emitted, &smap, &sbytes, &sn, err, errlen);
    if (tc.beams)
        rc |= photon_beams_serialise(tc.beams, tc.num_blocks, radius, tc.emitted, &bmap, &bbytes, &bn, err, errlen);
    free(tc.blocks);
    free(tc.surface);
    free(tc.beams);
    trace_ctx_end(&tc);
    if (rc != 0) {
        free(vmap);
        free(smap);
        free(bmap);
        return -1;
    }
    /* The volume map, then the surface map and the beams when there are any: the volume
     * map's buffer grows (realloc moves pages, it does not copy them) to take the rest. */
    size_t bytes = vbytes + sbytes + bbytes;
    uint8_t *out = sbytes + bbytes ? mem_realloc(vmap, bytes) : vmap;
    if (smap)
        memcpy(out + vbytes, smap, sbytes);
    if (bmap)
        memcpy(out + vbytes + sbytes, bmap, bbytes);
    free(smap);
    free(bmap);
    uint32_t n = vn + sn + bn;
    stats->stored_surface = sn;
    stats->stored_beams = bn;
    *blob = out;
    *size = bytes;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    stats->seconds = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    stats->emitted = tc.emitted;
    stats->stored = n;
    stats->bytes = bytes;
    return 0;
}

