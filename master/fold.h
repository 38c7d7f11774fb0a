/* Folding a frame's units (tile, pass) into final tiles: passes arrive in any order, from
 * any worker, journal or kept copy, and each tile's passes are folded in pass order
 * (per-stream sums of the pass means, batch means over the sampler's streams:
 * pass_pixel_fold), a pass that comes early being buffered, so
 * the final pixels do not depend on arrival order. A final tile has FOLD_NUM_CHANNELS
 * channels: the tile's, then the samples each pixel received. Pure: no I/O. Called by
 * master/master.c; tested by tests/unit/test_fold.c. */
#ifndef BRUME_FOLD_H
#define BRUME_FOLD_H
#include <stdint.h>
#include "image/imgio.h"
#include "render/tile.h"

#define FOLD_NUM_CHANNELS (TILE_NUM_CHANNELS + 1)
#define FOLD_CH_SAMPLES TILE_NUM_CHANNELS
/* With AOVs a final tile has the tile's beauty channels, the samples channel, then the
 * AOVs (desc->num_channels + 1 in all, at most FOLD_MAX_CHANNELS). */
#define FOLD_MAX_CHANNELS (TILE_MAX_CHANNELS + 1)
extern const char *const fold_samples_channel; /* "samples" */

struct fold;

/* Folds for the tiles of desc in at most `passes` passes (>= 2) of spp_per_pass samples,
 * pass p in stream p mod streams (integrator_streams). */
struct fold *fold_new(const struct image_desc *desc, uint32_t passes, uint32_t spp_per_pass, uint32_t streams);
void fold_free(struct fold **f);
/* A new frame: nothing folded or buffered. */
void fold_reset(struct fold *f);
/* The output layout: desc's beauty channels, the samples channel, desc's AOVs. */
void fold_output_desc(const struct image_desc *desc, struct image_desc *out);
/* Unit (tile, pass)'s channels (the tile's w*h pixels, desc->num_channels each, as
 * integrator_render_tile_pass writes them); tile and pass must be in range, and each unit
 * is given once (the scheduler's done state guarantees it). Returns the passes folded
 * now: passes 0..n-1 are in, later ones buffered. */
uint32_t fold_add_unit(struct fold *f, uint32_t tile, uint32_t pass, const float *px);
/* An adaptive render's unit: the tile's slot-th unit (slots arrive in any order and are
 * folded in slot order, at most `passes` of them), which rendered sample pass `pass` for
 * the pixel blocks of mask (render/tile.h) only: its other pixels are ignored. Each
 * block's passes must come in increasing pass order over the slots (adapt's release
 * gives them so), so that every pixel folds its passes in pass order, as a uniform
 * render would. fold_add_unit is the slot = pass, every block case. */
uint32_t fold_add_slot(struct fold *f, uint32_t tile, uint32_t slot, uint32_t pass, uint64_t mask, const float *px);
/* A tile's final pixels from its folded passes (mean, coverage, batch-means variance,
 * samples: the passes each pixel's block received) into out (w*h pixels of desc->num_channels + 1), its relative standard errors
 * added to stats; the tile then takes nothing more. */
void fold_finish(struct fold *f, uint32_t tile, float *out, struct tile_stats *stats);
/* The master's way for renders whose every tile gets all `passes` units and that read no
 * sums of unfinished tiles (fold_block_sums; not adaptive ones): a tile's units are kept
 * as they come (copies: w*h pixels of the unit's channels, a seventh of the per-pixel batch
 * sums) and folded in batches, in slot order, on any thread. With at most
 * FOLD_KEEP_ALL_PASSES passes a tile's one batch is all its units, once its last is in
 * (cheapest: no sums kept between batches); with more, a batch is due as soon as
 * FOLD_BATCH units from the tile's next slot on are in without a gap (or they reach its
 * last slot), so that the master holds a tile's batch sums and a few copies, not a copy of
 * every pass of every tile (units go out pass by pass: every tile's passes would be kept
 * until the frame's last pass). fold_add_take gives unit (tile, pass) (copied) and returns
 * the tile's batch if one is due now, else NULL; a tile takes units either this way or
 * through fold_add_slot, not both. fold_run then folds the batch's units in slot order
 * into the tile's sums (the same bits as fold_add), and for the tile's last batch
 * (fold_units_final) finishes the tile into out (stats: the tile's relative errors
 * added), with *scratch (*scratch_size bytes, grown as needed; one per thread, freed by
 * its owner); it reads only f's settings, so it runs on any thread while the caller goes
 * on with other tiles. A tile has one batch out at a time: a batch that is not final goes
 * back with fold_units_return, which gives the tile's next batch if one is due by then.
 * fold_units_free frees a batch (NULL is fine). */
#define FOLD_KEEP_ALL_PASSES 16
#define FOLD_BATCH 8
struct fold_units;
struct fold_units *fold_add_take(struct fold *f, uint32_t tile, uint32_t pass, const float *px);
/* fold_add_take with *px taken over instead of copied (set to NULL): fold_unit_copy's
 * buffer (the checker pool makes it beside its decode, so the loop copies nothing). */
