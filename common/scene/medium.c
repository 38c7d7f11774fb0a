/* Media model, validation and the closed forms of homogeneous media (see medium.h).
 * Exponentials are taken in float from float products, the same expression on every
 * machine; HG sampling runs in double, where g = +-0.999 loses nothing. */
#include "scene/medium.h"
#include "base/bytes.h"
#include "base/log.h"
#include "scene/motion.h"
#include "base/rng.h"
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

struct scene_media *media_scene_new(void)
{
    struct scene_media *m = mem_calloc(1, sizeof *m);
    m->fog = MEDIUM_NONE;
    m->interface_material = UINT32_MAX;
    m->method = MEDIA_MARCH_BEAM;
    m->photons = 100000;
    m->skip_bound = 0.01f;
    m->knn = 50;
    m->shadow_cache = 1;
    m->surface_photons = 1;
    m->max_photon_depth = 16;
    return m;
}

void photon_map_free(struct photon_map **pm); /* photonmap.c */

void media_scene_free(struct scene_media **pm)
{
    struct scene_media *m = *pm;
    if (!m)
        return;
    for (uint32_t i = 0; m->media && i < m->num_media; i++)
        grid_free(&m->media[i].grid);
    free(m->media);
    free(m->mesh_medium);
    free(m->sphere_medium);
    photon_map_free(&m->map);
    free(m);
    *pm = NULL;
}

static void set_idx(uint32_t **arr, uint32_t *n, uint32_t idx, uint32_t medium)
{
    if (idx >= *n) {
        *arr = mem_realloc(*arr, sizeof **arr * ((size_t)idx + 1));
        for (uint32_t i = *n; i <= idx; i++)
            (*arr)[i] = MEDIUM_NONE;
        *n = idx + 1;
    }
    (*arr)[idx] = medium;
}

void media_set_mesh(struct scene_media *m, uint32_t idx, uint32_t medium)
{
    set_idx(&m->mesh_medium, &m->num_mesh_medium, idx, medium);
}

void media_set_sphere(struct scene_media *m, uint32_t idx, uint32_t medium)
{
    set_idx(&m->sphere_medium, &m->num_sphere_medium, idx, medium);
}

uint32_t media_mesh_inside(const struct scene_media *m, uint32_t idx)
{
    return m && idx < m->num_mesh_medium ? m->mesh_medium[idx] : MEDIUM_NONE;
}

uint32_t media_sphere_inside(const struct scene_media *m, uint32_t idx)
{
    return m && idx < m->num_sphere_medium ? m->sphere_medium[idx] : MEDIUM_NONE;
}

static const char *const method_names[MEDIA_METHOD_COUNT_] = {"vpt", "march", "beam"};

const char *media_method_name(enum media_method m)
{
    return (unsigned)m < MEDIA_METHOD_COUNT_ ? method_names[m] : "?";
}

int media_method_from_name(const char *name, enum media_method *out)
{
    for (int i = 0; i < MEDIA_METHOD_COUNT_; i++)
        if (strcmp(name, method_names[i]) == 0) {
            *out = (enum media_method)i;
            return 0;
        }
    return -1;
}

static int nonneg3(vec3 v, float hi)
{
    return v3_is_finite(v) && v.x >= 0 && v.y >= 0 && v.z >= 0 && v.x <= hi && v.y <= hi && v.z <= hi;
}

