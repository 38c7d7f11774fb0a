/* Rough materials (GGX, material.c and microfacet.h): D normalisation, chi-square tests of
 * sampling against the evaluated pdf for conductor reflection and dielectric reflection
 * plus transmission at roughness 0.0032 (the smallest rough one) to 1, isotropic and anisotropic, sample weights
 * against eval / pdf, reciprocity (the eta^2 form for transmission), energy (directional
 * albedo: at most 1, with the single-scattering loss stated), and the smooth limits
 * (roughness below 0.0032 is exactly today's mirror and glass). */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "base/rng.h"
#include "scene/material.h"
#include "scene/microfacet.h"
#include "helpers.h"

static struct material rough(enum material_type type, float ur, float vr)
{
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = type;
    m.albedo = v3(0.8f, 0.8f, 0.8f);
    m.reflectance = v3(1, 1, 1);
    m.transmittance = v3(1, 1, 1);
    m.ior = 1.5f;
    m.eta = v3(0.2f, 0.92f, 1.1f);
    m.k = v3(3.9f, 2.45f, 2.14f);
    m.alpha_x = microfacet_alpha(ur);
    m.alpha_y = microfacet_alpha(vr);
    return m;
}

static vec3 dir_of(float theta_deg, float phi_deg)
{
    float t = theta_deg * (float)M_PI / 180.0f, p = phi_deg * (float)M_PI / 180.0f;
    return v3(sinf(t) * cosf(p), sinf(t) * sinf(p), cosf(t));
}

Test(microfacet, d_projected_area_is_one)
{
    /* Integral of D(wm) cos(theta_m) over the hemisphere = 1 (in slope space, exactly). */
    const float as[][2] = {{0.01f, 0.01f}, {0.1f, 0.1f}, {0.5f, 0.5f}, {1.0f, 1.0f}, {0.05f, 0.6f}};
    for (int k = 0; k < 5; k++) {
        struct ggx g = {as[k][0], as[k][1]};
        double sum = 0.0;
        enum { N = 600 };
        for (int i = 0; i < N; i++)
            for (int j = 0; j < N; j++) {
                /* wm from the slopes (tan(pi (a - 1/2)) alpha): Jacobian in closed form. */
                double a = (i + 0.5) / N, b = (j + 0.5) / N;
                double sx = tan(M_PI * (a - 0.5)), sy = tan(M_PI * (b - 0.5));
                double dsx = M_PI * (1 + sx * sx) / N, dsy = M_PI * (1 + sy * sy) / N;
                double x = sx * g.ax, y = sy * g.ay, l = sqrt(x * x + y * y + 1);
                vec3 wm = v3((float)(x / l), (float)(y / l), (float)(1 / l));
                /* d omega = cos^3 dxslope dyslope in unscaled slopes */
                double domega = dsx * g.ax * dsy * g.ay / (l * l * l);
                sum += ggx_d(&g, wm) * wm.z * domega;
            }
        cr_assert(fabs(sum - 1.0) < 2e-3, "alpha %g %g: %g", (double)g.ax, (double)g.ay, sum);
    }
}

/* ---- chi-square: bins over the microfacet normal's scaled slopes ---- */

enum { BINS = 16, SUB = 4 };

struct chi_ctx {
    const struct material *m;
    vec3 wo;
    int front;
    double eta; /* far side over wo's side */
    double ax, ay;
};

/* wi for bin coordinates (a, b) in [0, 1]^2 of lobe `t` (0 reflect, 1 transmit); 0 if none. */
static int wi_of(const struct chi_ctx *c, double a, double b, int t, double wi[3])
{
    double sx = tan(M_PI * (a - 0.5)) * c->ax, sy = tan(M_PI * (b - 0.5)) * c->ay, l = sqrt(sx * sx + sy * sy + 1);
    double wm[3] = {-sx / l, -sy / l, 1 / l}, wo[3] = {c->wo.x, c->wo.y, c->wo.z};
    double co = wo[0] * wm[0] + wo[1] * wm[1] + wo[2] * wm[2];
    if (co <= 0)
        return 0;
    if (!t) {
        for (int k = 0; k < 3; k++)
            wi[k] = 2 * co * wm[k] - wo[k];
        return wi[2] > 0;
    }
    double s2t = (1 - co * co) / (c->eta * c->eta);
    if (s2t >= 1)
        return 0;
    double ct = sqrt(1 - s2t);
    for (int k = 0; k < 3; k++)
        wi[k] = -wo[k] / c->eta + (co / c->eta - ct) * wm[k];
    double n = sqrt(wi[0] * wi[0] + wi[1] * wi[1] + wi[2] * wi[2]);
    for (int k = 0; k < 3; k++)
        wi[k] /= n;
    return wi[2] < 0;
}

