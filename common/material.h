/* BSDFs of the closed set of materials, dispatched by a switch on the type (hot path).
 * Directions are world-space unit vectors, wo toward the viewer, wi toward the light;
 * n is the shading normal on the side of wo. eval returns f * |cos(wi, n)|. */
#ifndef BRUME_MATERIAL_H
#define BRUME_MATERIAL_H
#include "scene.h"
#include "vec.h"

struct bsdf_sample {
    vec3 wi;
    vec3 weight;    /* f * cos / pdf */
    float pdf;      /* solid angle; 0 = no sample */
};

vec3 material_eval(const struct material *m, vec3 n, vec3 wo, vec3 wi, float *pdf);
void material_sample(const struct material *m, vec3 n, vec3 wo, float u1, float u2, struct bsdf_sample *out);

#endif
