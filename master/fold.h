/* Folding a frame's units (tile, pass) into final tiles: progressive passes arrive in any
 * order, from any worker, journal or kept copy, and each tile's passes are folded in pass
 * order (Welford's batch means, pass_pixel_fold), a pass that comes early being buffered,
 * so the final pixels do not depend on arrival order. Pure: no I/O. Called by
 * master/master.c; tested by tests/unit/test_fold.c. */
#ifndef BRUME_FOLD_H
#define BRUME_FOLD_H
#include <stdint.h>
#include "image/imgio.h"
#include "render/tile.h"

struct fold;

/* Folds for the tiles of desc in `passes` passes (>= 2). */
struct fold *fold_new(const struct image_desc *desc, uint32_t passes);
void fold_free(struct fold **f);
/* A new frame: nothing folded or buffered. */
void fold_reset(struct fold *f);
/* Unit (tile, pass)'s channels (the tile's w*h pixels, TILE_NUM_CHANNELS each, as
 * integrator_render_tile_pass writes them); tile and pass must be in range, and each unit
 * is given once (the scheduler's done state guarantees it). 1 when this completed the
 * tile: its final pixels (mean, coverage, batch-means variance) are in out (w*h pixels)
 * and its relative standard errors added to stats; 0 while passes are missing. */
int fold_add(struct fold *f, uint32_t tile, uint32_t pass, const float *px, float *out, struct tile_stats *stats);

#endif
