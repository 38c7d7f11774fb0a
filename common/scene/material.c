/* Lambertian diffuse: f = albedo / pi, sampled by cosine-weighted hemisphere (Malley), so
 * the sample weight is the albedo itself. Mirror: the reflected direction, weight the
 * reflectance. Smooth dielectric: reflect with probability F (exact Fresnel), otherwise
 * refract, so both weights need no division by F. Refracted radiance is scaled by
 * 1 / eta^2 (eta = n on wi's side / n on wo's side): radiance is not invariant across an
 * index change, L / n^2 is (Veach 1997, 5.2). A white furnace therefore stays white.
 *
 * Rough lobes (alpha above MICROFACET_SMOOTH_ALPHA) are single-scattering GGX microfacet
 * BSDFs in the frame (v3_basis(n), n) (anisotropic ones: m->u_axis, the uv map's u axis,
 * made orthogonal to n, material_frame), sampled through the visible normals (microfacet.h):
 * mirror and conductor reflect, f = D G F / (4 cos_o cos_i); the rough dielectric reflects
 * or refracts (Walter et al. 2007), picking reflection with probability F(wo . wm) like the
 * smooth one. Plastic is a dielectric coat (index ior, smooth or GGX) over Lambert:
 * f = f_coat + albedo / pi (1 - F(cos_i)) (1 - F(cos_o)), with F the smooth Fresnel at the
 * macro normal: light enters and leaves the coat once, internal reflections between coat
 * and base are not followed (darker than a full layered model, never above 1). It samples
 * the coat with probability F(cos_o) / (F(cos_o) + (1 - F(cos_o)) mean(albedo)). A rough
 * lobe's choice between two lobes takes a third uniform hashed from the two it is given. */
#include "scene/material.h"
#include "scene/microfacet.h"
#include "base/rng.h"
#include <complex.h>
#include <math.h>
#include <string.h>

float material_fresnel_dielectric(float cos_i, float eta)
{
    cos_i = f_min(f_max(cos_i, 0.0f), 1.0f);
    float sin2_t = (1.0f - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0f)
        return 1.0f;
    float cos_t = sqrtf(1.0f - sin2_t);
    float r_par = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    float r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    float f = 0.5f * (r_par * r_par + r_perp * r_perp);
    return f < 1.0f ? f : 1.0f; /* at cos_i = 0 both ratios are -1 and 1: F = 1 */
}

/* Unpolarised reflectance of a conductor of complex index eta + i k (from outside, index 1). */
static float fresnel_complex(float cos_i, float eta, float k)
{
    cos_i = f_min(f_max(cos_i, 0.0f), 1.0f);
    double complex n = eta + k * I;
    double ci = cos_i, s2 = 1.0 - ci * ci;
    double complex s2t = s2 / (n * n), ct = csqrt(1.0 - s2t);
    double complex rpar = (n * ci - ct) / (n * ci + ct), rperp = (ci - n * ct) / (ci + n * ct);
    double f = 0.5 * (creal(rpar * conj(rpar)) + creal(rperp * conj(rperp)));
    return (float)fmin(fmax(f, 0.0), 1.0);
}

vec3 material_fresnel_conductor(const struct material *m, float cos_i)
{
    if (m->type == MATERIAL_MIRROR)
        return m->reflectance;
    if (m->schlick) {
        float c = 1.0f - f_min(f_max(cos_i, 0.0f), 1.0f), c5 = c * c * c * c * c;
        vec3 f0 = m->reflectance;
        return v3(f0.x + (1.0f - f0.x) * c5, f0.y + (1.0f - f0.y) * c5, f0.z + (1.0f - f0.z) * c5);
    }
    return v3(fresnel_complex(cos_i, m->eta.x, m->k.x), fresnel_complex(cos_i, m->eta.y, m->k.y),
              fresnel_complex(cos_i, m->eta.z, m->k.z));
}

int material_refract(vec3 wo, vec3 n, float cos_i, float eta, vec3 *wt)
{
    float sin2_t = (1.0f - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0f)
        return 0;
    float cos_t = sqrtf(1.0f - sin2_t);
    vec3 d = v3_add(v3_scale(v3_neg(wo), 1.0f / eta), v3_scale(n, cos_i / eta - cos_t));
    *wt = v3_normalize(d); /* unit up to rounding already; renormalised for long TIR chains */
    return 1;
}

static vec3 reflect(vec3 wo, vec3 n, float cos_i)
{
    return v3_sub(v3_scale(n, 2.0f * cos_i), wo);
}