static double pdf_at(const struct chi_ctx *c, const double wi[3])
{
    float pdf;
    material_eval(c->m, v3(0, 0, 1), c->wo, v3((float)wi[0], (float)wi[1], (float)wi[2]), c->front, &pdf);
    return pdf;
}

/* Probability of bin (i, j) of lobe t: pdf(wi) |dwi/da x dwi/db| integrated by midpoints. */
static double bin_prob_sub(const struct chi_ctx *c, int i, int j, int t, int sub, int *valid)
{
    double sum = 0.0, h = 1e-6;
    *valid = 0;
    for (int si = 0; si < sub; si++)
        for (int sj = 0; sj < sub; sj++) {
            double a = (i + (si + 0.5) / sub) / BINS, b = (j + (sj + 0.5) / sub) / BINS;
            double w[3], wa0[3], wa1[3], wb0[3], wb1[3];
            if (!wi_of(c, a, b, t, w) || !wi_of(c, a - h, b, t, wa0) || !wi_of(c, a + h, b, t, wa1) ||
                !wi_of(c, a, b - h, t, wb0) || !wi_of(c, a, b + h, t, wb1))
                continue;
            double da[3], db[3];
            for (int k = 0; k < 3; k++) {
                da[k] = (wa1[k] - wa0[k]) / (2 * h);
                db[k] = (wb1[k] - wb0[k]) / (2 * h);
            }
            double cx = da[1] * db[2] - da[2] * db[1], cy = da[2] * db[0] - da[0] * db[2], cz = da[0] * db[1] - da[1] * db[0];
            double p = pdf_at(c, w);
            *valid += p > 0.0;
            sum += p * sqrt(cx * cx + cy * cy + cz * cz);
        }
    return sum / ((double)sub * sub * BINS * BINS);
}

/* A bin the lobe's edge (the horizon, total internal reflection) crosses is integrated finer. */
static double bin_prob(const struct chi_ctx *c, int i, int j, int t)
{
    int valid, v2;
    double p = bin_prob_sub(c, i, j, t, SUB, &valid), p2 = bin_prob_sub(c, i, j, t, 2 * SUB, &v2);
    if ((valid > 0 && valid < SUB * SUB) || fabs(p - p2) > 2e-3 * p2)
        p2 = bin_prob_sub(c, i, j, t, 8 * SUB, &valid);
    return p2;
}

/* The bin of a sampled wi, from its (generalised) half vector. */
static int bin_of(const struct chi_ctx *c, vec3 wi, int *t)
{
    double wo[3] = {c->wo.x, c->wo.y, c->wo.z}, w[3] = {wi.x, wi.y, wi.z}, h[3];
    *t = w[2] < 0;
    double s = *t ? c->eta : 1.0;
    for (int k = 0; k < 3; k++)
        h[k] = wo[k] + s * w[k];
    if (h[2] < 0)
        for (int k = 0; k < 3; k++)
            h[k] = -h[k];
    if (!(h[2] > 0))
        return -1;
    double sx = -h[0] / (h[2] * c->ax), sy = -h[1] / (h[2] * c->ay);
    int i = (int)((atan(sx) / M_PI + 0.5) * BINS), j = (int)((atan(sy) / M_PI + 0.5) * BINS);
    i = i < 0 ? 0 : (i >= BINS ? BINS - 1 : i);
    j = j < 0 ? 0 : (j >= BINS ? BINS - 1 : j);
    return i * BINS + j;
}

