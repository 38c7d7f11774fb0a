/* Media tracking (see media_track.h): which medium a point or a crossing ray is in, and
 * shadow transmittance through invisible boundaries. Rays leave boundaries with the path
 * tracer's integer-ULP offsets (vec.h); distances run from the exact boundary points. */
#include "render/media_track.h"
#include "base/log.h"
#include "base/rng.h"
#include "scene/grid.h"
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_CROSSINGS 256

int media_is_interface(const struct media_job *mj, uint32_t material)
{
    const struct scene_media *sm = mj->sm;
    return sm && material == sm->interface_material;
}

static uint32_t inside_of(const struct media_job *mj, const struct accel_hit *h)
{
    const struct scene_media *sm = mj->sm;
    if (h->geom == mj->accel->sphere_geom)
        return media_sphere_inside(sm, h->prim);
    return media_mesh_inside(sm, h->geom);
}

uint32_t media_after_crossing(const struct media_job *mj, const struct accel_hit *h, vec3 ng, vec3 dir)
{
    /* ng points outside the object: travelling against it enters. */
    return v3_dot(dir, ng) < 0.0f ? inside_of(mj, h) : mj->sm->fog;
}

uint32_t media_at(const struct media_job *mj, vec3 p)
{
    const struct scene_media *sm = mj->sm;
    vec3 dir = v3_normalize(v3(0.5377f, 0.6211f, 0.5703f));
    vec3 o = p;
    for (int i = 0; i < 64; i++) {
        struct accel_hit h;
        if (!accel_intersect(mj->accel, o, dir, INFINITY, 0.0f, &h))
            break;
        struct surface s;
        surface_from_hit(mj->accel, mj->lights, o, dir, &h, 0.0f, &s);
        uint32_t in = inside_of(mj, &h);
        if (in != MEDIUM_NONE)
            return v3_dot(dir, s.ng) > 0.0f ? in : sm->fog; /* leaving it: we were inside */
        vec3 n = v3_dot(dir, s.ng) > 0.0f ? s.ng : v3_neg(s.ng);
        o = offset_ray_origin(v3_add(s.p, v3_scale(n, s.p_err)), n);
    }
    return sm->fog;
}

/* Shadow transmittance caches of Jensen's methods: one per (point light, grid medium),
 * filled by the first thread that needs it (under a lock, on all cores) and read-only
 * after; the values are a pure function of the scene, so pixels do not depend on which
 * thread filled it, or when. */
#define SHADOW_CACHES_MAX 64
struct shadow_cache {
    vec3 light;
    uint32_t medium;
    struct tr_cache c;
    atomic_int ready;
};
struct shadow_caches {
    pthread_mutex_t lock;
    uint32_t n, threads;
    struct shadow_cache e[SHADOW_CACHES_MAX];
};

static struct shadow_caches *shadow_caches_new(const struct media_job *mj)
{
    const struct scene *sc = mj->accel->desc;
    const struct scene_media *sm = sc->media;
    if (sm->method == MEDIA_VPT || !sm->shadow_cache)
        return NULL;
    struct shadow_caches *s = mem_calloc(1, sizeof *s);
    pthread_mutex_init(&s->lock, NULL);
    long cores = sysconf(_SC_NPROCESSORS_ONLN);
    s->threads = cores < 1 ? 1u : (cores > 64 ? 64u : (uint32_t)cores);
    for (uint32_t m = 0; m < sm->num_media; m++) {
        if (!sm->media[m].grid)
            continue;
        for (uint32_t i = 0; i < mj->lights->num_entries && s->n < SHADOW_CACHES_MAX; i++) {
            const struct light_entry *e = &mj->lights->entries[i];
            if (e->kind != LK_POINT)
                continue;
            struct shadow_cache *c = &s->e[s->n++];
            c->light = sc->lights[e->index].position;
            c->medium = m;
            atomic_init(&c->ready, 0);
        }
    }
    return s;
}

static void shadow_caches_free(struct shadow_caches **ps)
{
    struct shadow_caches *s = *ps;
    if (!s)
        return;
    for (uint32_t i = 0; i < s->n; i++)
        tr_cache_fini(&s->e[i].c);
    pthread_mutex_destroy(&s->lock);
    free(s);
    *ps = NULL;
}

static const struct tr_cache *shadow_cache_get(const struct media_job *mj, vec3 light, uint32_t medium)
{
    struct shadow_caches *s = mj->shadow;
    if (!s)
        return NULL;
    for (uint32_t i = 0; i < s->n; i++) {
        struct shadow_cache *c = &s->e[i];
        if (c->medium != medium || memcmp(&c->light, &light, sizeof light) != 0)
            continue;
        if (!atomic_load_explicit(&c->ready, memory_order_acquire)) {
            pthread_mutex_lock(&s->lock);
            if (!atomic_load_explicit(&c->ready, memory_order_relaxed)) {
                tr_cache_init(&c->c, &mj->sm->media[medium], light, s->threads);
                atomic_store_explicit(&c->ready, 1, memory_order_release);
            }
            pthread_mutex_unlock(&s->lock);
        }
        return c->c.tau ? &c->c : NULL;
    }
    return NULL;
}