int material_is_smooth(const struct material *m)
{
    /* Glass of ior within 1e-5 of 1 bends light by at most 1e-5 radians and reflects
     * almost nothing whatever its roughness: the smooth lobe, where the rough one's half
     * vector wo + eta wi is 0 or rounding noise (a NaN for ior 1 +- 1 ulp). */
    return f_max(m->alpha_x, m->alpha_y) < MICROFACET_SMOOTH_ALPHA ||
           (m->type == MATERIAL_DIELECTRIC && fabsf(m->ior - 1.0f) < 1e-5f);
}

/* The shading frame: x and y the anisotropy axes, z the normal. */
struct frame {
    vec3 t, b, n;
};

void material_frame(vec3 n, vec3 tu, vec3 *x, vec3 *y)
{
    float l2u = v3_dot(tu, tu);
    if (l2u > 0.0f && isfinite(l2u)) {
        vec3 t = v3_sub(tu, v3_scale(n, v3_dot(n, tu)));
        float l2 = v3_dot(t, t);
        if (l2 > 1e-8f * l2u && isfinite(l2)) {
            *x = v3_scale(t, 1.0f / sqrtf(l2));
            *y = v3_cross(n, *x);
            return;
        }
    }
    v3_basis(n, x, y);
}

const struct material *material_with_axis(const struct material *m, vec3 tu, struct material *buf)
{
    if (m != buf)
        *buf = *m;
    buf->u_axis = tu;
    return buf;
}

/* The rough lobes' frame of m at n: oriented by m->u_axis when m is anisotropic, else the
 * arbitrary frame (isotropic lobes do not depend on it; their samples keep their bits). */
static struct frame frame_of(const struct material *m, vec3 n)
{
    struct frame f;
    f.n = n;
    if (material_is_anisotropic(m))
        material_frame(n, m->u_axis, &f.t, &f.b);
    else
        v3_basis(n, &f.t, &f.b);
    return f;
}

static vec3 to_local(const struct frame *f, vec3 v)
{
    return v3(v3_dot(v, f->t), v3_dot(v, f->b), v3_dot(v, f->n));
}

static vec3 to_world(const struct frame *f, vec3 v)
{
    return v3_add(v3_add(v3_scale(f->t, v.x), v3_scale(f->b, v.y)), v3_scale(f->n, v.z));
}

static struct ggx ggx_of(const struct material *m)
{
    struct ggx g = {f_max(m->alpha_x, MICROFACET_SMOOTH_ALPHA), f_max(m->alpha_y, MICROFACET_SMOOTH_ALPHA)};
    return g;
}

/* Density of sampling normal wm from wo (local) by the material's strategy, from
 * d = ggx_d(wm) and lo = ggx_lambda(wo). */
static float normal_pdf_dl(const struct material *m, vec3 wo, vec3 wm, float d, float lo)
{
    return m->sample_all ? d * wm.z : ggx_d_visible_dl(wo, wm, d, lo);
}

static vec3 sample_normal(const struct material *m, const struct ggx *g, vec3 wo, float u1, float u2)
{
    return m->sample_all ? ggx_sample_all(g, u1, u2) : ggx_sample_visible(g, wo, u1, u2);
}

/* A third uniform from the two a sample gets (for the choice between two lobes). */
static float lobe_uniform(float u1, float u2)
{
    uint32_t a, b;
    memcpy(&a, &u1, 4);
    memcpy(&b, &u2, 4);
    return (float)(rng_mix64(((uint64_t)a << 32 | b) ^ 0x6c6f6265ull) >> 40) * 0x1p-24f;
}

/* Plastic's smooth Fresnel at the macro normal and its probability of sampling the coat. */
static float coat_pick(const struct material *m, float fo)
{
    float a = (m->albedo.x + m->albedo.y + m->albedo.z) / 3.0f;
    float d = fo + (1.0f - fo) * a;
    return d > 0.0f ? fo / d : 1.0f;
}

/* The reflection lobe of a rough surface (local, wo.z > 0, wi.z > 0) with Fresnel fr at
 * wo . wm: f cos_i, and the pdf of sampling wi through the normal. */
static vec3 glossy_eval(const struct material *m, const struct ggx *g, vec3 wo, vec3 wi, vec3 fr, vec3 wm, float *pdf)
{
    float c = v3_dot(wo, wm), d = ggx_d(g, wm), lo = ggx_lambda(g, wo); /* each once: pdf and f share them */
    *pdf = normal_pdf_dl(m, wo, wm, d, lo) / (4.0f * c);
    return v3_scale(fr, d * ggx_g_lambdas(lo, ggx_lambda(g, wi)) / (4.0f * wo.z));
}

/* Rough dielectric (Walter et al. 2007, as pbrt-v4's DielectricBxDF), local frame, wo.z > 0;
 * eta = index on the far side / index on wo's side. */