static void chi_square(const struct material *m, vec3 wo, int front, const char *what)
{
    enum { N = 100000, NB = 2 * BINS * BINS };
    struct chi_ctx c = {m, wo, front, front ? m->ior : 1.0 / m->ior, fmax(m->alpha_x, 1e-6), fmax(m->alpha_y, 1e-6)};
    static double expect[NB];
    static int count[NB];
    memset(count, 0, sizeof count);
    int lobes = m->type == MATERIAL_DIELECTRIC ? 2 : 1;
    double total = 0.0;
    for (int t = 0; t < lobes; t++)
        for (int i = 0; i < BINS; i++)
            for (int j = 0; j < BINS; j++)
                total += expect[t * BINS * BINS + i * BINS + j] = N * bin_prob(&c, i, j, t);
    uint64_t key = rng_key(17, 0, (uint64_t)(m->alpha_x * 1e6f), (uint32_t)front);
    int got = 0;
    for (int s = 0; s < N; s++) {
        struct bsdf_sample bs;
        material_sample(m, v3(0, 0, 1), wo, front, rng_uniform(key, 2 * (uint32_t)s), rng_uniform(key, 2 * (uint32_t)s + 1), &bs);
        if (!(bs.pdf > 0.0f))
            continue;
        int t, b = bin_of(&c, bs.wi, &t);
        cr_assert(b >= 0 && t < lobes, "%s: sample outside the lobes", what);
        count[t * BINS * BINS + b]++;
        got++;
    }
    /* Pool bins expected below 5 (in order) so every term has the chi-square's shape. */
    double chi2 = 0.0, pe = 0.0, po = 0.0;
    int dof = 0;
    for (int b = 0; b < lobes * BINS * BINS; b++) {
        pe += expect[b];
        po += count[b];
        if (pe >= 5.0) {
            chi2 += (po - pe) * (po - pe) / pe;
            dof++;
            pe = po = 0.0;
        }
    }
    if (pe > 0.0)
        chi2 += (po - pe) * (po - pe) / fmax(pe, 1.0);
    /* The samples that fail (masked, below the horizon) are what the pdf leaves out. */
    cr_assert(fabs(got - total) < 5.0 * sqrt(N) + 2e-3 * N, "%s: %d samples against %.0f expected", what, got, total);
    cr_assert(dof >= 8, "%s: %d bins", what, dof);
    cr_assert(chi2 < dof + 6.0 * sqrt(2.0 * dof), "%s: chi2 %.1f over %d bins", what, chi2, dof);
}

Test(microfacet, conductor_sampling_chi_square)
{
    const float rs[][2] = {{0.0032f, 0.0032f}, {0.01f, 0.01f}, {0.1f, 0.1f}, {0.5f, 0.5f}, {1.0f, 1.0f}, {0.1f, 0.6f}, {0.8f, 0.2f}};
    const float th[] = {15.0f, 75.0f};
    for (int k = 0; k < 7; k++)
        for (int a = 0; a < 2; a++) {
            struct material m = rough(MATERIAL_CONDUCTOR, rs[k][0], rs[k][1]);
            char what[96];
            snprintf(what, sizeof what, "conductor roughness %g/%g theta %g", (double)rs[k][0], (double)rs[k][1], (double)th[a]);
            chi_square(&m, dir_of(th[a], 30.0f), 1, what);
        }
}

Test(microfacet, dielectric_sampling_chi_square)
{
    const float rs[][2] = {{0.0032f, 0.0032f}, {0.01f, 0.01f}, {0.1f, 0.1f}, {0.5f, 0.5f}, {1.0f, 1.0f}, {0.1f, 0.6f}};
    const float th[] = {20.0f, 70.0f};
    for (int k = 0; k < 6; k++)
        for (int a = 0; a < 2; a++)
            for (int front = 0; front < 2; front++) {
                struct material m = rough(MATERIAL_DIELECTRIC, rs[k][0], rs[k][1]);
                char what[96];
                snprintf(what, sizeof what, "dielectric roughness %g/%g theta %g front %d", (double)rs[k][0],
                         (double)rs[k][1], (double)th[a], front);
                chi_square(&m, dir_of(th[a], -40.0f), front, what);
            }
}

Test(microfacet, plastic_and_classic_sampling_chi_square)
{
    struct material m = rough(MATERIAL_CONDUCTOR, 0.3f, 0.3f);
    m.sample_all = 1; /* D cos sampling (the benchmark's baseline) */
    chi_square(&m, dir_of(45.0f, 10.0f), 1, "conductor, D cos sampling");
    struct material d = rough(MATERIAL_DIELECTRIC, 0.4f, 0.2f);
    d.sample_all = 1;
    chi_square(&d, dir_of(30.0f, 10.0f), 1, "dielectric, D cos sampling");
}

