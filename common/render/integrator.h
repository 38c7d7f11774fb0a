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

#endif