static vec3 dielectric_eval(const struct material *m, const struct ggx *g, vec3 wo, vec3 wi, float eta, float *pdf)
{
    *pdf = 0.0f;
    int refl = wi.z > 0.0f;
    if (wi.z == 0.0f)
        return v3(0, 0, 0);
    vec3 wm = refl ? v3_add(wo, wi) : v3_add(wo, v3_scale(wi, eta));
    float l2 = v3_dot(wm, wm);
    if (!(l2 > 0.0f))
        return v3(0, 0, 0);
    wm = v3_scale(wm, 1.0f / sqrtf(l2));
    if (wm.z < 0.0f)
        wm = v3_neg(wm);
    float co = v3_dot(wo, wm), ci = v3_dot(wi, wm);
    if (!(co > 0.0f) || ci * wi.z <= 0.0f) /* back-facing microfacets */
        return v3(0, 0, 0);
    float f = material_fresnel_dielectric(co, eta);
    if (refl) {
        vec3 r = glossy_eval(m, g, wo, wi, v3(f, f, f), wm, pdf);
        *pdf *= f;
        return r;
    }
    float denom = ci + co / eta;
    denom *= denom;
    float t = 1.0f - f, d = ggx_d(g, wm), lo = ggx_lambda(g, wo);
    *pdf = normal_pdf_dl(m, wo, wm, d, lo) * fabsf(ci) / denom * t;
    float v = t * d * ggx_g_lambdas(lo, ggx_lambda(g, wi)) * fabsf(ci * co / (wo.z * denom)) / (eta * eta);
    return v3_scale(m->transmittance, v);
}

vec3 material_eval_glossy_(const struct material *m, vec3 n, vec3 wo, vec3 wi, int front, float *pdf)
{
    switch (m->type) {
    case MATERIAL_DIFFUSE:
        break; /* material_eval's */
    case MATERIAL_MIRROR:
    case MATERIAL_CONDUCTOR:
    case MATERIAL_DIELECTRIC: {
        if (material_is_smooth(m))
            break; /* a delta BSDF is zero for every direction a light sample can pick */
        struct frame fr = frame_of(m, n);
        struct ggx g = ggx_of(m);
        vec3 lo = to_local(&fr, wo), li = to_local(&fr, wi);
        if (!(lo.z > 0.0f))
            break;
        if (m->type == MATERIAL_DIELECTRIC)
            return dielectric_eval(m, &g, lo, li, front ? m->ior : 1.0f / m->ior, pdf);
        if (!(li.z > 0.0f))
            break;
        vec3 wm = v3_add(lo, li);
        if (!(v3_dot(wm, wm) > 0.0f))
            break;
        wm = v3_normalize(wm);
        return glossy_eval(m, &g, lo, li, material_fresnel_conductor(m, v3_dot(lo, wm)), wm, pdf);
    }
    case MATERIAL_PLASTIC: {
        float co = v3_dot(n, wo), ci = v3_dot(n, wi);
        if (!(co > 0.0f) || !(ci > 0.0f))
            break;
        float fo = material_fresnel_dielectric(co, m->ior), fi = material_fresnel_dielectric(ci, m->ior);
        float pc = coat_pick(m, fo);
        vec3 f = v3_scale(m->albedo, (float)M_1_PI * (1.0f - fo) * (1.0f - fi) * ci);
        *pdf = (1.0f - pc) * ci * (float)M_1_PI;
        if (!material_is_smooth(m)) {
            struct frame fr = frame_of(m, n);
            struct ggx g = ggx_of(m);
            vec3 lo = to_local(&fr, wo), li = to_local(&fr, wi), wm = v3_normalize(v3_add(lo, li));
            float fm = material_fresnel_dielectric(v3_dot(lo, wm), m->ior), cp;
            f = v3_add(f, glossy_eval(m, &g, lo, li, v3(fm, fm, fm), wm, &cp));
            *pdf += pc * cp;
        }
        return f;
    }
    }
    return v3(0, 0, 0);
}

/* A rough lobe sample (local frame), completed with the evaluated weight. */
static void finish_rough(const struct material *m, const struct frame *fr, vec3 n, vec3 wo, vec3 li, int front,
                         struct bsdf_sample *out)
{
    out->wi = v3_normalize(to_world(fr, li));
    float pdf;
    vec3 f = material_eval(m, n, wo, out->wi, front, &pdf);
    if (!(pdf > 0.0f) || v3_is_black(f)) {
        bsdf_no_sample(out);
        return;
    }
    out->pdf = pdf;
    out->weight = v3_scale(f, 1.0f / pdf);
    out->is_delta = 0;
    out->transmitted = li.z < 0.0f;
    out->eta2 = 1.0f;
    if (out->transmitted) {
        float eta = front ? m->ior : 1.0f / m->ior;
        out->eta2 = 1.0f / (eta * eta);
    }
}

