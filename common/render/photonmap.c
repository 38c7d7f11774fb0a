/* Volume photon map: tracing, serialisation, decoding and the two radiance estimates (see
 * photonmap.h). Called by the master (build) and by workers (decode, lookups). */
#include "render/photonmap.h"
#include "base/bytes.h"
#include "render/integrator.h"
#include "base/log.h"
#include "scene/material.h"
#include "render/media_integrator.h"
#include "base/rng.h"
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

_Static_assert(sizeof(struct photon) == 20, "photons are 20 bytes on the wire");

#define PM_MAGIC "BVPM0001"
#define PM_HEADER 48
#define PM_BLOCK 1024
/* Kernels use at least this radius and estimates saturate at 1e30, so a gather radius
 * near 0 cannot turn one photon into an infinite estimate. */
#define PM_MIN_KERNEL_RADIUS 1e-9           /* photon indices per work unit */
#define SALT_PHOTON 0x70686f746f6eull

/* ---- encodings ---- */

void photon_rgbe_encode(vec3 c, uint8_t out[4])
{
    float m = v3_max_component(c);
    if (!(m > 1e-32f) || !isfinite(m)) {
        memset(out, 0, 4);
        return;
    }
    int e;
    float f = frexpf(m, &e) * 256.0f / m; /* m = f' 2^e, f' in [0.5, 1) */
    out[0] = (uint8_t)fminf(c.x * f, 255.0f);
    out[1] = (uint8_t)fminf(c.y * f, 255.0f);
    out[2] = (uint8_t)fminf(c.z * f, 255.0f);
    out[3] = (uint8_t)(e + 128);
}

vec3 photon_rgbe_decode(const uint8_t in[4])
{
    if (in[3] == 0)
        return v3(0, 0, 0);
    float f = ldexpf(1.0f, (int)in[3] - (128 + 8));
    /* +0.5: the centre of the quantisation bin, so the code is unbiased on average. */
    return v3(((float)in[0] + 0.5f) * f, ((float)in[1] + 0.5f) * f, ((float)in[2] + 0.5f) * f);
}

uint16_t photon_dir_encode(vec3 d)
{
    float s = fabsf(d.x) + fabsf(d.y) + fabsf(d.z);
    float x = d.x / s, y = d.y / s;
    if (d.z < 0.0f) {
        float ox = (1.0f - fabsf(y)) * (x >= 0.0f ? 1.0f : -1.0f);
        float oy = (1.0f - fabsf(x)) * (y >= 0.0f ? 1.0f : -1.0f);
        x = ox, y = oy;
    }
    int qx = (int)lrintf((x * 0.5f + 0.5f) * 255.0f), qy = (int)lrintf((y * 0.5f + 0.5f) * 255.0f);
    qx = qx < 0 ? 0 : (qx > 255 ? 255 : qx);
    qy = qy < 0 ? 0 : (qy > 255 ? 255 : qy);
    return (uint16_t)(qx | qy << 8);
}

vec3 photon_dir_decode(uint16_t e)
{
    float x = (float)(e & 255) / 255.0f * 2.0f - 1.0f, y = (float)(e >> 8) / 255.0f * 2.0f - 1.0f;
    float z = 1.0f - fabsf(x) - fabsf(y);
    if (z < 0.0f) {
        float ox = (1.0f - fabsf(y)) * (x >= 0.0f ? 1.0f : -1.0f);
        float oy = (1.0f - fabsf(x)) * (y >= 0.0f ? 1.0f : -1.0f);
        x = ox, y = oy;
    }
    return v3_normalize(v3(x, y, z));
}

/* ---- hash grid ---- */

static uint32_t bucket_of(int32_t ix, int32_t iy, int32_t iz, uint32_t mask)
{
    uint32_t h = ((uint32_t)ix * 73856093u) ^ ((uint32_t)iy * 19349663u) ^ ((uint32_t)iz * 83492791u);
    return h & mask;
}

static int32_t cell_coord(float x, float inv_cell)
{
    float f = floorf(x * inv_cell);
    f = f < -1e9f ? -1e9f : (f > 1e9f ? 1e9f : f);
    if (!(f == f))
        f = 0.0f; /* NaN (an infinite inverse times 0): any cell; callers check distances */
    return (int32_t)f;
}

/* ---- tracing ---- */

/* Photons one block of indices stored, in index order. */
struct photon_list {
    struct photon *a;
    uint32_t n;
    size_t cap;
};

struct trace_ctx {
    const struct render_job *job;
    const struct media_job *mj;
    uint64_t seed;
    uint64_t emitted;
    float photon_scale;     /* 1 / emitted */
    uint32_t num_blocks;
    _Atomic uint32_t next_block;
    struct photon_list *blocks;     /* volume photons per block of indices */
    struct photon_list *surface;    /* surface photons per block (NULL: none kept) */
    int aim;                /* point lights aim most photons at the media's bounding sphere */
    vec3 aim_center;
    float aim_radius;
};

#define AIM_SHARE 0.75f     /* photons of a point light sent into the cone toward the media */

/* Bounding sphere of where media are (grids' occupied boxes, medium spheres and meshes);
 * 0 when a homogeneous fog fills everything (nothing to aim at). */
