/* Photon tracing for the photon map (Jensen and Christensen 1998), on the master: photons
 * leave the lights in proportion to their power, are traced through media and off
 * surfaces, and are stored at each scattering in a medium except on their first flight
 * (marching computes single scattering) and, for the final gather with surface_photons
 * (media_wants_surface_photons), on diffuse surfaces after any interaction. Fixed blocks
 * of photon indices per thread, joined in index order: the bytes are the same for any
 * thread count. */
#ifndef BRUME_PHOTON_TRACE_H
#define BRUME_PHOTON_TRACE_H
#include <stddef.h>
#include <stdint.h>
#include "base/vec.h"

struct render_job;
struct scene;
struct medium;

struct photon_pass_stats {
    double seconds;
    uint64_t emitted, stored;  /* stored: volume and surface photons */
    uint64_t stored_surface;
    uint64_t stored_beams;    /* of stored: photon beams (the beams method) */
    size_t bytes;
};

/* Traces job's photons (scene media settings: count, radius, depth) on `threads` threads
 * and returns the serialised map in *blob (caller frees). The job must be a media job
 * (render_job_init of a scene with media). 0 or -1 with err. */
int photon_trace_map(const struct render_job *job, uint64_t seed, uint32_t threads, uint8_t **blob, size_t *size,
                     struct photon_pass_stats *stats, char *err, size_t errlen);
/* One photon as it leaves a light (photon_trace_emit). */
struct photon_emitted {
    vec3 o, d, power;
};
/* Emits photons first .. first + n - 1 of the pass keyed by seed without tracing them,
 * each with the power of one of n photons (zero where none is emitted): the sum of the
 * powers over any set of directions estimates the lights' power into it. For tests of the
 * emission densities (the mixtures' pdfs). */
void photon_trace_emit(const struct render_job *job, uint64_t seed, uint64_t first, uint32_t n, struct photon_emitted *out);
/* The box outside which a photon meets nothing (the geometry over the shutter and every
 * grid's box, padded): point lights outside it send no photon away from it. 0 when a
 * homogeneous fog fills all space. */
int photon_interaction_bounds(const struct render_job *job, vec3 *lo, vec3 *hi);
/* How far a camera ray that leaves the scene's bounds in homogeneous medium md is
 * marched (march, beam) past them, and so how far past them photons are kept: the
 * distance where the transmittance of every channel that scatters or absorbs falls to
 * PHOTON_REACH_EPS, at most PHOTON_REACH_MAX scene diagonals (scene_size; a fog that
 * thin is all but transparent). 0 for grids (their boxes are inside the bounds) and media
 * that do nothing. See docs/media.md, "Open fog". */
#define PHOTON_REACH_EPS 1e-4f
#define PHOTON_REACH_MAX 64.0f
float photon_fog_reach(const struct medium *md, float scene_size);
/* Asks every photon pass of this process to stop: its threads stop at the next photon
 * and photon_trace_map returns -1 ("interrupted"). Async-signal-safe (a lock-free atomic
 * store): the master's SIGINT / SIGTERM handler calls it. There is no way back. */
void photon_trace_request_stop(void);
/* Upper bound on the share of in-scattered light that comes from more than one bounce:
 * max(largest surface reflectance, largest medium albedo x (1 - exp(-sigma_t,max D))),
 * D the scene's diagonal. The photon pass is skipped when it is below skip_bound. */
double photon_trace_indirect_bound(const struct scene *s, float scene_size);

#endif
