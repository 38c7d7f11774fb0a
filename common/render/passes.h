/* Progressive photon-map passes (docs/media.md#progressive-passes): how many passes a frame
 * renders, how many camera samples and photons each takes, and the dimension of each photon
 * estimate's kernel, which its radius rule (photon_pass_radius) shrinks in. Pure functions
 * of the settings; the master's photon pass calls them, the unit tests check them. */
#ifndef BRUME_PASSES_H
#define BRUME_PASSES_H
#include <stdint.h>
#include "scene/medium.h"

/* Default rule: one camera sample per pixel per pass (the radius shrinks and a fresh map
 * comes with every sample), at most PASS_PHOTONS_PER_PIXEL photons emitted per pixel of the
 * image in each pass and at most PASS_STORED_PER_PIXEL stored in its volume map (as the
 * master's pilot map measures them), and at most PASS_MAX_PHOTONS photons in all the
 * passes' maps together (the master holds every map of the frame, for late workers and
 * re-issues): past that, passes take more samples each. */
#define PASS_DEFAULT_SPP 1u
#define PASS_PHOTONS_PER_PIXEL 8u
#define PASS_STORED_PER_PIXEL 3u
#define PASS_MAX_PHOTONS (1ull << 24)

/* The dimension of the kernel of the volume map's estimate for `method`: 2 for beam (photon
 * points against the query ray: a disc across the ray, 1 / (pi r^2)), 3 for march (a sphere
 * around the step); the surface map's estimate is a disc on the surface, dimension 2. */
int passes_volume_kernel_dim(enum media_method method);
#define PASSES_SURFACE_KERNEL_DIM 2

struct pass_plan {
    uint32_t passes;        /* P, 1..SCENE_MAX_PASSES */
    uint32_t spp_per_pass;  /* k = ceil(spp / P) */
    uint32_t spp;           /* P k, the frame's spp (>= the asked spp); 0 when over SCENE_MAX_SPP */
    uint64_t photons;       /* photons emitted per pass */
};

/* The passes of a frame of `spp` samples per pixel and `pixels` pixels. With `asked` passes
 * (--passes, render.passes; 0: none asked) P = asked and every pass traces `photons`
 * (volume.photons, --photons). Otherwise the default rule above: photons per pass are
 * min(photons, PASS_PHOTONS_PER_PIXEL x pixels, PASS_STORED_PER_PIXEL x pixels /
 * stored_per_photon) unless `photons_given` (--photons); stored_per_photon is the volume
 * map's photons stored per photon emitted (the pilot's; <= 0: unknown, no such cap). And
 * P = ceil(spp / k) with k the fewest samples per pass (from PASS_DEFAULT_SPP up) that keep
 * P x photons within PASS_MAX_PHOTONS. 0, or -1 when P k would exceed SCENE_MAX_SPP (out is
 * filled; out->spp is 0). */
int passes_plan(uint32_t spp, uint32_t asked, uint64_t photons, int photons_given, double stored_per_photon,
                uint64_t pixels, struct pass_plan *out);

#endif
