/* What the photon map and the photon beams share (photon_map.h, photon_beams.h): the
 * bound on a photon's depth, the RGBE power code and transmittance from a marched
 * optical-depth table. */
#ifndef BRUME_PHOTON_CODEC_H
#define BRUME_PHOTON_CODEC_H
#include <stdint.h>
#include "base/vec.h"
#include "scene/medium.h"

#define PHOTON_DEPTH_MAX 1024u  /* volume.max_photon_depth's bound */

/* A stored photon's 16-bit depth word: the events of its light path before it was stored
 * (bits 0-10, 1..PHOTON_DEPTH_MAX) and, for a photon stored in a density grid, a density
 * code k (bits 11-15): the density there is at least 2^-(k+1) of the grid's maximum
 * (k = 31 also for anything thinner); 0 in homogeneous media. */
#define PHOTON_EVENTS(word) ((uint32_t)(word) & 0x7ffu)
uint16_t photon_depth_word(uint32_t events, float density_rel);
/* The word's lower bound on the density, as a fraction of the grid's maximum. */
float photon_density_floor(uint16_t word);
/* In a grid a photon carries its power over the density where it was stored, and an
 * estimate at a point of density rho weighs it by min(rho, PHOTON_DENSITY_RATIO x the
 * photon's density floor x the grid's maximum) (photon_density_weight). */
#define PHOTON_DENSITY_RATIO 8.0f
static inline float photon_density_weight(float rho, float floor_rel, float grid_max)
{
    float cap = PHOTON_DENSITY_RATIO * floor_rel * grid_max;
    return rho < cap ? rho : cap;
}

/* Power as RGB with a shared exponent (4 bytes); decoded at the bin's centre. */
void photon_rgbe_encode(vec3 c, uint8_t out[4]);
vec3 photon_rgbe_decode(const uint8_t in[4]);

/* Optical depth along a ray segment, marched through a grid. */
struct photon_tau {
    const float *tau;   /* optical depth per unit sigma_t at t0 + k dt, k < n */
    uint32_t n;
    float t0, dt;
};
/* Optical depth (per unit sigma_t) at t, interpolated in the table: 0 before it, its last
 * value after it; and into *rho the density the march took at t: the table's slope there
 * (constant over each step; 0 outside the table). One lookup for both: the beam query takes
 * them for every photon it accepts in a grid. */
static inline float photon_tau_depth_density(const struct photon_tau *tt, float t, float *rho)
{
    float x = (t - tt->t0) / tt->dt;
    *rho = 0.0f;
    if (!(x > 0.0f)) {
        if (x == 0.0f && tt->n > 1)
            *rho = (tt->tau[1] - tt->tau[0]) / tt->dt;
        return 0.0f;
    }
    if (!(x < (float)(tt->n - 1)))
        return tt->tau[tt->n - 1];
    uint32_t i = (uint32_t)x;
    *rho = (tt->tau[i + 1] - tt->tau[i]) / tt->dt;
    float f = x - (float)i;
    return tt->tau[i] * (1.0f - f) + tt->tau[i + 1] * f;
}
/* The optical depth alone. */
static inline float photon_tau_depth(const struct photon_tau *tt, float t)
{
    float rho;
    return photon_tau_depth_density(tt, t, &rho);
}
/* Transmittance at t from a marched table. */
static inline vec3 photon_tau_transmittance(const struct photon_tau *tt, const struct medium *md, float t)
{
    return medium_tr_tau(md, photon_tau_depth(tt, t));
}

#endif
