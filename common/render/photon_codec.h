/* What the photon map and the photon beams share (photon_map.h, photon_beams.h): the
 * bound on a photon's depth, the RGBE power code and transmittance from a marched
 * optical-depth table. */
#ifndef BRUME_PHOTON_CODEC_H
#define BRUME_PHOTON_CODEC_H
#include <stdint.h>
#include "base/vec.h"
#include "scene/medium.h"

#define PHOTON_DEPTH_MAX 1024u  /* volume.max_photon_depth's bound */

/* Power as RGB with a shared exponent (4 bytes); decoded at the bin's centre. */
void photon_rgbe_encode(vec3 c, uint8_t out[4]);
vec3 photon_rgbe_decode(const uint8_t in[4]);

/* Optical depth along a ray segment, marched through a grid. */
struct photon_tau {
    const float *tau;   /* optical depth per unit sigma_t at t0 + k dt, k < n */
    uint32_t n;
    float t0, dt;
};
/* Transmittance at t from a marched table. */
vec3 photon_tau_transmittance(const struct photon_tau *tt, const struct medium *md, float t);

#endif