int media_validate(const struct scene *s, char *err, size_t errlen)
{
    const struct scene_media *m = s->media;
    if (!m)
        return 0;
    for (uint32_t i = 0; i < m->num_media; i++) {
        const struct medium *md = &m->media[i];
        if (!nonneg3(md->sigma_a, 1e30f) || !nonneg3(md->sigma_s, 1e30f) || !nonneg3(md->emission, 1e30f) ||
            !(md->g > -1.0f && md->g < 1.0f)) {
            str_fmt(err, errlen, "medium \"%s\": coefficients must be in [0, 1e30] and g in (-1, 1)", md->name);
            return -1;
        }
    }
    if (m->fog != MEDIUM_NONE && m->fog >= m->num_media) {
        str_fmt(err, errlen, "fog medium index out of range");
        return -1;
    }
    for (uint32_t i = 0; i < m->num_mesh_medium; i++)
        if (m->mesh_medium[i] != MEDIUM_NONE && (m->mesh_medium[i] >= m->num_media || i >= s->num_meshes)) {
            str_fmt(err, errlen, "mesh medium out of range");
            return -1;
        }
    for (uint32_t i = 0; i < m->num_sphere_medium; i++)
        if (m->sphere_medium[i] != MEDIUM_NONE && (m->sphere_medium[i] >= m->num_media || i >= s->num_spheres)) {
            str_fmt(err, errlen, "sphere medium out of range");
            return -1;
        }
    if (m->interface_material != UINT32_MAX && m->interface_material >= s->num_materials) {
        str_fmt(err, errlen, "interface material out of range");
        return -1;
    }
    if ((unsigned)m->method >= MEDIA_METHOD_COUNT_ || !(m->step >= 0.0f) || !isfinite(m->step) ||
        !(m->radius >= 0.0f) || !isfinite(m->radius) || !(m->skip_bound >= 0.0f && m->skip_bound <= 1.0f) ||
        m->photons > (1ull << 32) || m->max_photon_depth < 1 || m->max_photon_depth > 1024) {
        str_fmt(err, errlen, "volume settings out of range");
        return -1;
    }
    return 0;
}

static float tr1(float sigma_t, float d)
{
    if (sigma_t == 0.0f)
        return 1.0f;
    return expf(-sigma_t * d); /* d = inf gives 0 */
}

vec3 medium_transmittance(const struct medium *m, float d)
{
    return v3(tr1(m->sigma_t.x, d), tr1(m->sigma_t.y, d), tr1(m->sigma_t.z, d));
}

static float emit1(float sigma_t, float e, float d)
{
    if (e == 0.0f)
        return 0.0f;
    if (sigma_t == 0.0f)
        return isfinite(d) ? e * d : 0.0f;
    /* (1 - exp(-x)) / sigma_t without cancellation for small x. */
    float x = sigma_t * d;
    return e * (-expm1f(-x)) / sigma_t;
}

vec3 medium_emission_integral(const struct medium *m, float d)
{
    return v3(emit1(m->sigma_t.x, m->emission.x, d), emit1(m->sigma_t.y, m->emission.y, d),
              emit1(m->sigma_t.z, m->emission.z, d));
}

static float comp(vec3 v, int c) { return c == 0 ? v.x : (c == 1 ? v.y : v.z); }

static vec3 channel_probs(vec3 chan)
{
    float cs = chan.x + chan.y + chan.z;
    if (cs > 0.0f && isfinite(cs) && chan.x >= 0 && chan.y >= 0 && chan.z >= 0)
        return v3_add(v3_scale(chan, 0.9f / cs), v3(0.1f / 3.0f, 0.1f / 3.0f, 0.1f / 3.0f));
    return v3(1.0f / 3.0f, 1.0f / 3.0f, 1.0f / 3.0f);
}

float medium_flight_pdf(const struct medium *m, vec3 chan, float t)
{
    vec3 pc = channel_probs(chan), tr = medium_transmittance(m, t);
    return pc.x * m->sigma_t.x * tr.x + pc.y * m->sigma_t.y * tr.y + pc.z * m->sigma_t.z * tr.z;
}

int medium_sample_distance(const struct medium *m, float tmax, vec3 chan, float u_channel, float u, float *t,
                           vec3 *weight)
{
    /* Channel probabilities: 0.9 in proportion to chan (the path throughput: history-aware
     * spectral MIS, Kutz et al. 2017) and 0.1 uniform, so every channel keeps a share and
     * no pdf can underflow; uniform when chan is black or not finite. */
    vec3 pc = channel_probs(chan);
    int c = u_channel < pc.x ? 0 : (u_channel < pc.x + pc.y ? 1 : 2);
    float st = comp(m->sigma_t, c);
    float ts = INFINITY;
    if (st > 0.0f)
        ts = -log1pf(-u) / st; /* u < 1 */
    if (ts < tmax) {
        vec3 tr = medium_transmittance(m, ts);
        float pdf = pc.x * m->sigma_t.x * tr.x + pc.y * m->sigma_t.y * tr.y + pc.z * m->sigma_t.z * tr.z;
        /* pdf >= P_c st (1 - u) > 0: the chosen channel's own term. */
        *t = ts;
        *weight = v3_scale(v3_mul(m->sigma_s, tr), 1.0f / pdf);
        return 1;
    }
    vec3 tr = medium_transmittance(m, tmax);
    float p = pc.x * tr.x + pc.y * tr.y + pc.z * tr.z;
    *t = tmax;
    *weight = p > 0.0f ? v3_scale(tr, 1.0f / p) : v3(0, 0, 0);
    return 0;
}

