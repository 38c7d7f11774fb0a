/* Photon tracing for the photon map (Jensen and Christensen 1998), on the master.
 * - Photons leave the lights in proportion to their power and are traced through media
 *   and off surfaces; threads take fixed blocks of photon indices, joined in index order
 *   and sorted stably by grid cell: the bytes are the same for any thread count.
 * - A photon is stored at each scattering event in a medium except on its first flight
 *   from the light (ray marching computes single scattering); with surface_photons, also
 *   on arriving at a diffuse surface after any interaction (its indirect light). */
#ifndef BRUME_PHOTON_TRACE_H
#define BRUME_PHOTON_TRACE_H
#include <stddef.h>
#include <stdint.h>

struct render_job;
struct scene;

struct photon_pass_stats {
    double seconds;
    uint64_t emitted, stored;  /* stored: volume and surface photons */
    uint64_t stored_surface;
    size_t bytes;
};

/* Traces job's photons (scene media settings: count, radius, depth) on `threads` threads
 * and returns the serialised map in *blob (caller frees). The job must be a media job
 * (render_job_init of a scene with media). 0 or -1 with err. */
int photon_trace_map(const struct render_job *job, uint64_t seed, uint32_t threads, uint8_t **blob, size_t *size,
                     struct photon_pass_stats *stats, char *err, size_t errlen);
/* Upper bound on the share of in-scattered light that comes from more than one bounce:
 * max(largest surface reflectance, largest medium albedo x (1 - exp(-sigma_t,max D))),
 * D the scene's diagonal. The photon pass is skipped when it is below skip_bound. */
double photon_trace_indirect_bound(const struct scene *s, float scene_size);

#endif
