/* The anisotropic GGX (Trowbridge-Reitz) microfacet distribution in a local frame whose z
 * axis is the shading normal: the normal distribution D, Smith's height-correlated masking
 * (Lambda, G1, G), and two ways to sample a microfacet normal: the visible normals of a
 * direction (Heitz 2018, "Sampling the GGX Distribution of Visible Normals", pdf
 * D_wo(wm) = G1(wo) max(0, wo.wm) D(wm) / wo.z) and the classic D(wm) cos(theta_m)
 * (Walter et al. 2007), kept for the benchmark (scripts/bench_materials.sh).
 * alpha_x, alpha_y > 0 are the widths along the frame's x and y axes. Pure functions;
 * callers: material.c, tests. */
#ifndef BRUME_MICROFACET_H
#define BRUME_MICROFACET_H
#include "base/vec.h"

/* Below this alpha (roughness below about 0.0032 with alpha = roughness^2), a lobe is
 * treated as smooth: a delta BSDF, exactly the mirror and glass of material.c. Narrower
 * lobes are not resolved in float (half vectors of unit vectors carry errors of ~1e-7):
 * the chi-square tests of sampling fail at roughness 0.001. */
#define MICROFACET_SMOOTH_ALPHA 1e-5f

/* Perceptual roughness in [0, 1] to alpha, as Cycles and Disney map it: alpha = r^2. */
static inline float microfacet_alpha(float roughness)
{
    return roughness * roughness;
}

struct ggx {
    float ax, ay;
};

float ggx_d(const struct ggx *g, vec3 wm);
float ggx_lambda(const struct ggx *g, vec3 w);
float ggx_g1(const struct ggx *g, vec3 w);
/* Height-correlated masking-shadowing of the pair (Heitz 2014, eq. 99). */
float ggx_g(const struct ggx *g, vec3 wo, vec3 wi);
/* ggx_g from the two Lambdas, for callers that have them (evaluation shares them with the pdf). */
static inline float ggx_g_lambdas(float lambda_o, float lambda_i) { return 1.0f / (1.0f + lambda_o + lambda_i); }
/* Density of the visible normal wm seen from wo (wo.z > 0): G1(wo) max(0, wo.wm) D(wm) / wo.z. */
float ggx_d_visible(const struct ggx *g, vec3 wo, vec3 wm);
/* The same from d = D(wm) and lambda_o = Lambda(wo), bit for bit. */
float ggx_d_visible_dl(vec3 wo, vec3 wm, float d, float lambda_o);
/* A visible normal of wo (wo.z > 0) from two uniforms; pdf ggx_d_visible. */
vec3 ggx_sample_visible(const struct ggx *g, vec3 wo, float u1, float u2);
/* A normal with density D(wm) wm.z (all normals, visible or not). */
vec3 ggx_sample_all(const struct ggx *g, float u1, float u2);

#endif