/* The weight of every sample is eval / pdf, and its pdf is eval's. */
Test(microfacet, sample_weight_is_eval_over_pdf)
{
    const enum material_type types[] = {MATERIAL_CONDUCTOR, MATERIAL_DIELECTRIC, MATERIAL_PLASTIC};
    uint64_t key = rng_key(5, 0, 0, 0);
    for (int t = 0; t < 3; t++)
        for (float r = 0.05f; r <= 1.0f; r += 0.3f)
            for (int s = 0; s < 2000; s++) {
                struct material m = rough(types[t], r, r * 0.5f);
                vec3 wo = dir_of(85.0f * rng_uniform(key, 4 * (uint32_t)s), 360.0f * rng_uniform(key, 4 * (uint32_t)s + 1));
                int front = s & 1;
                struct bsdf_sample bs;
                material_sample(&m, v3(0, 0, 1), wo, front, rng_uniform(key, 4 * (uint32_t)s + 2),
                                rng_uniform(key, 4 * (uint32_t)s + 3), &bs);
                if (!(bs.pdf > 0.0f))
                    continue;
                float pdf;
                vec3 f = material_eval(&m, v3(0, 0, 1), wo, bs.wi, front, &pdf);
                cr_assert(fabsf(pdf - bs.pdf) <= 1e-4f * pdf, "type %d: pdf %g against %g", t, (double)pdf, (double)bs.pdf);
                cr_assert(fabsf(f.y / pdf - bs.weight.y) <= 1e-4f * bs.weight.y + 1e-7f, "type %d", t);
                cr_assert(bs.is_delta == 0);
            }
}

Test(microfacet, reciprocity)
{
    uint64_t key = rng_key(6, 0, 0, 0);
    for (int s = 0; s < 3000; s++) {
        vec3 a = dir_of(89.0f * rng_uniform(key, 4 * (uint32_t)s), 360.0f * rng_uniform(key, 4 * (uint32_t)s + 1));
        vec3 b = dir_of(89.0f * rng_uniform(key, 4 * (uint32_t)s + 2), 360.0f * rng_uniform(key, 4 * (uint32_t)s + 3));
        float r = 0.05f + 0.9f * (float)(s % 10) / 10.0f, p1, p2;
        /* Reflection, anisotropic: f(a, b) = f(b, a) (eval includes cos of wi). */
        const enum material_type types[] = {MATERIAL_CONDUCTOR, MATERIAL_DIELECTRIC, MATERIAL_PLASTIC};
        for (int t = 0; t < 3; t++) {
            struct material m = rough(types[t], r, 0.7f * r);
            vec3 fab = material_eval(&m, v3(0, 0, 1), a, b, 1, &p1), fba = material_eval(&m, v3(0, 0, 1), b, a, 1, &p2);
            double x = fab.y / b.z, y = fba.y / a.z;
            cr_assert(fabs(x - y) <= 2e-4 * fmax(x, y) + 1e-9, "type %d: %g against %g", t, x, y);
        }
        /* Transmission, isotropic (Veach 1997, 5.2): f(wi -> wo) / n_o^2 = f(wo -> wi) / n_i^2
         * for radiance-scaled BTDFs: viewed from a (outside, n 1) lit from b' (b below the
         * surface, n 1.5), f1 n_i^2 / n_o^2 = f2, the reverse query shading from inside. */
        struct material m = rough(MATERIAL_DIELECTRIC, r, r);
        vec3 bi = v3(b.x, b.y, -b.z);
        vec3 f1 = material_eval(&m, v3(0, 0, 1), a, bi, 1, &p1), f2 = material_eval(&m, v3(0, 0, -1), bi, a, 0, &p2);
        double x = f1.y / fabs(bi.z) * (1.5 * 1.5), y = f2.y / fabs(a.z);
        cr_assert(fabs(x - y) <= 1e-2 * fmax(x, y) + 1e-6, "transmission: %g against %g", x, y);
    }
}

/* Directional albedo (mean sample weight; flux for transmission): never above 1. The
 * single-scattering loss at normal and at 60 degrees, measured here, is at most the stated
 * bound: energy of multiple bounces between microfacets is not followed. */
