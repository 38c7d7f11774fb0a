/* Lambertian diffuse: f = albedo / pi, sampled by cosine-weighted hemisphere (Malley), so
 * the sample weight is the albedo itself. */
#include "material.h"
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
    }
    *pdf = 0.0f;
    return v3(0, 0, 0);
}

void material_sample(const struct material *m, vec3 n, vec3 wo, float u1, float u2, struct bsdf_sample *out)
{
    (void)wo;
    switch (m->type) {
    case MATERIAL_DIFFUSE: {
        float r = sqrtf(u1), sp, cp;
        sincos_2pi(u2, &sp, &cp);
        float x = r * cp, y = r * sp, z = sqrtf(1.0f - u1); /* u1 < 1 */
        vec3 t, b;
        v3_basis(n, &t, &b);
        /* Unit to within rounding: (t, b, n) is orthonormal and x^2 + y^2 + z^2 = 1. */
        out->wi = v3_add(v3_add(v3_scale(t, x), v3_scale(b, y)), v3_scale(n, z));
        float c = v3_dot(out->wi, n);
        if (c <= 0.0f) {
            out->pdf = 0.0f;
            out->weight = v3(0, 0, 0);
            return;
        }
        out->pdf = c * (float)M_1_PI;
        out->weight = m->albedo;
        return;
    }
    }
    out->pdf = 0.0f;
    out->weight = v3(0, 0, 0);
}