static int media_bounds(const struct render_job *job, vec3 *center, float *radius)
{
    const struct scene *sc = job->scene;
    const struct scene_media *sm = sc->media;
    vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
#define GROW(q) (lo = v3(fminf(lo.x, (q).x), fminf(lo.y, (q).y), fminf(lo.z, (q).z)), \
                 hi = v3(fmaxf(hi.x, (q).x), fmaxf(hi.y, (q).y), fmaxf(hi.z, (q).z)))
    if (sm->fog != MEDIUM_NONE) {
        const struct density_grid *g = sm->media[sm->fog].grid;
        if (!g)
            return 0;
        if (!(g->occ_lo.x <= g->occ_hi.x && g->occ_lo.y <= g->occ_hi.y && g->occ_lo.z <= g->occ_hi.z))
            return 0;
        for (int k = 0; k < 8; k++) {
            vec3 c = v3(k & 1 ? g->occ_hi.x : g->occ_lo.x, k & 2 ? g->occ_hi.y : g->occ_lo.y, k & 4 ? g->occ_hi.z : g->occ_lo.z);
            vec3 w = xform_point(&g->grid_to_world, c);
            GROW(w);
        }
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

static int outside_bounds(const struct media_job *mj, vec3 p)
{
    return !(p.x >= mj->bounds_lo.x && p.y >= mj->bounds_lo.y && p.z >= mj->bounds_lo.z && p.x <= mj->bounds_hi.x &&
             p.y <= mj->bounds_hi.y && p.z <= mj->bounds_hi.z);
}

static vec3 cosine_dir(vec3 n, float u1, float u2)
{
    float r = sqrtf(u1), sp, cp;
    sincos_2pi(u2, &sp, &cp);
    vec3 t, b;
    v3_basis(n, &t, &b);
    return v3_normalize(v3_add(v3_add(v3_scale(t, r * cp), v3_scale(b, r * sp)), v3_scale(n, sqrtf(fmaxf(0.0f, 1.0f - u1)))));
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
        float cos_max = l->type == LIGHT_SPOT ? l->cos_outer : -1.0f;
        vec3 axis = l->type == LIGHT_SPOT ? l->direction : v3(0, 0, 1);
        float cos_aim = 2.0f;
        vec3 aim_axis = axis;
        if (tc->aim) {
            vec3 to = v3_sub(tc->aim_center, l->position);
            float dist = v3_length(to);
            if (dist > tc->aim_radius) {
                aim_axis = v3_scale(to, 1.0f / dist);
                float s2 = (tc->aim_radius / dist) * (tc->aim_radius / dist);
                cos_aim = sqrtf(fmaxf(0.0f, 1.0f - s2));
            }
        }
        int aimed = cos_aim < 1.0f && rng_uniform(key, 5) < AIM_SHARE;
        float cm = aimed ? cos_aim : cos_max;
        vec3 ax = aimed ? aim_axis : axis;
        float z = 1.0f - u1 * (1.0f - cm), r = sqrtf(fmaxf(0.0f, 1.0f - z * z)), sp, cp;
        sincos_2pi(u2, &sp, &cp);
        vec3 t, b;
        v3_basis(ax, &t, &b);
        *d = v3_normalize(v3_add(v3_scale(ax, z), v3_add(v3_scale(t, r * cp), v3_scale(b, r * sp))));
        *o = l->position;
        float pdf_own = (l->type != LIGHT_SPOT || v3_dot(*d, axis) >= cos_max) ? 1.0f / (2.0f * (float)M_PI * (1.0f - cos_max)) : 0.0f;
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
        float z = 1.0f - 2.0f * u1, r = sqrtf(fmaxf(0.0f, 1.0f - z * z)), s, co;
        sincos_2pi(u2, &s, &co);
        vec3 n = v3(r * co, r * s, z);
        vec3 p = v3_add(sp->center, v3_scale(n, sp->radius));
        *o = offset_ray_origin(v3_add(p, v3_scale(n, (v3_max_abs(sp->center) + sp->radius) * 0x1p-21f)), n);
        *d = cosine_dir(n, u3, u4);
        *power = v3_scale(e->emission, (float)M_PI * e->area / pick * tc->photon_scale);
        return 1;
    }
    }
    return 0;
}

static void store(struct photon_list *l, vec3 p, vec3 d, vec3 power)
{
    if (!v3_is_finite(power) || v3_is_black(power))
        return;
    mem_grow((void **)&l->a, &l->cap, (size_t)l->n + 1, sizeof *l->a);
    struct photon *ph = &l->a[l->n++];
    ph->p[0] = p.x, ph->p[1] = p.y, ph->p[2] = p.z;
    photon_rgbe_encode(power, ph->rgbe);
    ph->dir = photon_dir_encode(d);
    ph->reserved = 0;
}

/* Traces photon `index`: volume photons into vol; when surf is non-NULL, photons arriving
 * at diffuse surfaces after any interaction into surf. */
