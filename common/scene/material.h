/* BSDFs of the closed set of materials, dispatched by a switch on the type (hot path).
 * Directions are world-space unit vectors, wo toward the viewer, wi toward the light;
 * n is the shading normal on the side of wo. eval returns f * |cos(wi, n)|; delta BSDFs
 * (mirror, dielectric) evaluate to zero and are only sampled. Callers: integrator.c. */
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
};

static inline int material_is_delta(const struct material *m)
{
    return m->type == MATERIAL_MIRROR || m->type == MATERIAL_DIELECTRIC;
}

vec3 material_eval(const struct material *m, vec3 n, vec3 wo, vec3 wi, float *pdf);
/* front: wo is on the outside (the side the geometric normal points to); only dielectrics
 * care (it decides which index of refraction is on which side). */
void material_sample(const struct material *m, vec3 n, vec3 wo, int front, float u1, float u2,
                     struct bsdf_sample *out);

/* Fresnel reflectance of unpolarised light at a smooth dielectric boundary. cos_i in
 * [0, 1] on the incident side; eta = n_transmitted / n_incident. 1 under total internal
 * reflection. */
float material_fresnel_dielectric(float cos_i, float eta);
/* Refracts wo (unit, dot(wo, n) = cos_i >= 0) through n with eta as above; returns 0
 * under total internal reflection. */
int material_refract(vec3 wo, vec3 n, float cos_i, float eta, vec3 *wt);

#endif
