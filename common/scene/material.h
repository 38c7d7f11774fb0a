/* BSDFs of the closed set of materials, dispatched by a switch on the type (hot path).
 * Directions are world-space unit vectors, wo toward the viewer, wi toward the light;
 * n is the shading normal on the side of wo. eval returns f * |cos(wi, n)|; delta BSDFs
 * (smooth mirror, conductor and dielectric) evaluate to zero and are only sampled; rough
 * ones are GGX microfacet lobes (material.c, microfacet.h). Callers: integrator.c,
 * media_integrator.c, photon_trace.c, surface.c. */
#ifndef BRUME_MATERIAL_H
#define BRUME_MATERIAL_H
#include "scene/scene.h"
#include "base/vec.h"

struct bsdf_sample {
    vec3 wi;
    vec3 weight;    /* f * cos / pdf */
    float pdf;      /* solid angle; for a delta lobe the probability of picking it; 0 = no sample */
    int is_delta;   /* a single direction: no MIS, no light sampling */
    int transmitted; /* wi is on the other side of the surface than wo */
    float eta2;     /* the radiance scale 1 / eta^2 in weight (1 unless transmitted): flux
                     * (photons) crosses an index change without it */
};

/* Roughness below MICROFACET_SMOOTH_ALPHA, or a dielectric of ior within 1e-5 of 1: the
 * smooth (delta) lobe. */
int material_is_smooth(const struct material *m);

static inline int material_is_delta(const struct material *m)
{
    return (m->type == MATERIAL_MIRROR || m->type == MATERIAL_DIELECTRIC || m->type == MATERIAL_CONDUCTOR) &&
           material_is_smooth(m);
}

/* Anisotropic roughness (alpha_x != alpha_y): the lobe's widths lie along the u and v
 * axes of the surface's uv map (m->u_axis, set per hit by material_with_axis). */
static inline int material_is_anisotropic(const struct material *m)
{
    return m->alpha_x != m->alpha_y;
}

/* The rough lobes' frame (x, y the anisotropy axes, z = n): x is tu made orthogonal to n
 * (Gram-Schmidt) and normalised, y = n x x; where tu is zero or (nearly) parallel to n, the
 * arbitrary frame v3_basis(n). Pure and deterministic. Anisotropic lobes take it with
 * tu = m->u_axis; isotropic ones always the arbitrary frame (they do not depend on it). */
void material_frame(vec3 n, vec3 tu, vec3 *x, vec3 *y);

/* m with its u axis set to tu (the surface's dP/du at the hit, surface_dpdu), in *buf (m
 * itself may be buf, e.g. a textured copy). Callers do this only where
 * material_is_anisotropic(m): other scenes never copy. */
const struct material *material_with_axis(const struct material *m, vec3 tu, struct material *buf);

/* front: wo is on the outside (the side the geometric normal points to); dielectrics and
 * plastic care (it decides which index of refraction is on which side). eval returns the
 * reflection lobe when wi is on n's side, else the transmission lobe (rough dielectric). */
/* The glossy types (all but MATERIAL_DIFFUSE), out of line in material.c: their frames and
 * Fresnel terms need a large stack frame that the Lambertian case, the most common and
 * inline here, should not set up. */
vec3 material_eval_glossy_(const struct material *m, vec3 n, vec3 wo, vec3 wi, int front, float *pdf);
void material_sample_glossy_(const struct material *m, vec3 n, vec3 wo, int front, float u1, float u2,
                             struct bsdf_sample *out);

static inline vec3 material_eval(const struct material *m, vec3 n, vec3 wo, vec3 wi, int front, float *pdf)
{
    *pdf = 0.0f;
    if (m->type == MATERIAL_DIFFUSE) {
        float c = v3_dot(n, wi);
        if (c <= 0.0f)
            return v3(0, 0, 0);
        *pdf = c * (float)M_1_PI;
        return v3_scale(m->albedo, c * (float)M_1_PI);
    }
    return material_eval_glossy_(m, n, wo, wi, front, pdf);
}

/* No sample: pdf 0, weight 0. */
static inline void bsdf_no_sample(struct bsdf_sample *out)
{
    out->pdf = 0.0f;
    out->weight = v3(0, 0, 0);
    out->is_delta = 0;
    out->transmitted = 0;
    out->eta2 = 1.0f;
}

static inline void material_sample(const struct material *m, vec3 n, vec3 wo, int front, float u1, float u2,
                                   struct bsdf_sample *out)
{
    out->eta2 = 1.0f;
    if (m->type == MATERIAL_DIFFUSE) {
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
            bsdf_no_sample(out);
            return;
        }
        out->pdf = c * (float)M_1_PI;
        out->weight = m->albedo;
        return;
    }
    material_sample_glossy_(m, n, wo, front, u1, u2, out);
}

/* Fresnel reflectance of unpolarised light at a smooth dielectric boundary. cos_i in
 * [0, 1] on the incident side; eta = n_transmitted / n_incident. 1 under total internal
 * reflection. */
float material_fresnel_dielectric(float cos_i, float eta);
/* Refracts wo (unit, dot(wo, n) = cos_i >= 0) through n with eta as above; returns 0
 * under total internal reflection. */
int material_refract(vec3 wo, vec3 n, float cos_i, float eta, vec3 *wt);
/* Reflectance of a mirror (its constant reflectance) or a conductor (complex eta + i k,
 * or Schlick with F0 = reflectance) at cos_i. */
vec3 material_fresnel_conductor(const struct material *m, float cos_i);

#endif
