/* GGX in the local frame (see microfacet.h). Conventions as pbrt-v4's
 * TrowbridgeReitzDistribution: D integrates with wm.z to 1 over the hemisphere. */
#include "scene/microfacet.h"
#include <math.h>

float ggx_d(const struct ggx *g, vec3 wm)
{
    if (!(wm.z > 0.0f))
        return 0.0f;
    /* 1 / (pi ax ay (x^2/ax^2 + y^2/ay^2 + z^2)^2) for a unit wm: no tan or cos^4 to lose. */
    float x = wm.x / g->ax, y = wm.y / g->ay, s = x * x + y * y + wm.z * wm.z;
    return 1.0f / ((float)M_PI * g->ax * g->ay * s * s);
}

float ggx_lambda(const struct ggx *g, vec3 w)
{
    float z2 = w.z * w.z;
    if (!(z2 > 0.0f))
        return INFINITY;
    float a2t2 = (g->ax * g->ax * w.x * w.x + g->ay * g->ay * w.y * w.y) / z2;
    return 0.5f * (sqrtf(1.0f + a2t2) - 1.0f);
}

float ggx_g1(const struct ggx *g, vec3 w)
{
    return 1.0f / (1.0f + ggx_lambda(g, w));
}

float ggx_g(const struct ggx *g, vec3 wo, vec3 wi)
{
    return ggx_g_lambdas(ggx_lambda(g, wo), ggx_lambda(g, wi));
}

float ggx_d_visible(const struct ggx *g, vec3 wo, vec3 wm)
{
    return ggx_d_visible_dl(wo, wm, ggx_d(g, wm), ggx_lambda(g, wo));
}

float ggx_d_visible_dl(vec3 wo, vec3 wm, float d, float lambda_o)
{
    float c = v3_dot(wo, wm);
    if (!(wo.z > 0.0f) || !(c > 0.0f))
        return 0.0f;
    return 1.0f / (1.0f + lambda_o) * c * d / wo.z;
}

vec3 ggx_sample_visible(const struct ggx *g, vec3 wo, float u1, float u2)
{
    /* Stretch to the hemisphere configuration (alpha 1), sample the projected disc of the
     * visible hemisphere, warp it by the foreshortening, unstretch. */
    vec3 vh = v3_normalize(v3(g->ax * wo.x, g->ay * wo.y, wo.z));
    float len2 = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = len2 > 0.0f ? v3_scale(v3(-vh.y, vh.x, 0.0f), 1.0f / sqrtf(len2)) : v3(1, 0, 0);
    vec3 t2 = v3_cross(vh, t1);
    float r = sqrtf(u1), sp, cp;
    sincos_2pi(u2, &sp, &cp);
    float p1 = r * cp, p2 = r * sp;
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrtf(fmaxf(0.0f, 1.0f - p1 * p1)) + s * p2;
    float p3 = sqrtf(fmaxf(0.0f, 1.0f - p1 * p1 - p2 * p2));
    vec3 nh = v3_add(v3_add(v3_scale(t1, p1), v3_scale(t2, p2)), v3_scale(vh, p3));
    return v3_normalize(v3(g->ax * nh.x, g->ay * nh.y, fmaxf(1e-7f, nh.z)));
}

vec3 ggx_sample_all(const struct ggx *g, float u1, float u2)
{
    /* phi from the anisotropic azimuth CDF, then tan^2(theta) = u1 / ((1 - u1) A(phi)). */
    float sp, cp;
    sincos_2pi(u2, &sp, &cp);
    vec3 dir = v3_normalize(v3(g->ax * cp, g->ay * sp, 0.0f));
    float a = dir.x * dir.x / (g->ax * g->ax) + dir.y * dir.y / (g->ay * g->ay);
    float t2 = u1 / (fmaxf(1e-12f, 1.0f - u1) * a);
    float cz = 1.0f / sqrtf(1.0f + t2), sz = sqrtf(fmaxf(0.0f, 1.0f - cz * cz));
    return v3(dir.x * sz, dir.y * sz, cz);
}