static void trace_photon(const struct trace_ctx *tc, uint64_t index, struct photon_list *vol,
                         struct photon_list *surf)
{
    const struct render_job *job = tc->job;
    const struct scene *sc = job->scene;
    const struct scene_media *sm = sc->media;
    uint64_t key = rng_mix64(rng_key(tc->seed ^ SALT_PHOTON, job->frame, index, 0));
    vec3 o, d, power;
    uint32_t medium;
    if (!emit(tc, key, &o, &d, &power, &medium) || v3_is_black(power))
        return;
    int indirect = 0;           /* any interaction since the light */
    uint32_t crossings = 0;
    /* Moving geometry: each photon lives at one time of the frame's shutter, drawn as the
     * camera draws its rays' times, so the map averages the shutter as the image does. */
    const float time01 = job->accel.has_motion ? camera_shutter_warp(&job->camera, rng_uniform(key, 6)) : 0.0f;
    for (uint32_t depth = 0; depth < sm->max_photon_depth;) {
        uint32_t dim = 8 + 8 * depth;
        struct accel_hit h;
        int hit = accel_intersect(&job->accel, o, d, INFINITY, time01, &h);
        if (medium != MEDIUM_NONE) {
            const struct medium *md = &sm->media[medium];
            float t;
            vec3 w;
            int scatter = medium_sample_flight(md, o, d, hit ? h.t : INFINITY, power, rng_mix64(key ^ ((uint64_t)dim << 32)), &t, &w);
            vec3 before = power;
            power = v3_mul(power, w);
            if (scatter) {
                vec3 x = v3_add(o, v3_scale(d, t));
                if (outside_bounds(tc->mj, x))
                    return;
                if (indirect)
                    store(vol, x, d, power);
                /* Russian roulette keeps the power of survivors near what it was. */
                float q = fminf(1.0f, v3_max_component(power) / fmaxf(v3_max_component(before), 1e-30f));
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
        struct media_surface s;
        integrator_media_surface(job, o, d, &h, time01, &s);
        if (media_is_interface(job, s.material)) {
            if (++crossings > 256)
                return;
            medium = media_after_crossing(job, &h, s.ng, d);
            vec3 nn = v3_dot(s.ng, d) > 0.0f ? s.ng : v3_neg(s.ng);
            o = offset_ray_origin(v3_add(s.p, v3_scale(nn, s.p_err)), nn);
            continue;
        }
        const struct material *mat = &sc->materials[s.material];
        /* Light reaching a diffuse surface after an interaction: its indirect light (what
         * arrives straight from a light, next-event estimation computes). */
        if (surf && indirect && mat->type == MATERIAL_DIFFUSE && !v3_is_black(mat->albedo))
            store(surf, s.p, d, power);
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
        vec3 w = bs.transmitted ? mat->transmittance : bs.weight;
        float q = fminf(1.0f, v3_max_component(w));
        if (!(q > 0.0f) || rng_uniform(key, dim + 7) >= q)
            return;
        power = v3_scale(v3_mul(power, w), 1.0f / q);
        if (bs.transmitted) {
            medium = media_after_crossing(job, &h, s.ng, d);
            o = offset_ray_origin(v3_sub(s.p, v3_scale(ng, s.p_err)), v3_neg(ng));
        } else {
            o = offset_ray_origin(v3_add(s.p, v3_scale(ng, s.p_err)), ng);
        }
        d = bs.wi;
        indirect = 1;
        depth++;
    }
}

static void *trace_thread(void *arg)
{
    struct trace_ctx *tc = arg;
    for (;;) {
        uint32_t b = atomic_fetch_add(&tc->next_block, 1);
        if (b >= tc->num_blocks)
            break;
        uint64_t first = (uint64_t)b * PM_BLOCK, last = first + PM_BLOCK;
        last = last < tc->emitted ? last : tc->emitted;
        for (uint64_t i = first; i < last; i++)
            trace_photon(tc, i, &tc->blocks[b], tc->surface ? &tc->surface[b] : NULL);
    }
    return NULL;
}


static int host_little_endian(void)
{
    uint16_t x = 1;
    uint8_t b;
    memcpy(&b, &x, 1);
    return b == 1;
}

double photon_map_indirect_bound(const struct scene *s, float scene_size)
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

/* Joins the blocks' photons in index order (freeing them), sorts them stably by hash-grid
 * bucket and writes one map (header, photons, bucket starts). NULL when too many. */
static uint8_t *serialise(struct photon_list *blocks, uint32_t num_blocks, float radius, uint64_t emitted,
                          size_t *bytes_out, uint32_t *n_out)
{
    uint64_t total = 0;
    for (uint32_t b = 0; b < num_blocks; b++)
        total += blocks[b].n;
    if (total > UINT32_MAX / 2) {
        for (uint32_t b = 0; b < num_blocks; b++)
            free(blocks[b].a);
        return NULL;
    }
    uint32_t n = (uint32_t)total;
    uint32_t table = 1;
    while (table < n / 2)
        table <<= 1;
    float cell = 2.0f * radius, inv = 1.0f / cell;
    struct photon *all = mem_alloc(sizeof *all * (n ? n : 1)), *sorted = mem_alloc(sizeof *all * (n ? n : 1));
    uint32_t k = 0;
    for (uint32_t b = 0; b < num_blocks; b++) {
        if (blocks[b].n)
            memcpy(all + k, blocks[b].a, sizeof *all * blocks[b].n);
        k += blocks[b].n;
        free(blocks[b].a);
    }
    uint32_t *start = mem_calloc((size_t)table + 1, sizeof *start), *bk = mem_alloc(sizeof *bk * (n ? n : 1));
    for (uint32_t i = 0; i < n; i++) {
        bk[i] = bucket_of(cell_coord(all[i].p[0], inv), cell_coord(all[i].p[1], inv), cell_coord(all[i].p[2], inv),
                          table - 1);
        start[bk[i] + 1]++;
    }
    for (uint32_t i = 0; i < table; i++)
        start[i + 1] += start[i];
    uint32_t *fill = mem_alloc(sizeof *fill * table);
    memcpy(fill, start, sizeof *fill * table);
    for (uint32_t i = 0; i < n; i++)
        sorted[fill[bk[i]]++] = all[i];
    free(fill);
    free(bk);
    free(all);
    size_t bytes = PM_HEADER + sizeof(struct photon) * (size_t)n + 4 * ((size_t)table + 1);
    uint8_t *out = mem_calloc(bytes, 1);
    memcpy(out, PM_MAGIC, 8);
    bytes_put_u32(out + 8, n);
    bytes_put_u32(out + 12, table);
    bytes_put_u64(out + 16, emitted);
    bytes_put_f32(out + 24, radius);
    bytes_put_f32(out + 28, cell);
    if (n)
        memcpy(out + PM_HEADER, sorted, sizeof(struct photon) * (size_t)n);
    uint8_t *sp = out + PM_HEADER + sizeof(struct photon) * (size_t)n;
    for (uint32_t i = 0; i <= table; i++)
        bytes_put_u32(sp + 4 * (size_t)i, start[i]);
    free(sorted);
    free(start);
    *bytes_out = bytes;
    *n_out = n;
    return out;
}

int photon_map_build(const struct render_job *job, uint64_t seed, uint32_t threads, uint8_t **blob, size_t *size,
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
    if (!host_little_endian()) {
        str_fmt(err, errlen, "photon pass: big-endian hosts are not supported");
        return -1;
    }
    struct trace_ctx tc;
    memset(&tc, 0, sizeof tc);
    tc.job = job;
    tc.mj = job->media;
    tc.seed = seed;
    tc.emitted = job->lights.num_entries > 0 ? sm->photons : 0;
    tc.photon_scale = tc.emitted ? (float)(1.0 / (double)tc.emitted) : 0.0f;
    tc.num_blocks = (uint32_t)((tc.emitted + PM_BLOCK - 1) / PM_BLOCK);
    tc.aim = media_bounds(job, &tc.aim_center, &tc.aim_radius);
    atomic_init(&tc.next_block, 0);
    tc.blocks = mem_calloc(tc.num_blocks ? tc.num_blocks : 1, sizeof *tc.blocks);
    if (sm->surface_photons)
        tc.surface = mem_calloc(tc.num_blocks ? tc.num_blocks : 1, sizeof *tc.surface);
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
    float radius = job->media->radius;
    size_t vbytes = 0, sbytes = 0;
    uint32_t vn = 0, sn = 0;
    uint8_t *vmap = serialise(tc.blocks, tc.num_blocks, radius, tc.emitted, &vbytes, &vn);
    uint8_t *smap = tc.surface ? serialise(tc.surface, tc.num_blocks, radius,
                                                 tc.emitted, &sbytes, &sn)
                                     : NULL;
    free(tc.blocks);
    int want_surface = tc.surface != NULL;
    free(tc.surface);
    if (!vmap || (want_surface && !smap)) {
        str_fmt(err, errlen, "photon pass: too many photons stored");
        free(vmap);
        free(smap);
        return -1;
    }
    /* The volume map, then the surface map when there is one. */
    size_t bytes = vbytes + sbytes;
    uint8_t *out = mem_alloc(bytes);
    memcpy(out, vmap, vbytes);
    if (smap)
        memcpy(out + vbytes, smap, sbytes);
    free(vmap);
    free(smap);
    uint32_t n = vn + sn;
    stats->stored_surface = sn;
    *blob = out;
    *size = bytes;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    stats->seconds = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    stats->emitted = tc.emitted;
    stats->stored = n;
    stats->bytes = bytes;
    return 0;
}

/* One map at the start of data: its size (from its header) goes to *used. */
static int decode_one(const uint8_t *data, size_t size, size_t *used, struct photon_map **out, char *err,
                      size_t errlen)
{
    *out = NULL;
    if (size < PM_HEADER || memcmp(data, PM_MAGIC, 8) != 0) {
        str_fmt(err, errlen, "photon map: not a photon map (bad header)");
        return -1;
    }
    if (!host_little_endian()) {
        str_fmt(err, errlen, "photon map: big-endian hosts are not supported");
        return -1;
    }
    uint32_t n = bytes_get_u32(data + 8), table = bytes_get_u32(data + 12);
    uint64_t emitted = bytes_get_u64(data + 16);
    float radius = bytes_get_f32(data + 24), cell = bytes_get_f32(data + 28);
    if (table == 0 || (table & (table - 1)) != 0 || table > (1u << 30) || n > UINT32_MAX / 2 ||
        !(radius > 0.0f) || !isfinite(radius) || cell != 2.0f * radius || !isfinite(1.0f / cell) ||
        size < PM_HEADER + sizeof(struct photon) * (uint64_t)n + 4 * ((uint64_t)table + 1)) {
        str_fmt(err, errlen, "photon map: inconsistent sizes in the header");
        return -1;
    }
    *used = PM_HEADER + sizeof(struct photon) * (size_t)n + 4 * ((size_t)table + 1);
    struct photon_map *m = mem_calloc(1, sizeof *m);
    m->num_photons = n;
    m->table_size = table;
    m->num_emitted = emitted;
    m->radius = radius;
    m->cell_size = cell;
    m->photons = mem_alloc(sizeof *m->photons * (n ? n : 1));
    if (n)
        memcpy(m->photons, data + PM_HEADER, sizeof *m->photons * (size_t)n);
    m->bucket_start = mem_alloc(sizeof *m->bucket_start * ((size_t)table + 1));
    const uint8_t *sp = data + PM_HEADER + sizeof(struct photon) * (size_t)n;
    for (uint32_t i = 0; i <= table; i++)
        m->bucket_start[i] = bytes_get_u32(sp + 4 * (size_t)i);
    int ok = m->bucket_start[0] == 0 && m->bucket_start[table] == n;
    for (uint32_t i = 0; ok && i < table; i++)
        ok = m->bucket_start[i] <= m->bucket_start[i + 1];
    for (uint32_t i = 0; ok && i < n; i++)
        ok = isfinite(m->photons[i].p[0]) && isfinite(m->photons[i].p[1]) && isfinite(m->photons[i].p[2]);
    if (!ok) {
        str_fmt(err, errlen, "photon map: bucket table or photon positions are invalid");
        photon_map_free(&m);
        return -1;
    }
    /* Decoded direction and power per photon (reader side only, never serialised): the
     * lookups read them for the photons they accept. */
    m->decoded = mem_alloc(sizeof *m->decoded * (n ? n : 1));
    for (uint32_t i = 0; i < n; i++) {
        vec3 dd = photon_dir_decode(m->photons[i].dir), pw = photon_rgbe_decode(m->photons[i].rgbe);
        m->decoded[i] = (struct photon_decoded){{dd.x, dd.y, dd.z}, {pw.x, pw.y, pw.z}};
    }
    *out = m;
    return 0;
}

int photon_map_decode(const uint8_t *data, size_t size, struct photon_map **out, char *err, size_t errlen)
{
    size_t used = 0, used2 = 0;
    if (decode_one(data, size, &used, out, err, errlen) != 0)
        return -1;
    if (used == size)
        return 0;
    /* A surface map follows: exactly one more map, with the same radius and photon count. */
    struct photon_map *s = NULL;
    if (decode_one(data + used, size - used, &used2, &s, err, errlen) != 0 || used2 != size - used ||
        s->radius != (*out)->radius || s->num_emitted != (*out)->num_emitted) {
        if (s || used2)
            str_fmt(err, errlen, "photon map: the surface map does not fit the blob or the volume map");
        photon_map_free(&s);
        photon_map_free(out);
        return -1;
    }
    (*out)->surface = s;
    return 0;
}

void photon_map_free(struct photon_map **pm)
{
    if (!*pm)
        return;
    photon_map_free(&(*pm)->surface);
    free((*pm)->decoded);
    free((*pm)->photons);
    free((*pm)->bucket_start);
    free(*pm);
    *pm = NULL;
}

/* ---- lookups ---- */

/* Henyey-Greenstein in float for the lookups' inner loops (the photons' directions carry
 * 8-bit precision; g is bounded away from +-1 by the scene's validation). */
static inline float phase_hg_fast(float cos_theta, float g)
{
    float d = 1.0f + g * g - 2.0f * g * cos_theta;
    d = d > 1e-30f ? d : 1e-30f;
    return (1.0f - g * g) / (4.0f * (float)M_PI * d * sqrtf(d));
}

/* phase x power of photon i for light leaving along d_out. */
static inline vec3 photon_contrib(const struct photon_map *m, uint32_t i, vec3 d_out, float g)
{
    if (m->decoded) {
        const struct photon_decoded *pd = &m->decoded[i];
        float p = phase_hg_fast(pd->dir[0] * d_out.x + pd->dir[1] * d_out.y + pd->dir[2] * d_out.z, g);
        return v3(p * pd->power[0], p * pd->power[1], p * pd->power[2]);
    }
    const struct photon *ph = &m->photons[i];
    return v3_scale(photon_rgbe_decode(ph->rgbe), phase_hg(v3_dot(photon_dir_decode(ph->dir), d_out), g));
}

/* Visits each bucket of the cells [lo, hi] once (hash collisions would repeat them). */
#define MAX_VISIT 64
/* seg (optional): o, d, [a, b]: only cells whose centre lies within r + half a cell
 * diagonal of that segment can hold photons within r of it. */
struct seg_filter { vec3 o, d; float a, b, reach2; };

static uint32_t collect_buckets(const struct photon_map *m, vec3 lo, vec3 hi, uint32_t *out,
                                const struct seg_filter *seg)
{
    float inv = 1.0f / m->cell_size, cs = m->cell_size;
    int32_t x0 = cell_coord(lo.x, inv), y0 = cell_coord(lo.y, inv), z0 = cell_coord(lo.z, inv);
    int32_t x1 = cell_coord(hi.x, inv), y1 = cell_coord(hi.y, inv), z1 = cell_coord(hi.z, inv);
    uint32_t nb = 0;
    for (int32_t z = z0; z <= z1 && z - z0 < 4; z++)
        for (int32_t y = y0; y <= y1 && y - y0 < 4; y++)
            for (int32_t x = x0; x <= x1 && x - x0 < 4; x++) {
                if (seg) {
                    vec3 c = v3(((float)x + 0.5f) * cs, ((float)y + 0.5f) * cs, ((float)z + 0.5f) * cs);
                    vec3 oc = v3_sub(c, seg->o);
                    float t = v3_dot(oc, seg->d);
                    t = t < seg->a ? seg->a : (t > seg->b ? seg->b : t);
                    vec3 q = v3_sub(oc, v3_scale(seg->d, t));
                    if (v3_dot(q, q) > seg->reach2)
                        continue;
                }
                uint32_t b = bucket_of(x, y, z, m->table_size - 1);
                int seen = 0;
                for (uint32_t i = 0; i < nb && !seen; i++)
                    seen = out[i] == b;
                if (!seen && nb < MAX_VISIT)
                    out[nb++] = b;
            }
    return nb;
}

/* The buckets of the cells the sphere of radius r around x touches. */
static uint32_t sphere_buckets(const struct photon_map *m, vec3 x, float r, uint32_t *buckets)
{
    return collect_buckets(m, v3(x.x - r, x.y - r, x.z - r), v3(x.x + r, x.y + r, x.z + r), buckets, NULL);
}

/* acc times k, saturated at 1e30 (a near-zero kernel radius cannot give infinity). */
static vec3 scaled(const double acc[3], double k)
{
    return v3((float)fmin(acc[0] * k, 1e30), (float)fmin(acc[1] * k, 1e30), (float)fmin(acc[2] * k, 1e30));
}

vec3 photon_map_gather(const struct photon_map *m, vec3 x, vec3 d_out, float g)
{
    if (!m || m->num_photons == 0)
        return v3(0, 0, 0);
    float r = m->radius, r2 = r * r;
    uint32_t buckets[MAX_VISIT];
    uint32_t nb = sphere_buckets(m, x, r, buckets);
    double acc[3] = {0, 0, 0};
    for (uint32_t bi = 0; bi < nb; bi++)
        for (uint32_t i = m->bucket_start[buckets[bi]]; i < m->bucket_start[buckets[bi] + 1]; i++) {
            const struct photon *ph = &m->photons[i];
            vec3 dp = v3_sub(v3(ph->p[0], ph->p[1], ph->p[2]), x);
            if (v3_dot(dp, dp) > r2)
                continue;
            float p = phase_hg(v3_dot(photon_dir_decode(ph->dir), d_out), g);
            vec3 pw = photon_rgbe_decode(ph->rgbe);
            acc[0] += (double)p * pw.x, acc[1] += (double)p * pw.y, acc[2] += (double)p * pw.z;
        }
    double rk = fmax((double)r, PM_MIN_KERNEL_RADIUS);
    return scaled(acc, 1.0 / (4.0 / 3.0 * M_PI * rk * rk * rk));
}

vec3 photon_map_surface(const struct photon_map *vm, vec3 x, vec3 n)
{
    const struct photon_map *m = vm ? vm->surface : NULL;
    if (!m || m->num_photons == 0)
        return v3(0, 0, 0);
    float r = m->radius, r2 = r * r, slab = 0.25f * r;
    uint32_t buckets[MAX_VISIT];
    uint32_t nb = sphere_buckets(m, x, r, buckets);
    double acc[3] = {0, 0, 0};
    for (uint32_t bi = 0; bi < nb; bi++)
        for (uint32_t i = m->bucket_start[buckets[bi]]; i < m->bucket_start[buckets[bi] + 1]; i++) {
            const struct photon *ph = &m->photons[i];
            vec3 dp = v3_sub(v3(ph->p[0], ph->p[1], ph->p[2]), x);
            if (v3_dot(dp, dp) > r2 || fabsf(v3_dot(dp, n)) > slab)
                continue;
            const struct photon_decoded *pd = m->decoded ? &m->decoded[i] : NULL;
            vec3 dir = pd ? v3(pd->dir[0], pd->dir[1], pd->dir[2]) : photon_dir_decode(ph->dir);
            if (v3_dot(dir, n) >= 0.0f)
                continue; /* arrived on the other side */
            vec3 pw = pd ? v3(pd->power[0], pd->power[1], pd->power[2]) : photon_rgbe_decode(ph->rgbe);
            acc[0] += pw.x, acc[1] += pw.y, acc[2] += pw.z;
        }
    double rk = fmax((double)r, PM_MIN_KERNEL_RADIUS);
    return scaled(acc, 1.0 / (M_PI * rk * rk));
}

/* Max-heap on squared distance (the root is the farthest of the k kept). */
struct knn_item { float d2; uint32_t i; };

static void heap_sift_down(struct knn_item *h, uint32_t n, uint32_t i)
{
    for (;;) {
        uint32_t l = 2 * i + 1, r = l + 1, m = i;
        if (l < n && (h[l].d2 > h[m].d2 || (h[l].d2 == h[m].d2 && h[l].i > h[m].i)))
            m = l;
        if (r < n && (h[r].d2 > h[m].d2 || (h[r].d2 == h[m].d2 && h[r].i > h[m].i)))
            m = r;
        if (m == i)
            return;
        struct knn_item t = h[i];
        h[i] = h[m], h[m] = t;
        i = m;
    }
}

static void heap_sift_up(struct knn_item *h, uint32_t i)
{
    while (i > 0) {
        uint32_t p = (i - 1) / 2;
        if (!(h[i].d2 > h[p].d2 || (h[i].d2 == h[p].d2 && h[i].i > h[p].i)))
            return;
        struct knn_item t = h[i];
        h[i] = h[p], h[p] = t;
        i = p;
    }
}

/* Offers the photons of bucket b to the heap of the k nearest within r2max. */
static void knn_bucket(const struct photon_map *m, uint32_t b, vec3 x, uint32_t k, float r2max, struct knn_item *h,
                       uint32_t *n)
{
    for (uint32_t i = m->bucket_start[b]; i < m->bucket_start[b + 1]; i++) {
        const struct photon *ph = &m->photons[i];
        vec3 dp = v3_sub(v3(ph->p[0], ph->p[1], ph->p[2]), x);
        float d2 = v3_dot(dp, dp);
        if (!(d2 <= r2max))
            continue;
        if (*n < k) {
            h[*n] = (struct knn_item){d2, i};
            heap_sift_up(h, (*n)++);
        } else if (d2 < h[0].d2 || (d2 == h[0].d2 && i < h[0].i)) {
            h[0] = (struct knn_item){d2, i};
            heap_sift_down(h, *n, 0);
        }
    }
}

#define KNN_MAX_RING 8          /* cells searched around x's cell: rmax is capped at 8 cells */
#define KNN_SEEN 8192           /* buckets remembered per query (hash collisions repeat them) */

uint32_t photon_map_knn(const struct photon_map *m, vec3 x, uint32_t k, float rmax, uint32_t *idx, float *r2_out)
{
    *r2_out = 0.0f;
    if (!m || m->num_photons == 0 || k == 0)
        return 0;
    if (k > PM_KNN_MAX)
        k = PM_KNN_MAX;
    float cs = m->cell_size, inv = 1.0f / cs;
    rmax = fminf(rmax, (float)KNN_MAX_RING * cs);
    if (!(rmax > 0.0f) || !isfinite(x.x + x.y + x.z))
        return 0;
    float r2max = rmax * rmax;
    int32_t cx = cell_coord(x.x, inv), cy = cell_coord(x.y, inv), cz = cell_coord(x.z, inv);
    int32_t rings = (int32_t)ceilf(rmax * inv);
    if (rings > KNN_MAX_RING)
        rings = KNN_MAX_RING;
    struct knn_item h[PM_KNN_MAX];
    uint32_t n = 0, mask = m->table_size - 1, seen[KNN_SEEN], side = 2 * (uint32_t)rings + 1, set = 64;
    while (set < 2 * side * side * side && set < KNN_SEEN)
        set *= 2;
    memset(seen, 0xff, sizeof *seen * set);
    /* Rings of cells at Chebyshev distance s from x's cell hold only photons at least
     * (s - 1) cells away: stop once the k-th nearest is closer than that. */
    for (int32_t sr = 0; sr <= rings; sr++) {
        float gap = (float)(sr - 1) * cs;
        if (sr >= 1 && (gap > rmax || (n == k && h[0].d2 <= gap * gap)))
            break;
        for (int32_t dz = -sr; dz <= sr; dz++)
            for (int32_t dy = -sr; dy <= sr; dy++)
                for (int32_t dx = -sr; dx <= sr; dx++) {
                    if (abs(dx) != sr && abs(dy) != sr && abs(dz) != sr)
                        continue; /* inner cells: an earlier ring */
                    uint32_t b = bucket_of(cx + dx, cy + dy, cz + dz, mask);
                    uint32_t hs = (b * 2654435761u) & (set - 1);
                    while (seen[hs] != UINT32_MAX && seen[hs] != b)
                        hs = (hs + 1) & (set - 1);
                    if (seen[hs] == b)
                        continue;
                    seen[hs] = b;
                    knn_bucket(m, b, x, k, r2max, h, &n);
                }
    }
    for (uint32_t j = 0; j < n; j++)
        idx[j] = h[j].i;
    /* Fewer than k within rmax: the estimate's sphere is the maximum radius. */
    *r2_out = n == k ? h[0].d2 : r2max;
    return n;
}

vec3 photon_map_gather_knn(const struct photon_map *m, vec3 x, vec3 d_out, float g, uint32_t k, float rmax)
{
    uint32_t idx[PM_KNN_MAX];
    float r2;
    uint32_t n = photon_map_knn(m, x, k, rmax, idx, &r2);
    if (n == 0)
        return v3(0, 0, 0);
    double acc[3] = {0, 0, 0};
    for (uint32_t j = 0; j < n; j++) {
        vec3 c = photon_contrib(m, idx[j], d_out, g);
        acc[0] += c.x, acc[1] += c.y, acc[2] += c.z;
    }
    double rk = fmax(sqrt((double)r2), PM_MIN_KERNEL_RADIUS);
    return scaled(acc, 1.0 / (4.0 / 3.0 * M_PI * rk * rk * rk));
}

/* Drops repeated bucket ids in place (a small open-addressing set); returns the count. */
static uint32_t unique_buckets(uint32_t *b, uint32_t n)
{
    enum { SET = 2048 };
    uint32_t set[SET];
    memset(set, 0xff, sizeof set);
    uint32_t k = 0;
    for (uint32_t i = 0; i < n; i++) {
        uint32_t h = (b[i] * 2654435761u) & (SET - 1);
        while (set[h] != UINT32_MAX && set[h] != b[i])
            h = (h + 1) & (SET - 1);
        if (set[h] == b[i])
            continue;
        set[h] = b[i];
        b[k++] = b[i];
    }
    return k;
}

#define BEAM_CHUNK 16           /* pieces whose buckets are merged before the photons are read */

static vec3 tau_tr(const struct photon_tau *tt, const struct medium *md, float t)
{
    float x = (t - tt->t0) / tt->dt, tau;
    if (!(x > 0.0f))
        tau = 0.0f;
    else if (!(x < (float)(tt->n - 1)))
        tau = tt->tau[tt->n - 1];
    else {
        uint32_t i = (uint32_t)x;
        float f = x - (float)i;
        tau = tt->tau[i] * (1.0f - f) + tt->tau[i + 1] * f;
    }
    float ex = expf(-md->sigma_t.x * tau);
    if (md->sigma_t.y == md->sigma_t.x && md->sigma_t.z == md->sigma_t.x)
        return v3(ex, ex, ex); /* grey: the same value, one exponential */
    return v3(ex, expf(-md->sigma_t.y * tau), expf(-md->sigma_t.z * tau));
}

vec3 photon_map_beam(const struct photon_map *m, vec3 o, vec3 d, float t1, const struct medium *md,
                     const struct photon_tau *tau)
{
    if (!m || m->num_photons == 0 || !(t1 > 0.0f))
        return v3(0, 0, 0);
    float r = m->radius, r2 = r * r, seg = m->cell_size;
    vec3 d_out = v3_neg(d);
    double acc[3] = {0, 0, 0};
    uint32_t buckets[BEAM_CHUNK * MAX_VISIT];
    /* The segment in pieces one cell long; the buckets of BEAM_CHUNK pieces are merged
     * (sorted, duplicates dropped) and a photon counts only if its closest-point parameter
     * lies in the chunk's interval, so no photon is counted twice. */
    float np = ceilf(t1 / seg);
    uint64_t pieces = np < (float)(1u << 24) ? (uint64_t)np : (1u << 24); /* also for inf / NaN */
    for (uint64_t k0 = 0; k0 < pieces; k0 += BEAM_CHUNK) {
        uint32_t nb = 0;
        uint64_t k1 = k0 + BEAM_CHUNK < pieces ? k0 + BEAM_CHUNK : pieces;
        for (uint64_t k = k0; k < k1; k++) {
            float a = (float)k * seg, b = fminf(t1, (float)(k + 1) * seg);
            vec3 pa = v3_add(o, v3_scale(d, a)), pb = v3_add(o, v3_scale(d, b));
            vec3 lo = v3(fminf(pa.x, pb.x) - r, fminf(pa.y, pb.y) - r, fminf(pa.z, pb.z) - r);
            vec3 hi = v3(fmaxf(pa.x, pb.x) + r, fmaxf(pa.y, pb.y) + r, fmaxf(pa.z, pb.z) + r);
            float reach = r + 0.8660254f * seg;
            struct seg_filter sf = {o, d, a, b, reach * reach};
            nb += collect_buckets(m, lo, hi, buckets + nb, &sf);
        }
        nb = unique_buckets(buckets, nb);
        float a = (float)k0 * seg, b = k1 == pieces ? t1 : (float)k1 * seg;
        for (uint32_t bi = 0; bi < nb; bi++) {
            for (uint32_t i = m->bucket_start[buckets[bi]]; i < m->bucket_start[buckets[bi] + 1]; i++) {
                const struct photon *ph = &m->photons[i];
                vec3 dp = v3_sub(v3(ph->p[0], ph->p[1], ph->p[2]), o);
                float t = v3_dot(dp, d);
                if (!(t >= a && t < b))
                    continue;
                vec3 perp = v3_sub(dp, v3_scale(d, t));
                if (v3_dot(perp, perp) > r2)
                    continue;
                vec3 tr = tau ? tau_tr(tau, md, t) : medium_transmittance(md, t);
                vec3 c = v3_mul(photon_contrib(m, i, d_out, md->g), tr);
                acc[0] += c.x, acc[1] += c.y, acc[2] += c.z;
            }
        }
    }
    double rk = fmax((double)r, PM_MIN_KERNEL_RADIUS);
    return scaled(acc, 1.0 / (M_PI * rk * rk));
}

/* ---- the volume blob ---- */

#define VB_MAGIC "BVOL0001"
#define VB_HEADER 32

int volume_blob_make(const struct scene_media *sm, const uint8_t *map, size_t map_size, uint8_t **out,
                     size_t *out_size)
{
    size_t n = VB_HEADER + (map ? map_size : 0);
    uint8_t *b = mem_calloc(n, 1);
    memcpy(b, VB_MAGIC, 8);
    bytes_put_u32(b + 8, (uint32_t)sm->method);
    bytes_put_f32(b + 12, sm->step);
    bytes_put_f32(b + 16, sm->radius);
    bytes_put_u32(b + 20, map ? 1u : 0u);
    bytes_put_u64(b + 24, sm->photons);
    if (map)
        memcpy(b + VB_HEADER, map, map_size);
    *out = b;
    *out_size = n;
    return 0;
}

int volume_blob_apply(struct scene *s, const uint8_t *data, size_t size, char *err, size_t errlen)
{
    struct scene_media *sm = s->media;
    if (!sm || size < VB_HEADER || memcmp(data, VB_MAGIC, 8) != 0) {
        str_fmt(err, errlen, "volume blob: bad header or a scene without media");
        return -1;
    }
    uint32_t method = bytes_get_u32(data + 8), has_map = bytes_get_u32(data + 20);
    float step = bytes_get_f32(data + 12), radius = bytes_get_f32(data + 16);
    if (method >= MEDIA_METHOD_COUNT_ || !(step >= 0.0f) || !isfinite(step) || !(radius >= 0.0f) ||
        !isfinite(radius) || has_map > 1 || (!has_map && size != VB_HEADER)) {
        str_fmt(err, errlen, "volume blob: settings out of range");
        return -1;
    }
    sm->method = (enum media_method)method;
    sm->step = step;
    sm->radius = radius;
    sm->photons = bytes_get_u64(data + 24);
    photon_map_free(&sm->map);
    if (has_map && photon_map_decode(data + VB_HEADER, size - VB_HEADER, &sm->map, err, errlen) != 0)
        return -1;
    return 0;
}