float phase_hg(float cos_theta, float g)
{
    double gg = g, d = 1.0 + gg * gg - 2.0 * gg * cos_theta;
    d = d > 1e-300 ? d : 1e-300;
    return (float)((1.0 - gg * gg) / (4.0 * M_PI * d * sqrt(d)));
}

float phase_hg_sample_cos(float g, float u)
{
    if (fabsf(g) < 1e-3f)
        return 1.0f - 2.0f * u;
    double gg = g, s = (1.0 - gg * gg) / (1.0 - gg + 2.0 * gg * u);
    double c = (1.0 + gg * gg - s * s) / (2.0 * gg);
    return (float)(c < -1.0 ? -1.0 : (c > 1.0 ? 1.0 : c));
}

float phase_hg_sample(vec3 d_in, float g, float u1, float u2, vec3 *d_out)
{
    float c = phase_hg_sample_cos(g, u1);
    float s = sqrtf(fmaxf(0.0f, 1.0f - c * c)), sp, cp;
    sincos_2pi(u2, &sp, &cp);
    vec3 t, b;
    v3_basis(d_in, &t, &b);
    *d_out = v3_normalize(v3_add(v3_scale(d_in, c), v3_add(v3_scale(t, s * cp), v3_scale(b, s * sp))));
    return phase_hg(c, g);
}

/* ---- density grids ---- */


int grid_parse(const uint8_t *data, size_t size, struct density_grid *out, char *err, size_t errlen)
{
    memset(out, 0, sizeof *out);
    if (size < 20 || memcmp(data, GRID_MAGIC, 8) != 0) {
        str_fmt(err, errlen, "not a density grid (expected the \"%s\" header)", GRID_MAGIC);
        return -1;
    }
    uint32_t nx = bytes_get_u32(data + 8), ny = bytes_get_u32(data + 12), nz = bytes_get_u32(data + 16);
    if (nx < 1 || ny < 1 || nz < 1 || (uint64_t)nx * ny * nz > GRID_MAX_VOXELS) {
        str_fmt(err, errlen, "grid size %ux%ux%u out of range (1.. and at most %u voxels)", nx, ny, nz, GRID_MAX_VOXELS);
        return -1;
    }
    uint64_t n = (uint64_t)nx * ny * nz;
    if (size != 20 + 4 * n) {
        str_fmt(err, errlen, "grid of %ux%ux%u needs %llu bytes, the file has %zu", nx, ny, nz,
                (unsigned long long)(20 + 4 * n), size);
        return -1;
    }
    float *v = mem_alloc(sizeof(float) * n);
    for (uint64_t i = 0; i < n; i++) {
        uint32_t u = bytes_get_u32(data + 20 + 4 * i);
        memcpy(&v[i], &u, 4);
        if (!isfinite(v[i]) || v[i] < 0.0f) {
            free(v);
            str_fmt(err, errlen, "voxel %llu: density must be finite and >= 0", (unsigned long long)i);
            return -1;
        }
    }
    out->nx = nx, out->ny = ny, out->nz = nz;
    out->data = v;
    out->scale = 1.0f;
    out->grid_to_world = out->world_to_grid = xform_identity();
    return 0;
}