static void sample_rough(const struct material *m, vec3 n, vec3 wo, int front, float u1, float u2,
                         struct bsdf_sample *out)
{
    struct frame fr = frame_of(m, n);
    struct ggx g = ggx_of(m);
    vec3 lo = to_local(&fr, wo);
    if (!(lo.z > 0.0f)) {
        bsdf_no_sample(out);
        return;
    }
    vec3 wm = sample_normal(m, &g, lo, u1, u2);
    float co = v3_dot(lo, wm);
    if (!(co > 0.0f)) {
        bsdf_no_sample(out);
        return;
    }
    vec3 li = reflect(lo, wm, co);
    if (m->type == MATERIAL_DIELECTRIC) {
        float eta = front ? m->ior : 1.0f / m->ior;
        float f = material_fresnel_dielectric(co, eta);
        vec3 wt;
        int refr = lobe_uniform(u1, u2) >= f && material_refract(lo, wm, co, eta, &wt);
        if (refr)
            li = wt;
        if (refr ? !(li.z < 0.0f) : !(li.z > 0.0f)) {
            bsdf_no_sample(out); /* the lobe's direction lies on the other side of the surface */
            return;
        }
    }
    finish_rough(m, &fr, n, wo, li, front, out);
}

void material_sample_glossy_(const struct material *m, vec3 n, vec3 wo, int front, float u1, float u2,
                             struct bsdf_sample *out)
{
    switch (m->type) {
    case MATERIAL_DIFFUSE:
        break; /* material_sample's */
    case MATERIAL_MIRROR:
    case MATERIAL_CONDUCTOR: {
        if (!material_is_smooth(m)) {
            sample_rough(m, n, wo, front, u1, u2, out);
            return;
        }
        float c = v3_dot(wo, n);
        if (!(c > 0.0f)) {
            bsdf_no_sample(out);
            return;
        }
        out->wi = reflect(wo, n, c);
        out->weight = material_fresnel_conductor(m, c);
        out->pdf = 1.0f;
        out->is_delta = 1;
        out->transmitted = 0;
        return;
    }
    case MATERIAL_DIELECTRIC: {
        if (!material_is_smooth(m)) {
            sample_rough(m, n, wo, front, u1, u2, out);
            return;
        }
        float c = v3_dot(wo, n);
        if (!(c > 0.0f)) {
            bsdf_no_sample(out);
            return;
        }
        float eta = front ? m->ior : 1.0f / m->ior;
        float f = material_fresnel_dielectric(c, eta);
        out->is_delta = 1;
        vec3 wt;
        if (u1 < f || !material_refract(wo, n, c, eta, &wt)) {
            out->wi = reflect(wo, n, c);
            out->weight = v3(1, 1, 1);
            out->pdf = f;
            out->transmitted = 0;
            return;
        }
        out->wi = wt;
        out->eta2 = 1.0f / (eta * eta);
        out->weight = v3_scale(m->transmittance, out->eta2);
        out->pdf = 1.0f - f;
        out->transmitted = 1;
        return;
    }
    case MATERIAL_PLASTIC: {
        float co = v3_dot(wo, n);
        if (!(co > 0.0f)) {
            bsdf_no_sample(out);
            return;
        }
        float fo = material_fresnel_dielectric(co, m->ior), pc = coat_pick(m, fo);
        float uc = lobe_uniform(u1, u2);
        if (uc < pc && material_is_smooth(m)) {
            out->wi = reflect(wo, n, co);
            out->weight = v3_scale(v3(1, 1, 1), fo / pc);
            out->pdf = pc;
            out->is_delta = 1;
            out->transmitted = 0;
            return;
        }
        struct frame fr = frame_of(m, n);
        vec3 lo = to_local(&fr, wo), li;
        if (uc < pc) {
            struct ggx g = ggx_of(m);
            vec3 wm = sample_normal(m, &g, lo, u1, u2);
            float c = v3_dot(lo, wm);
            if (!(c > 0.0f)) {
                bsdf_no_sample(out);
                return;
            }
            li = reflect(lo, wm, c);
        } else {
            float r = sqrtf(u1), sp, cp;
            sincos_2pi(u2, &sp, &cp);
            li = v3(r * cp, r * sp, sqrtf(f_max(0.0f, 1.0f - u1)));
        }
        finish_rough(m, &fr, n, wo, li, front, out);
        return;
    }
    }
    bsdf_no_sample(out);
}