Test(microfacet, energy_white_furnace)
{
    const float rs[] = {0.0032f, 0.1f, 0.3f, 0.5f, 0.7f, 1.0f};
    const float max_loss[] = {1e-3f, 2e-3f, 0.03f, 0.16f, 0.33f, 0.72f};
    const enum material_type types[] = {MATERIAL_MIRROR, MATERIAL_DIELECTRIC, MATERIAL_PLASTIC};
    for (int t = 0; t < 3; t++)
        for (int k = 0; k < 6; k++)
            for (int a = 0; a < 2; a++) {
                struct material m = rough(types[t], rs[k], rs[k]);
                m.albedo = v3(1, 1, 1);
                vec3 wo = dir_of(a ? 60.0f : 0.0f, 0.0f);
                enum { N = 100000 };
                uint64_t key = rng_key(9, 0, (uint64_t)k, (uint32_t)t);
                double sum = 0.0, sum2 = 0.0;
                for (int s = 0; s < N; s++) {
                    struct bsdf_sample bs;
                    material_sample(&m, v3(0, 0, 1), wo, 1, rng_uniform(key, 2 * (uint32_t)s), rng_uniform(key, 2 * (uint32_t)s + 1), &bs);
                    double w = bs.pdf > 0.0f ? bs.weight.y / bs.eta2 : 0.0;
                    sum += w;
                    sum2 += w * w;
                }
                double mean = sum / N, se = sqrt(fmax(0.0, sum2 / N - mean * mean) / N);
                cr_log_info("furnace type %d roughness %.3f theta %d: albedo %.4f (loss %.4f)", t, (double)rs[k], a ? 60 : 0, mean, 1.0 - mean);
                cr_assert(mean <= 1.0 + 4.0 * se + 1e-4, "type %d roughness %g: albedo %g above 1", t, (double)rs[k], mean);
                if (types[t] != MATERIAL_PLASTIC)
                    cr_assert(1.0 - mean <= max_loss[k] + 4.0 * se, "type %d roughness %g theta %d: loss %g", t, (double)rs[k], a ? 60 : 0, 1.0 - mean);
            }
}

/* Below the smooth threshold the lobes are exactly today's delta BSDFs: the same
 * directions and weights, bit for bit; just above it, sampling is within 1e-3 of them. */
Test(microfacet, smooth_limits)
{
    uint64_t key = rng_key(8, 0, 0, 0);
    for (int s = 0; s < 2000; s++) {
        vec3 wo = dir_of(88.0f * rng_uniform(key, 3 * (uint32_t)s), 360.0f * rng_uniform(key, 3 * (uint32_t)s + 1));
        float u1 = rng_uniform(key, 3 * (uint32_t)s + 2), u2 = 0.5f;
        int front = s & 1;
        for (int t = 0; t < 2; t++) {
            struct material smooth = rough(t ? MATERIAL_DIELECTRIC : MATERIAL_MIRROR, 0.0f, 0.0f);
            struct material below = rough(t ? MATERIAL_DIELECTRIC : MATERIAL_MIRROR, 0.003f, 0.002f);
            struct bsdf_sample a, b, c;
            material_sample(&smooth, v3(0, 0, 1), wo, front, u1, u2, &a);
            material_sample(&below, v3(0, 0, 1), wo, front, u1, u2, &b);
            cr_assert(material_is_delta(&below) && a.is_delta);
            cr_assert(memcmp(&a, &b, sizeof a) == 0, "type %d: not today's delta sample", t);
            /* Today's mirror: the mirror direction, weight the reflectance. */
            if (!t) {
                cr_assert(fabsf(a.wi.x + wo.x) < 1e-6f && fabsf(a.wi.z - wo.z) < 1e-6f && a.weight.y == 1.0f);
            }
            /* Just above the threshold: the rough lobe, within 1e-3 radians of the delta
             * direction when it picks the same side. */
            struct material above = rough(t ? MATERIAL_DIELECTRIC : MATERIAL_MIRROR, 0.0033f, 0.0033f);
            cr_assert(!material_is_delta(&above));
            material_sample(&above, v3(0, 0, 1), wo, front, u1, u2, &c);
            if (c.pdf > 0.0f && c.transmitted == a.transmitted && a.pdf > 0.0f)
                cr_assert(v3_dot(c.wi, a.wi) > 1.0f - 1e-6f, "type %d: rough sample %g off", t, (double)acosf(fminf(1.0f, v3_dot(c.wi, a.wi))));
        }
        /* A conductor whose Fresnel is 1 everywhere (Schlick, F0 = 1) is the mirror. */
        struct material cm = rough(MATERIAL_CONDUCTOR, 0.0f, 0.0f), mm = rough(MATERIAL_MIRROR, 0.0f, 0.0f);
        cm.schlick = 1;
        struct bsdf_sample a, b;
        material_sample(&cm, v3(0, 0, 1), wo, 1, u1, u2, &a);
        material_sample(&mm, v3(0, 0, 1), wo, 1, u1, u2, &b);
        cr_assert(memcmp(&a, &b, sizeof a) == 0);
    }
}