void grid_finish(struct density_grid *g, const struct xform *grid_to_world, float scale)
{
    g->scale = scale;
    g->grid_to_world = *grid_to_world;
    g->world_to_grid = motion_xform_inverse(grid_to_world);
    uint32_t lo[3] = {UINT32_MAX, UINT32_MAX, UINT32_MAX}, hi[3] = {0, 0, 0};
    float mx = 0.0f;
    for (uint32_t z = 0; z < g->nz; z++)
        for (uint32_t y = 0; y < g->ny; y++)
            for (uint32_t x = 0; x < g->nx; x++) {
                float v = g->data[((size_t)z * g->ny + y) * g->nx + x];
                if (!(v > 0.0f))
                    continue;
                mx = fmaxf(mx, v);
                uint32_t c[3] = {x, y, z};
                for (int k = 0; k < 3; k++) {
                    lo[k] = c[k] < lo[k] ? c[k] : lo[k];
                    hi[k] = c[k] > hi[k] ? c[k] : hi[k];
                }
            }
    g->max_density = mx * scale;
    uint32_t n[3] = {g->nx, g->ny, g->nz};
    float ol[3], oh[3];
    for (int k = 0; k < 3; k++) {
        if (lo[k] == UINT32_MAX) {
            ol[k] = 1.0f, oh[k] = 0.0f; /* empty */
            continue;
        }
        /* Trilinear support of voxels lo..hi reaches the neighbouring centres. */
        ol[k] = fmaxf(0.0f, ((float)lo[k] - 0.5f) / (float)n[k]);
        oh[k] = fminf(1.0f, ((float)hi[k] + 1.5f) / (float)n[k]);
    }
    g->occ_lo = v3(ol[0], ol[1], ol[2]);
    g->occ_hi = v3(oh[0], oh[1], oh[2]);
    float vw = INFINITY;
    for (int k = 0; k < 3; k++) {
        vec3 col = v3(grid_to_world->m[0][k], grid_to_world->m[1][k], grid_to_world->m[2][k]);
        vw = fminf(vw, v3_length(col) / (float)n[k]);
    }
    g->voxel_world = vw;
}

void grid_free(struct density_grid **pg)
{
    if (!*pg)
        return;
    free((*pg)->data);
    free(*pg);
    *pg = NULL;
}

float grid_density(const struct density_grid *g, vec3 p)
{
    vec3 q = xform_point(&g->world_to_grid, p);
    if (!(q.x >= 0.0f && q.y >= 0.0f && q.z >= 0.0f && q.x <= 1.0f && q.y <= 1.0f && q.z <= 1.0f))
        return 0.0f;
    float u[3] = {q.x * (float)g->nx - 0.5f, q.y * (float)g->ny - 0.5f, q.z * (float)g->nz - 0.5f};
    int32_t n[3] = {(int32_t)g->nx, (int32_t)g->ny, (int32_t)g->nz}, i0[3], i1[3];
    float f[3];
    for (int k = 0; k < 3; k++) {
        float fl = floorf(u[k]);
        f[k] = u[k] - fl;
        int32_t a = (int32_t)fl;
        i0[k] = a < 0 ? 0 : (a >= n[k] ? n[k] - 1 : a);
        i1[k] = a + 1 < 0 ? 0 : (a + 1 >= n[k] ? n[k] - 1 : a + 1);
    }
#define V(x, y, z) g->data[((size_t)(z) * g->ny + (y)) * g->nx + (x)]
    float c00 = V(i0[0], i0[1], i0[2]) * (1 - f[0]) + V(i1[0], i0[1], i0[2]) * f[0];
    float c10 = V(i0[0], i1[1], i0[2]) * (1 - f[0]) + V(i1[0], i1[1], i0[2]) * f[0];
    float c01 = V(i0[0], i0[1], i1[2]) * (1 - f[0]) + V(i1[0], i0[1], i1[2]) * f[0];
    float c11 = V(i0[0], i1[1], i1[2]) * (1 - f[0]) + V(i1[0], i1[1], i1[2]) * f[0];
#undef V
    float c0 = c00 * (1 - f[1]) + c10 * f[1], c1 = c01 * (1 - f[1]) + c11 * f[1];
    return (c0 * (1 - f[2]) + c1 * f[2]) * g->scale;
}

int medium_clip(const struct medium *m, vec3 o, vec3 d, float tmax, float *t0, float *t1)
{
    *t0 = 0.0f;
    *t1 = tmax;
    if (!m->grid)
        return tmax > 0.0f;
    const struct density_grid *g = m->grid;
    vec3 og = xform_point(&g->world_to_grid, o), dg = xform_vector(&g->world_to_grid, d);
    float a = 0.0f, b = tmax;
    if (!v3_clip_box(og, dg, g->occ_lo, g->occ_hi, &a, &b) || !(a < b))
        return 0;
    *t0 = a;
    *t1 = b;
    return 1;
}

