/* Path tracing of tiles over a render job (render_job.h, built once per frame and shared
 * read-only by the render threads). integrator_render_tile() writes a tile's interleaved channels
 * (tile.h order) and statistics; its pixels depend only on (scene, seed, frame, pixel),
 * never on the thread, tile size or order. Called by the worker (and by tests). */
#ifndef BRUME_INTEGRATOR_H
#define BRUME_INTEGRATOR_H
#include <stddef.h>
#include <stdint.h>
#include "render/render_job.h"
#include "render/tile.h"

/* Renders the pixel rectangle [x0, x0+w) x [y0, y0+h) into pixels (w*h*TILE_NUM_CHANNELS
 * floats). Fills stats (render_ns excluded: the caller times). */
void integrator_render_tile(const struct render_job *job, uint32_t x0, uint32_t y0, uint32_t w, uint32_t h,
                            float *pixels, struct tile_stats *stats);

/* Batch means over progressive passes: the running average of a pixel's pass means (RGB
 * and luminance) and the variance of that average estimated from their spread, s^2 / P
 * (s^2 the sample variance of the P pass means). Zero-initialise, add each pass's mean. */
struct pass_batch {
    double mean[3], m2[3], lum_mean, lum_m2;
    uint32_t n;
};
void pass_batch_add(struct pass_batch *b, const double m[3]);
/* Channel k (0..2: R, G, B; 3: luminance): s^2 / n, 0 for fewer than 2 passes. */
double pass_batch_var_of_mean(const struct pass_batch *b, int k);

#endif