Test(microfacet, conductor_fresnel)
{
    /* Normal incidence: ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2); grazing: 1. */
    struct material m = rough(MATERIAL_CONDUCTOR, 0.0f, 0.0f);
    vec3 f = material_fresnel_conductor(&m, 1.0f);
    double n = m.eta.y, k = m.k.y, want = ((n - 1) * (n - 1) + k * k) / ((n + 1) * (n + 1) + k * k);
    cr_assert(fabs(f.y - want) < 1e-5, "%g against %g", (double)f.y, want);
    cr_assert(material_fresnel_conductor(&m, 0.0f).x > 0.9999f);
    /* k = 0: the dielectric formula. */
    m.eta = v3(1.5f, 1.5f, 1.5f);
    m.k = v3(0, 0, 0);
    for (float c = 0.05f; c <= 1.0f; c += 0.05f)
        cr_assert(fabsf(material_fresnel_conductor(&m, c).x - material_fresnel_dielectric(c, 1.5f)) < 1e-5f);
    m.schlick = 1;
    m.reflectance = v3(0.5f, 0.5f, 0.5f);
    cr_assert(fabsf(material_fresnel_conductor(&m, 1.0f).x - 0.5f) < 1e-6f);
    cr_assert(fabsf(material_fresnel_conductor(&m, 0.0f).x - 1.0f) < 1e-6f);
}

Test(microfacet, scene_keys)
{
    struct scene s;
    char err[512];
    const char *head = "{\"version\": 1, \"camera\": {\"position\": [0,0,0], \"look_at\": [0,0,-1], \"fov_y\": 40},"
                       " \"render\": {\"width\": 8, \"height\": 8, \"spp\": 1},"
                       " \"textures\": {\"r\": {\"type\": \"checker\", \"color0\": [0.1, 0.1, 0.1], \"color1\": [0.5, 0.5, 0.5]}},\n";
    char text[2048];
    snprintf(text, sizeof text, "%s\"materials\": {"
             "\"a\": {\"type\": \"conductor\", \"roughness\": 0.5, \"vroughness\": 0.2},"
             "\"b\": {\"type\": \"conductor\", \"reflectance\": [0.9, 0.8, 0.7]},"
             "\"c\": {\"type\": \"dielectric\", \"roughness\": 0.1, \"sample_visible\": false},"
             "\"d\": {\"type\": \"coateddiffuse\", \"roughness\": \"r\", \"albedo\": [0.5, 0.5, 0.5]},"
             "\"e\": {\"type\": \"mirror\", \"roughness\": 0.002}}}", head);
    cr_assert_eq(test_scene_load(text, NULL, &s, err), 0, "%s", err);
    cr_assert_eq(s.num_materials, 5);
    const struct material *m = s.materials;
    cr_assert(m[0].type == MATERIAL_CONDUCTOR && !m[0].schlick && fabsf(m[0].alpha_x - 0.25f) < 1e-7f &&
              fabsf(m[0].alpha_y - 0.04f) < 1e-7f && fabsf(m[0].eta.x - 0.2f) < 1e-6f);
    cr_assert(m[1].schlick && m[1].reflectance.y == 0.8f && m[1].alpha_x == 0.0f && material_is_delta(&m[1]));
    cr_assert(m[2].type == MATERIAL_DIELECTRIC && m[2].sample_all && !material_is_delta(&m[2]));
    cr_assert(m[3].type == MATERIAL_PLASTIC && m[3].roughness_tex == 1 && !material_is_delta(&m[3]));
    cr_assert(m[4].type == MATERIAL_MIRROR && material_is_delta(&m[4])); /* below the smooth threshold */
    scene_fini(&s);
    snprintf(text, sizeof text, "%s\"materials\": {\"a\": {\"type\": \"conductor\", \"reflectance\": [1, 1, 1], \"eta\": [1, 1, 1]}}}", head);
    test_scene_expect_error(text, NULL, "scenes/t.json:2:");
    test_scene_expect_error(text, NULL, "give \"reflectance\" or \"eta\" and \"k\", not both");
    snprintf(text, sizeof text, "%s\"materials\": {\"a\": {\"type\": \"plastic\", \"roughness\": \"r\", \"uroughness\": 0.2}}}", head);
    test_scene_expect_error(text, NULL, "a roughness texture excludes uroughness and vroughness");
    snprintf(text, sizeof text, "%s\"materials\": {\"a\": {\"type\": \"diffuse\", \"roughness\": 0.2}}}", head);
    test_scene_expect_error(text, NULL, "scenes/t.json:2:40: key \"roughness\" does not apply to a diffuse material");
    snprintf(text, sizeof text, "%s\"materials\": {\"a\": {\"type\": \"plastic\", \"roughness\": \"nope\"}}}", head);
    test_scene_expect_error(text, NULL, "unknown texture \"nope\"");
}