float medium_march_step(const struct medium *m, float step)
{
    return m->grid ? fminf(step, 0.5f * m->grid->voxel_world) : step;
}

#define TRACK_MAX 1000000

vec3 medium_tr_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key, int ratio)
{
    if (!m->grid)
        return medium_transmittance(m, len);
    float c0, c1;
    if (!medium_clip(m, o, d, len, &c0, &c1))
        return v3(1, 1, 1);
    float st_max = v3_max_component(m->sigma_t), mu = st_max * m->grid->max_density;
    if (!(mu > 0.0f))
        return v3(1, 1, 1);
    if (ratio) {
        vec3 tr = v3(1, 1, 1);
        float t = c0;
        for (uint32_t k = 0; k < TRACK_MAX; k++) {
            t += -log1pf(-rng_uniform(key, k)) / mu;
            if (!(t < c1))
                break;
            float rho = grid_density(m->grid, v3_add(o, v3_scale(d, t)));
            tr = v3_mul(tr, v3(1.0f - m->sigma_t.x * rho / mu, 1.0f - m->sigma_t.y * rho / mu,
                               1.0f - m->sigma_t.z * rho / mu));
            if (v3_max_component(tr) < 1e-7f)
                return v3(0, 0, 0);
        }
        return tr;
    }
    /* Jensen: a jittered march of the optical depth at half-voxel steps. */
    float dx = 0.5f * m->grid->voxel_world;
    if ((c1 - c0) / dx > 100000.0f)
        dx = (c1 - c0) / 100000.0f;
    float tau = 0.0f, u = rng_uniform(key, 0);
    for (uint32_t k = 0;; k++) {
        float t = c0 + ((float)k + u) * dx;
        if (!(t < c1))
            break;
        tau += grid_density(m->grid, v3_add(o, v3_scale(d, t))) * dx;
    }
    return v3(expf(-m->sigma_t.x * tau), expf(-m->sigma_t.y * tau), expf(-m->sigma_t.z * tau));
}

vec3 medium_emission_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key)
{
    if (!m->grid)
        return medium_emission_integral(m, len);
    float c0, c1;
    if (v3_is_black(m->emission) || !medium_clip(m, o, d, len, &c0, &c1))
        return v3(0, 0, 0);
    float span = c1 - c0, t = c0 + rng_uniform(key, 0) * span;
    if (!(span > 0.0f) || !isfinite(span) || !(t < c1))
        return v3(0, 0, 0);
    float rho = grid_density(m->grid, v3_add(o, v3_scale(d, t)));
    if (!(rho > 0.0f))
        return v3(0, 0, 0);
    vec3 tr = medium_tr_segment(m, o, d, t, rng_mix64(key ^ 0x454d4954ull), 1);
    return v3_scale(v3_mul(tr, m->emission), rho * span);
}

int medium_sample_flight(const struct medium *m, vec3 o, vec3 d, float tmax, vec3 chan, uint64_t key, float *t,
                         vec3 *weight)
{
    if (!m->grid)
        return medium_sample_distance(m, tmax, chan, rng_uniform(key, 0), rng_uniform(key, 1), t, weight);
    *t = tmax;
    *weight = v3(1, 1, 1);
    float c0, c1;
    if (!medium_clip(m, o, d, tmax, &c0, &c1))
        return 0;
    float mu = v3_max_component(m->sigma_t) * m->grid->max_density;
    if (!(mu > 0.0f))
        return 0;
    /* Weighted delta tracking: a tentative collision is real with probability
     * avg(sigma_t(x)) / mu; the weights keep every channel unbiased. */
    vec3 w = v3(1, 1, 1);
    float tt = c0;
    for (uint32_t k = 0; k < TRACK_MAX; k++) {
        tt += -log1pf(-rng_uniform(key, 2 * k)) / mu;
        if (!(tt < c1))
            break;
        float rho = grid_density(m->grid, v3_add(o, v3_scale(d, tt)));
        vec3 st = v3_scale(m->sigma_t, rho);
        float avg = (st.x + st.y + st.z) / 3.0f, p = avg / mu;
        if (rng_uniform(key, 2 * k + 1) < p) {
            *t = tt;
            *weight = v3_mul(w, v3_scale(m->sigma_s, rho / avg));
            return 1;
        }
        float q = mu - avg;
        w = v3_mul(w, v3((mu - st.x) / q, (mu - st.y) / q, (mu - st.z) / q));
    }
    *weight = w;
    return 0;
}

