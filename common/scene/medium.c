/* Media model, validation and the closed forms of homogeneous media (see medium.h).
 * Exponentials are taken in float from float products, the same expression on every
 * machine; HG sampling runs in double, where g = +-0.999 loses nothing. */
#include "scene/medium.h"
#include "base/log.h"
#include <math.h>
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
    m->indirect = MEDIA_INDIRECT_GATHER;
    m->max_photon_depth = 0; /* the camera paths' max_depth (media_max_photon_depth) */
    return m;
}

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

static const char *const method_names[MEDIA_METHOD_COUNT_] = {"vpt", "march", "beam", "beams"};

const char *media_method_name(enum media_method m)
{
    return (unsigned)m < MEDIA_METHOD_COUNT_ ? method_names[m] : "?";
}

/* The index of name in names[0..n), or -1. */
static int name_index(const char *const *names, int n, const char *name)
{
    for (int i = 0; i < n; i++)
        if (strcmp(name, names[i]) == 0)
            return i;
    return -1;
}

int media_method_from_name(const char *name, enum media_method *out)
{
    int i = name_index(method_names, MEDIA_METHOD_COUNT_, name);
    if (i < 0)
        return -1;
    *out = (enum media_method)i;
    return 0;
}

static const char *const indirect_names[MEDIA_INDIRECT_COUNT_] = {"gather", "path"};

const char *media_indirect_name(enum media_indirect m)
{
    return (unsigned)m < MEDIA_INDIRECT_COUNT_ ? indirect_names[m] : "?";
}

int media_indirect_from_name(const char *name, enum media_indirect *out)
{
    int i = name_index(indirect_names, MEDIA_INDIRECT_COUNT_, name);
    if (i < 0)
        return -1;
    *out = (enum media_indirect)i;
    return 0;
}

int media_wants_surface_photons(const struct scene_media *m)
{
    return m->surface_photons && m->indirect == MEDIA_INDIRECT_GATHER;
}

static float tr1(float sigma_t, float d)
{
    if (sigma_t == 0.0f)
        return 1.0f;
    return expf(-sigma_t * d); /* d = inf gives 0 */
}

vec3 medium_transmittance(const struct medium *m, float d)
{
    float tx = tr1(m->sigma_t.x, d);
    if (m->sigma_t.y == m->sigma_t.x && m->sigma_t.z == m->sigma_t.x)
        return v3(tx, tx, tx); /* grey: the same value, one exponential */
    return v3(tx, tr1(m->sigma_t.y, d), tr1(m->sigma_t.z, d));
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

void grid_free(struct density_grid **pg)
{
    if (!*pg)
        return;
    free((*pg)->data);
    free(*pg);
    *pg = NULL;
}

double phase_forward_mass(float g)
{
    double gg = (double)g, mc = (double)MEDIUM_FORWARD_COS;
    if (fabs(gg) < 1e-4)
        return 0.5 * (1.0 - mc);
    /* HG's cdf in cos theta: (1 - g^2) / (2g) (1 / sqrt(1 + g^2 - 2 g mu) - 1 / (1 + g)). */
    double f = 1.0 - (1.0 - gg * gg) / (2.0 * gg) * (1.0 / sqrt(1.0 + gg * gg - 2.0 * gg * mc) - 1.0 / (1.0 + gg));
    return f < 0.0 ? 0.0 : (f > 1.0 ? 1.0 : f);
}

float phase_hg_cut(float cos_theta, float g)
{
    return cos_theta > MEDIUM_FORWARD_COS ? 0.0f : phase_hg(cos_theta, g);
}

struct medium medium_forward_cut(const struct medium *md)
{
    struct medium cut = *md;
    if (v3_is_black(md->sigma_s))
        return cut;
    float f = (float)phase_forward_mass(md->g);
    vec3 st = v3_sub(md->sigma_t, v3_scale(md->sigma_s, f));
    cut.sigma_t = v3(fmaxf(st.x, md->sigma_a.x), fmaxf(st.y, md->sigma_a.y), fmaxf(st.z, md->sigma_a.z));
    return cut;
}