/* The shared-term forms glossy and dielectric evaluation use give the plain ones' bits. */
Test(microfacet, shared_terms_bit_identical)
{
    struct ggx g = {0.3f, 0.07f};
    for (uint32_t i = 0; i < 2000; i++) {
        vec3 wo = v3_normalize(v3(2.0f * rng_uniform(11, 3 * i) - 1.0f, 2.0f * rng_uniform(12, 3 * i) - 1.0f,
                                  rng_uniform(13, 3 * i)));
        vec3 wi = v3_normalize(v3(2.0f * rng_uniform(14, 3 * i) - 1.0f, 2.0f * rng_uniform(15, 3 * i) - 1.0f,
                                  rng_uniform(16, 3 * i)));
        vec3 wm = v3_normalize(v3_add(wo, wi));
        float d = ggx_d(&g, wm), lo = ggx_lambda(&g, wo), li = ggx_lambda(&g, wi);
        float a = ggx_d_visible(&g, wo, wm), b = ggx_d_visible_dl(wo, wm, d, lo);
        float ga = ggx_g(&g, wo, wi), gb = ggx_g_lambdas(lo, li);
        cr_assert(memcmp(&a, &b, sizeof a) == 0 && memcmp(&ga, &gb, sizeof ga) == 0, "sample %u", i);
    }
}

/* A rough dielectric of ior 1 (or within 1e-5 of it) bends no ray by more than 1e-5
 * radians and reflects almost nothing: it is the smooth glass (a pass-through), never a
 * NaN. Its transmission half vector wo + eta wi is zero, or rounding noise, at eta = 1
 * +- 1 ulp (the generalised half vector of Walter et al. has no direction at eta = 1). */
Test(microfacet, rough_glass_of_ior_one_is_a_pass_through)
{
    const float iors[] = {1.0f, 1.00000012f, 0.99999994f, 1.000009f};
    for (int k = 0; k < 4; k++) {
        uint64_t key = rng_key(10, 0, (uint64_t)k, 0);
        for (int s = 0; s < 20000; s++) {
            vec3 wo = dir_of(88.0f * rng_uniform(key, 3 * (uint32_t)s), 360.0f * rng_uniform(key, 3 * (uint32_t)s + 1));
            float u1 = rng_uniform(key, 3 * (uint32_t)s + 2), u2 = 0.5f;
            struct material m = rough(MATERIAL_DIELECTRIC, 0.25f + 0.75f * u1, 0.5f);
            m.ior = iors[k];
            cr_assert(material_is_delta(&m));
            struct bsdf_sample b;
            material_sample(&m, v3(0, 0, 1), wo, s & 1, u1, u2, &b);
            cr_assert(isfinite(b.weight.x) && isfinite(b.weight.y) && isfinite(b.weight.z) && isfinite(b.pdf));
            cr_assert(b.pdf > 0.0f && b.transmitted, "ior %.9g sample %d: no transmission", (double)m.ior, s);
            cr_assert(v3_dot(b.wi, v3_neg(wo)) > 1.0f - 1e-6f && fabsf(b.weight.y / b.eta2 - 1.0f) < 1e-4f,
                      "ior %.9g sample %d: wi or weight off", (double)m.ior, s);
            float pdf = 0.0f;
            vec3 f = material_eval(&m, v3(0, 0, 1), wo, v3_neg(wo), s & 1, &pdf);
            cr_assert(isfinite(f.y) && isfinite(pdf), "ior %.9g sample %d: eval %g pdf %g", (double)m.ior, s, (double)f.y, (double)pdf);
        }
    }
}