int media_bounding_sphere(const struct scene *sc, vec3 *center, float *radius)
{
    const struct scene_media *sm = sc->media;
    vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
#define GROW(q) (lo = v3(fminf(lo.x, (q).x), fminf(lo.y, (q).y), fminf(lo.z, (q).z)), \
                 hi = v3(fmaxf(hi.x, (q).x), fmaxf(hi.y, (q).y), fmaxf(hi.z, (q).z)))
    if (sm->fog != MEDIUM_NONE) {
        const struct density_grid *g = sm->media[sm->fog].grid;
        if (!g || grid_is_empty(g))
            return 0;
        grid_world_box(g, &lo, &hi);
    }
    for (uint32_t i = 0; i < sm->num_sphere_medium && i < sc->num_spheres; i++)
        if (sm->sphere_medium[i] != MEDIUM_NONE) {
            const struct sphere *sp = &sc->spheres[i];
            vec3 rr = v3(sp->radius, sp->radius, sp->radius);
            vec3 a = v3_sub(sp->center, rr), b = v3_add(sp->center, rr);
            GROW(a);
            GROW(b);
        }
    for (uint32_t i = 0; i < sm->num_mesh_medium && i < sc->num_meshes; i++)
        if (sm->mesh_medium[i] != MEDIUM_NONE) {
            const struct mesh *m = &sc->meshes[i];
            for (uint32_t k = 0; k < m->num_vertices; k++) {
                vec3 q = v3(m->positions[3 * k], m->positions[3 * k + 1], m->positions[3 * k + 2]);
                GROW(q);
            }
        }
#undef GROW
    if (!(lo.x <= hi.x))
        return 0;
    *center = v3_scale(v3_add(lo, hi), 0.5f);
    *radius = 0.5f * v3_length(v3_sub(hi, lo)) * 1.001f;
    return 1;
}

struct media_job *media_job_new(const struct accel *a, const struct light_table *lt, const struct photon_map *map)
{
    const struct scene *sc = a->desc;
    const struct scene_media *sm = sc->media;
    struct media_job *mj = mem_calloc(1, sizeof *mj);
    mj->sm = sm;
    mj->cut = mem_alloc(sizeof *mj->cut * (sm->num_media + 1));
    for (uint32_t i = 0; i < sm->num_media; i++)
        mj->cut[i] = medium_forward_cut(&sm->media[i]);
    mj->accel = a;
    mj->lights = lt;
    struct RTCBounds b;
    rtcGetSceneBounds(a->scene, &b);
    vec3 lo = v3(b.lower_x, b.lower_y, b.lower_z), hi = v3(b.upper_x, b.upper_y, b.upper_z);
    if (!(lo.x <= hi.x)) /* empty scene */
        lo = hi = sc->camera.position;
    for (uint32_t i = 0; i <= sc->num_lights; i++) {
        vec3 q = i < sc->num_lights ? sc->lights[i].position : sc->camera.position;
        lo = v3(fminf(lo.x, q.x), fminf(lo.y, q.y), fminf(lo.z, q.z));
        hi = v3(fmaxf(hi.x, q.x), fmaxf(hi.y, q.y), fmaxf(hi.z, q.z));
    }
    /* Grids may reach beyond the geometry (a cloud in an open sky): rays march them all. */
    media_grids_grow_box(sm, &lo, &hi);
    float size = v3_length(v3_sub(hi, lo));
    size = size > 0.0f && isfinite(size) ? size : 1.0f;
    vec3 pad = v3(1e-3f * size, 1e-3f * size, 1e-3f * size);
    mj->bounds_lo = v3_sub(lo, pad);
    mj->bounds_hi = v3_add(hi, pad);
    mj->scene_size = size;
    mj->step = sm->step > 0.0f ? sm->step : size / 200.0f;
    mj->step = fmaxf(mj->step, size * 1e-6f);
    mj->radius = sm->radius > 0.0f ? sm->radius : size / 100.0f;
    mj->radius = fmaxf(mj->radius, size * 1e-5f); /* bounds the cells a beam query walks */
    mj->camera_medium = media_at(mj, sc->camera.position);
    mj->light_medium = mem_alloc(sizeof *mj->light_medium * (lt->num_entries + 1));
    for (uint32_t i = 0; i < lt->num_entries; i++) {
        const struct light_entry *e = &lt->entries[i];
        vec3 p;
        if (e->kind == LK_POINT) {
            p = sc->lights[e->index].position;
        } else if (e->kind == LK_TRIANGLE) {
            vec3 v[3], n;
            light_triangle_vertices(lt, i, v, &n);
            p = offset_ray_origin(v3_scale(v3_add(v3_add(v[0], v[1]), v[2]), 1.0f / 3.0f), n);
        } else if (e->kind == LK_ENV) {
            p = v3_add(mj->bounds_hi, v3(size, size, size)); /* outside everything */
        } else {
            const struct sphere *s = &sc->spheres[e->index];
            p = v3_add(s->center, v3(0, s->radius * 1.001f, 0));
        }
        mj->light_medium[i] = media_at(mj, p);
        /* A glowing light: a point or spot light where its medium scatters (a grid's
         * density there not 0). */
        uint32_t m = mj->light_medium[i];
        const struct medium *md = m != MEDIUM_NONE ? &sm->media[m] : NULL;
        if (e->kind == LK_POINT && md && !v3_is_black(md->sigma_s) && (!md->grid || grid_density(md->grid, p) > 0.0f) &&
            mj->num_glow < MEDIA_GLOW_MAX)
            mj->glow[mj->num_glow++] = p;
    }
    mj->aim = media_bounding_sphere(sc, &mj->aim_center, &mj->aim_radius);
    uint32_t grids = 0;
    for (uint32_t i = 0; i < sm->num_media; i++)
        grids += sm->media[i].grid != NULL;
    mj->aims = grids ? mem_calloc(grids < MEDIA_AIM_MAX ? grids : MEDIA_AIM_MAX, sizeof *mj->aims) : NULL;
    for (uint32_t i = 0; i < sm->num_media && mj->num_aims < MEDIA_AIM_MAX; i++)
        if (sm->media[i].grid && !v3_is_black(sm->media[i].sigma_s) && grid_aim_init(&mj->aims[mj->num_aims], sm->media[i].grid))
            mj->num_aims++;
    mj->map = sm->method != MEDIA_VPT ? map : NULL;
    mj->shadow = shadow_caches_new(mj);
    return mj;
}

