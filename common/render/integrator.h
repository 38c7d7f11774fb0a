/* Path tracing of tiles over a render job (render_job.h, built once per frame and shared
 * read-only by the render threads). integrator_render_tile() writes a tile's interleaved channels
 * (tile.h order) and statistics; its pixels depend only on (scene, seed, frame, pixel),
 * never on the thread, tile size or order. Called by the worker (and by tests). */
#ifndef BRUME_INTEGRATOR_H
#define BRUME_INTEGRATOR_H
#include <stddef.h>
#include <stdint.h>
#include "render/render_job.h"
#include "scene/sampler.h"
#include "render/tile.h"

/* Renders the pixel rectangle [x0, x0+w) x [y0, y0+h) into pixels (w*h*num_channels
 * floats of the settings' tile_layout: the beauty, then the AOVs render.aovs asks for). Fills stats (render_ns excluded: the caller times). */
void integrator_render_tile(const struct render_job *job, uint32_t x0, uint32_t y0, uint32_t w, uint32_t h,
                            float *pixels, struct tile_stats *stats);

/* One pass (< job->num_passes, >= 2 of them) of the rectangle: per pixel the mean of the
 * pass's k = spp / num_passes samples (CH_R..CH_B), the share of them that hit something
 * (CH_A; PASS_ALPHA_NONE when every sample was dropped as NaN or Inf) and variance 0. The
 * master folds a tile's passes in pass order (pass_pixel_fold); pixels depend only on
 * (scene, seed, frame, pass, pixel). */
#define PASS_ALPHA_NONE (-1.0f)
void integrator_render_tile_pass(const struct render_job *job, uint32_t pass, uint32_t x0, uint32_t y0, uint32_t w,
                                 uint32_t h, float *pixels, struct tile_stats *stats);

/* Batch means over the replicate streams of the passes (sampler.h): pass p belongs to
 * stream p mod R (integrator_streams), whose passes together are one sample set (for sobol a
 * prefix of one scrambled sequence, so their mean keeps the sampler's convergence), and the
 * streams are independent. The pixel is the average of the stream means (each stream
 * weighted equally: a tile's passes are a multiple of the stream count, or fewer than it)
 * and the variance of that average is estimated from the stream means' spread, s^2 / q (q
 * the streams that hold a pass). Zero-initialise, add each pass's mean with its pass. */
struct pass_batch {
    double sum[SAMPLER_MAX_STREAMS][4]; /* per stream: the sum of its pass means (R, G, B, luminance) */
    uint32_t count[SAMPLER_MAX_STREAMS];
    double mean[3], lum_mean;       /* the average of the stream means so far */
    uint32_t n;                     /* passes added */
};
/* stream < SAMPLER_MAX_STREAMS: the pass's stream (its pass mod R). */
void pass_batch_add(struct pass_batch *b, uint32_t stream, const double m[3]);
/* Channel k (0..2: R, G, B; 3: luminance): s^2 / q over the q stream means, 0 for fewer
 * than 2 streams. */
double pass_batch_var_of_mean(const struct pass_batch *b, int k);

/* A pixel's passes folded in pass order: batch means of the pass means and the sum of the
 * passes' coverage. Zero-initialise; pass_pixel_fold takes one pass's channels (as
 * integrator_render_tile_pass writes them; a pass with PASS_ALPHA_NONE is left out);
 * pass_pixel_finish writes the pixel (mean, coverage, variance of the mean s^2 / q) and
 * adds its relative standard error to stats (sum_rel_stderr, rel_stderr_pixels). */
struct pass_pixel {
    struct pass_batch b;
    double cover;
};
void pass_pixel_fold(struct pass_pixel *pp, uint32_t stream, const float *px);
/* R, the sampler streams of a render: SAMPLER_STREAMS_MAPS with photon maps, else
 * SAMPLER_STREAMS (the master's fold and the workers' sampler agree on it). */
static inline uint32_t integrator_streams(int photon_maps)
{
    return photon_maps ? SAMPLER_STREAMS_MAPS : SAMPLER_STREAMS;
}
void pass_pixel_finish(const struct pass_pixel *pp, float *px, struct tile_stats *stats);

#endif