struct fold_units *fold_add_take_own(struct fold *f, uint32_t tile, uint32_t pass, float **px);
/* A malloc'ed copy of unit px of tile: exactly its values, fold_unit_floats(f, tile)
 * floats (its pixels x the units' channels). Reads only f's settings: any thread. */
float *fold_unit_copy(const struct fold *f, uint32_t tile, const float *px);
size_t fold_unit_floats(const struct fold *f, uint32_t tile);
void fold_run(const struct fold *f, struct fold_units *u, void **scratch, size_t *scratch_size, float *out,
              struct tile_stats *stats);
/* 1 when u is its tile's last batch (fold_run has written the tile's pixels). */
int fold_units_final(const struct fold_units *u);
/* A batch fold_run has folded, not final, given back (*u taken, set to NULL): the tile keeps
 * its sums, and its next batch is returned if one is due now, else NULL. A final batch is
 * only freed. */
struct fold_units *fold_units_return(struct fold *f, struct fold_units **u);
/* Units fold_add_take keeps that no batch has taken yet (over every tile; a scan, for
 * tests). */
uint32_t fold_kept_units(const struct fold *f);
uint32_t fold_units_tile(const struct fold_units *u);
void fold_units_free(struct fold_units **u);
/* fold_add_unit, and fold_finish once all `passes` are in: 1 then, 0 while passes are
 * missing. */
int fold_add(struct fold *f, uint32_t tile, uint32_t pass, const float *px, float *out, struct tile_stats *stats);
/* Over the tile's pixels after its folded passes: the sum of the variance of the pixel
 * mean (s^2 / q over its q stream means), the sum of its square over q + 1 (an unbiased
 * estimate of its true square over q - 1: the variance's degrees of freedom), and the sum of the pixel mean, each the mean of R, G and B (as the
 * summary's relRMSE counts them). */
void fold_tile_sums(const struct fold *f, uint32_t tile, double *sum_var, double *sum_var_sq, double *sum_mean);
/* The same over the pixels of the blocks in mask only (one block: 1 << b). */
void fold_block_sums(const struct fold *f, uint32_t tile, uint64_t mask, double *sum_var, double *sum_var_sq,
                     double *sum_mean);
/* fold_block_sums of every block b of the tile (render/tile.h: tile_blocks_side^2 of them)
 * into sum_var[b], sum_var_sq[b], sum_mean[b], in one pass over the tile's pixels (the
 * same bits as one call per block; a block past the tile's edge gets zeros). */
void fold_blocks_sums(const struct fold *f, uint32_t tile, double *sum_var, double *sum_var_sq, double *sum_mean);
/* The per-pixel bound's figures of every block b of the tile (adapt.h): worst[b], the
 * largest over its pixels of the variance of the pixel mean over max(pixel mean, floor)^2
 * (a squared relative standard error; 0 where the scale is 0), and over[b], its pixels
 * whose figure is above bound^2. */
void fold_blocks_worst(const struct fold *f, uint32_t tile, double floor, double bound, double *worst, uint32_t *over);

/* The image's estimated relRMSE (the summary's figure, the EXR's brume_est_rel_rmse) from
 * its final tiles' pixels, as they lie in the output (with one pass the workers' tiles,
 * else the folded ones; black --tiles fillers too): sqrt(mean over pixels of the variance
 * channels' mean over R, G, B) / (mean over pixels of the mean of R, G and B). Each tile is
 * given once, in any order, when its pixels are decoded or folded anyway; each tile's
 * pixels are summed in pixel order, and the tiles' sums in tile order at the end (two
 * doubles a tile), so the figure has the same bits for any arrival order, worker count or
 * journal replay. */
struct fold_est;
struct fold_est *fold_est_new(const struct image_desc *desc);
void fold_est_free(struct fold_est **e);
/* A new frame: no tile given. */
void fold_est_reset(struct fold_est *e);
/* Tile's final pixels: its w*h pixels of desc->num_channels (desc as given to fold_est_new). */
void fold_est_add(struct fold_est *e, uint32_t tile, const float *px);
/* fold_est_add in two steps, the sums on any thread (the checker pool's, for the tiles it
 * folds) and the put on the loop's: the same bits. */
struct fold_est_sums {
    double var, mean;
    uint64_t saturated;
};
void fold_est_tile_sums(const struct image_desc *desc, uint32_t tile, const float *px, struct fold_est_sums *out);
void fold_est_put(struct fold_est *e, uint32_t tile, const struct fold_est_sums *sums);
/* The estimate over the tiles given so far (0 for none or a black image); *saturated: their
 * pixels whose variance channel is FLT_MAX (past float's range). */
double fold_est_result(const struct fold_est *e, uint64_t *saturated);

#endif