/* ---- shadow transmittance cache (Jensen's methods in grids) ---- */

void grid_world_box(const struct density_grid *g, vec3 *lo, vec3 *hi)
{
    *lo = v3(INFINITY, INFINITY, INFINITY);
    *hi = v3(-INFINITY, -INFINITY, -INFINITY);
    for (int k = 0; k < 8; k++) {
        vec3 q = v3(k & 1 ? g->occ_hi.x : g->occ_lo.x, k & 2 ? g->occ_hi.y : g->occ_lo.y, k & 4 ? g->occ_hi.z : g->occ_lo.z);
        vec3 w = xform_point(&g->grid_to_world, q);
        *lo = v3(fminf(lo->x, w.x), fminf(lo->y, w.y), fminf(lo->z, w.z));
        *hi = v3(fmaxf(hi->x, w.x), fmaxf(hi->y, w.y), fmaxf(hi->z, w.z));
    }
}

float grid_optical_depth(const struct medium *m, vec3 a, vec3 b)
{
    if (!m->grid)
        return 0.0f;
    vec3 ab = v3_sub(b, a);
    float len = v3_length(ab);
    if (!(len > 0.0f))
        return 0.0f;
    vec3 d = v3_scale(ab, 1.0f / len);
    float c0, c1;
    if (!medium_clip(m, a, d, len, &c0, &c1))
        return 0.0f;
    /* Midpoint rule at steps of at most half a voxel: deterministic, no random number. */
    float span = c1 - c0, steps = ceilf(span / (0.5f * m->grid->voxel_world));
    uint32_t n = steps < 1.0f ? 1u : (steps > 100000.0f ? 100000u : (uint32_t)steps);
    float dx = span / (float)n;
    double tau = 0.0;
    for (uint32_t k = 0; k < n; k++)
        tau += grid_density(m->grid, v3_add(a, v3_scale(d, c0 + ((float)k + 0.5f) * dx)));
    return (float)(tau * dx);
}

struct tr_fill { struct tr_cache *c; const struct medium *m; uint32_t threads, id; };

static void *tr_cache_fill(void *arg)
{
    const struct tr_fill *f = arg;
    struct tr_cache *c = f->c;
    for (uint32_t z = f->id; z < c->n[2]; z += f->threads)
        for (uint32_t y = 0; y < c->n[1]; y++)
            for (uint32_t x = 0; x < c->n[0]; x++) {
                vec3 p = v3(c->lo.x + (float)x * c->cell.x, c->lo.y + (float)y * c->cell.y, c->lo.z + (float)z * c->cell.z);
                c->tau[((size_t)z * c->n[1] + y) * c->n[0] + x] = grid_optical_depth(f->m, p, c->light);
            }
    return NULL;
}

