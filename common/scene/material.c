/* Lambertian diffuse: f = albedo / pi, sampled by cosine-weighted hemisphere (Malley), so
 * the sample weight is the albedo itself. Mirror: the reflected direction, weight the
 * reflectance. Smooth dielectric: reflect with probability F (exact Fresnel), otherwise
 * refract, so both weights need no division by F. Refracted radiance is scaled by
 * 1 / eta^2 (eta = n on wi's side / n on wo's side): radiance is not invariant across an
 * index change, L / n^2 is (Veach 1997, 5.2). A white furnace therefore stays white. */
#include "scene/material.h"
#include <math.h>

vec3 material_eval(const struct material *m, vec3 n, vec3 wo, vec3 wi, float *pdf)
{
    (void)wo;
    switch (m->type) {
    case MATERIAL_DIFFUSE: {
        float c = v3_dot(n, wi);
        if (c <= 0.0f) {
            *pdf = 0.0f;
            return v3(0, 0, 0);
        }
        *pdf = c * (float)M_1_PI;
        return v3_scale(m->albedo, c * (float)M_1_PI);
    }
    case MATERIAL_MIRROR:
    case MATERIAL_DIELECTRIC:
        break; /* a delta BSDF is zero for every direction a light sample can pick */
    }
    *pdf = 0.0f;
    return v3(0, 0, 0);
}

float material_fresnel_dielectric(float cos_i, float eta)
{
    cos_i = fminf(fmaxf(cos_i, 0.0f), 1.0f);
    float sin2_t = (1.0f - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0f)
        return 1.0f;
    float cos_t = sqrtf(1.0f - sin2_t);
    float r_par = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    float r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    float f = 0.5f * (r_par * r_par + r_perp * r_perp);
    return f < 1.0f ? f : 1.0f; /* at cos_i = 0 both ratios are -1 and 1: F = 1 */
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

static void no_sample(struct bsdf_sample *out)
{
    out->pdf = 0.0f;
    out->weight = v3(0, 0, 0);
    out->is_delta = 0;
    out->transmitted = 0;
}

void material_sample(const struct material *m, vec3 n, vec3 wo, int front, float u1, float u2,
                     struct bsdf_sample *out)
{
    switch (m->type) {
    case MATERIAL_DIFFUSE: {
        float r = sqrtf(u1), sp, cp;
        sincos_2pi(u2, &sp, &cp);
        float x = r * cp, y = r * sp, z = sqrtf(1.0f - u1); /* u1 < 1 */
        vec3 t, b;
        v3_basis(n, &t, &b);
        /* Unit to within rounding: (t, b, n) is orthonormal and x^2 + y^2 + z^2 = 1. */
        out->wi = v3_add(v3_add(v3_scale(t, x), v3_scale(b, y)), v3_scale(n, z));
        out->is_delta = 0;
        out->transmitted = 0;
        float c = v3_dot(out->wi, n);
        if (c <= 0.0f) {
            no_sample(out);
            return;
        }
        out->pdf = c * (float)M_1_PI;
        out->weight = m->albedo;
        return;
    }
    case MATERIAL_MIRROR: {
        float c = v3_dot(wo, n);
        if (!(c > 0.0f)) {
            no_sample(out);
            return;
        }
        out->wi = reflect(wo, n, c);
        out->weight = m->reflectance;
        out->pdf = 1.0f;
        out->is_delta = 1;
        out->transmitted = 0;
        return;
    }
    case MATERIAL_DIELECTRIC: {
        (void)u2;
        float c = v3_dot(wo, n);
        if (!(c > 0.0f)) {
            no_sample(out);
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
        out->weight = v3_scale(m->transmittance, 1.0f / (eta * eta));
        out->pdf = 1.0f - f;
        out->transmitted = 1;
        return;
    }
    }
    no_sample(out);
}