void media_job_free(struct media_job **pmj)
{
    if (!*pmj)
        return;
    for (uint32_t i = 0; i < (*pmj)->num_aims; i++)
        grid_aim_fini(&(*pmj)->aims[i]);
    free((*pmj)->aims);
    free((*pmj)->light_medium);
    free((*pmj)->cut);
    shadow_caches_free(&(*pmj)->shadow);
    free(*pmj);
    *pmj = NULL;
}

vec3 media_shadow_transmittance(const struct media_job *mj, vec3 p, vec3 target, uint32_t medium, float time01,
                                uint64_t key, uint64_t *rays)
{
    const struct scene_media *sm = mj->sm;
    const int ratio = sm->method == MEDIA_VPT; /* unbiased ratio tracking; marched for Jensen's methods */
    vec3 tr = v3(1, 1, 1);
    if (sm->interface_material == UINT32_MAX) {
        /* No invisible boundaries: any hit blocks, and the medium is the same all along. */
        (*rays)++;
        if (accel_occluded(mj->accel, p, v3_sub(target, p), 1.0f - 0x1p-12f, time01))
            return v3(0, 0, 0);
        if (medium == MEDIUM_NONE)
            return tr;
        const struct medium *md = &sm->media[medium];
        if (!ratio && md->grid) {
            /* Jensen's methods: the cached optical depth toward a point light, where cached. */
            const struct tr_cache *c = shadow_cache_get(mj, target, medium);
            float tau;
            if (c && tr_cache_tau_from(c, p, &tau))
                return medium_tr_tau(md, tau);
        }
        vec3 to = v3_sub(target, p);
        float len = v3_length(to);
        return len > 0.0f ? medium_tr_segment(&sm->media[medium], p, v3_scale(to, 1.0f / len), len, key, ratio) : tr;
    }
    /* Distances run from the exact boundary points, not from the offset ray origins (the
     * offsets would shorten every segment by a few hundred ulps). */
    vec3 start = p;
    for (int i = 0; i < MAX_CROSSINGS; i++) {
        vec3 to = v3_sub(target, p);
        float dist = v3_length(to);
        if (!(dist > 0.0f))
            return tr;
        vec3 dir = v3_scale(to, 1.0f / dist);
        struct accel_hit h;
        (*rays)++;
        if (!accel_intersect(mj->accel, p, dir, dist * (1.0f - 0x1p-12f), time01, &h)) {
            if (medium != MEDIUM_NONE)
                tr = v3_mul(tr, medium_tr_segment(&sm->media[medium], start, dir, v3_length(v3_sub(target, start)),
                                                  rng_mix64(key + (uint64_t)i), ratio));
            return tr;
        }
        struct surface s;
        surface_from_hit(mj->accel, mj->lights, p, dir, &h, time01, &s);
        if (!media_is_interface(mj, s.material))
            return v3(0, 0, 0);
        if (medium != MEDIUM_NONE)
            tr = v3_mul(tr, medium_tr_segment(&sm->media[medium], start, dir, v3_length(v3_sub(s.p, start)),
                                              rng_mix64(key + (uint64_t)i), ratio));
        if (v3_is_black(tr))
            return tr;
        medium = media_after_crossing(mj, &h, s.ng, dir);
        vec3 n = v3_dot(dir, s.ng) > 0.0f ? s.ng : v3_neg(s.ng);
        p = offset_ray_origin(v3_add(s.p, v3_scale(n, s.p_err)), n);
        start = s.p;
    }
    return v3(0, 0, 0);
}