int tr_cache_build(struct tr_cache *c, const struct medium *m, vec3 light, uint32_t threads)
{
    memset(c, 0, sizeof *c);
    const struct density_grid *g = m->grid;
    if (!g || !(g->occ_lo.x <= g->occ_hi.x && g->occ_lo.y <= g->occ_hi.y && g->occ_lo.z <= g->occ_hi.z))
        return 0;
    /* World box of the occupied grid box: every point where a march step can land. */
    vec3 lo, hi;
    grid_world_box(g, &lo, &hi);
    float ext[3] = {hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}, cell[3];
    if (!(g->voxel_world > 0.0f) || !isfinite(ext[0] + ext[1] + ext[2]))
        return 0;
    for (int k = 0; k < 3; k++) {
        /* One vertex per voxel, at most TR_CACHE_MAX_N per axis. */
        float nv = ceilf(ext[k] / (TR_CACHE_SPACING * g->voxel_world));
        nv = nv < 1.0f ? 1.0f : (nv > (float)(TR_CACHE_MAX_N - 1) ? (float)(TR_CACHE_MAX_N - 1) : nv);
        c->n[k] = (uint32_t)nv + 1;
        cell[k] = ext[k] > 0.0f ? ext[k] / nv : 1.0f;
    }
    c->lo = lo;
    c->hi = hi;
    c->cell = v3(cell[0], cell[1], cell[2]);
    c->inv_cell = v3(1.0f / cell[0], 1.0f / cell[1], 1.0f / cell[2]);
    c->light = light;
    c->tau = mem_alloc(sizeof *c->tau * c->n[0] * c->n[1] * c->n[2]);
    threads = threads < 1 ? 1 : (threads > 64 ? 64 : threads);
    pthread_t th[64];
    struct tr_fill f[64];
    int started[64] = {0};
    for (uint32_t i = 0; i < threads; i++)
        f[i] = (struct tr_fill){c, m, threads, i};
    for (uint32_t i = 1; i < threads; i++)
        started[i] = pthread_create(&th[i], NULL, tr_cache_fill, &f[i]) == 0;
    tr_cache_fill(&f[0]);
    for (uint32_t i = 1; i < threads; i++) {
        if (started[i])
            pthread_join(th[i], NULL);
        else
            tr_cache_fill(&f[i]); /* no thread: fill its slices here (same values) */
    }
    return 1;
}

void tr_cache_free(struct tr_cache *c)
{
    free(c->tau);
    c->tau = NULL;
}

int tr_cache_tau_from(const struct tr_cache *c, vec3 p, float *tau)
{
    if (!c->tau || !v3_is_finite(p))
        return 0;
    if (tr_cache_tau(c, p, tau))
        return 1;
    /* The part of p + t (light - p), t in [0, 1], inside the lattice's box. */
    vec3 d = v3_sub(c->light, p);
    float t0 = 0.0f, t1 = 1.0f;
    *tau = 0.0f;
    if (!v3_clip_box(p, d, c->lo, c->hi, &t0, &t1))
        return 1; /* the segment never enters the box: no density on it */
    /* The entry point, clamped onto the box against rounding. */
    vec3 q = v3_add(p, v3_scale(d, t0));
    q = v3(fminf(fmaxf(q.x, c->lo.x), c->hi.x), fminf(fmaxf(q.y, c->lo.y), c->hi.y), fminf(fmaxf(q.z, c->lo.z), c->hi.z));
    if (!tr_cache_tau(c, q, tau))
        *tau = 0.0f;
    return 1;
}

int tr_cache_tau(const struct tr_cache *c, vec3 p, float *tau)
{
    if (!c->tau)
        return 0;
    float u[3] = {(p.x - c->lo.x) * c->inv_cell.x, (p.y - c->lo.y) * c->inv_cell.y, (p.z - c->lo.z) * c->inv_cell.z};
    uint32_t i[3];
    float f[3];
    for (int k = 0; k < 3; k++) {
        if (!(u[k] >= 0.0f && u[k] <= (float)(c->n[k] - 1)))
            return 0;
        float fl = floorf(u[k]);
        i[k] = (uint32_t)fl;
        if (i[k] >= c->n[k] - 1)
            i[k] = c->n[k] >= 2 ? c->n[k] - 2 : 0;
        f[k] = c->n[k] >= 2 ? u[k] - (float)i[k] : 0.0f;
    }
    uint32_t sx = c->n[0] >= 2 ? 1 : 0, sy = c->n[1] >= 2 ? c->n[0] : 0,
             sz = c->n[2] >= 2 ? c->n[0] * c->n[1] : 0;
    const float *v = c->tau + ((size_t)i[2] * c->n[1] + i[1]) * c->n[0] + i[0];
    float c00 = v[0] * (1 - f[0]) + v[sx] * f[0], c10 = v[sy] * (1 - f[0]) + v[sy + sx] * f[0];
    float c01 = v[sz] * (1 - f[0]) + v[sz + sx] * f[0], c11 = v[sz + sy] * (1 - f[0]) + v[sz + sy + sx] * f[0];
    float c0 = c00 * (1 - f[1]) + c10 * f[1], c1 = c01 * (1 - f[1]) + c11 * f[1];
    *tau = c0 * (1 - f[2]) + c1 * f[2];
    return 1;
}
