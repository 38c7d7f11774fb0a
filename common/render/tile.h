/* What a rendered tile is: the channels every render produces (in this order, interleaved
 * per pixel in tile buffers) and the statistics that travel with it to the master.
 * Shared by the integrator (fills them), proto (carries them) and the master (sums them). */
#ifndef BRUME_TILE_H
#define BRUME_TILE_H
#include <float.h>
#include <stdint.h>
#include "image/imgio.h"
#include "scene/scene.h"

/* Mean radiance, coverage, and the variance of the mean per colour channel (the
 * per-pixel noise estimate written next to the image). */
enum tile_channel { CH_R, CH_G, CH_B, CH_A, CH_VAR_R, CH_VAR_G, CH_VAR_B, TILE_NUM_CHANNELS };
extern const char *const tile_channel_names[TILE_NUM_CHANNELS];

/* A frame's channels: the beauty channels above, then the AOVs the scene asks for
 * (render.aovs), in enum aov order, each with 1 or 3 channels (tile_aov_names). Tile
 * buffers hold num_channels floats a pixel. off[a] is AOV a's first channel, or -1. */
#define TILE_MAX_AOV_CHANNELS 12
#define TILE_MAX_CHANNELS (TILE_NUM_CHANNELS + TILE_MAX_AOV_CHANNELS)
struct tile_layout {
    uint32_t aovs;          /* bit set of enum aov */
    uint32_t num_channels;  /* TILE_NUM_CHANNELS + the AOVs' channels */
    int off[AOV_COUNT_];
};
/* An AOV's channel count and EXR channel names (the first is the AOV's name in
 * render.aovs: Z, N.X, albedo.R, P.X, id.object, id.material). */
uint32_t tile_aov_channels(enum aov a);
const char *tile_aov_channel_name(enum aov a, uint32_t k);
void tile_layout_init(struct tile_layout *l, uint32_t aovs);
/* The layout of a frame's desc (tile_image_desc's channels, as named). */
void tile_layout_from_desc(struct tile_layout *l, const struct image_desc *d);

struct tile_stats {
    uint64_t samples;       /* camera samples traced */
    uint64_t rays;          /* all rays (camera, bounce, shadow) */
    uint64_t nan_samples;   /* samples dropped for NaN or Inf */
    uint64_t render_ns;     /* time spent rendering the tile */
    double sum_rel_stderr;  /* sum over pixels of relative standard error (luminance) */
    uint32_t rel_stderr_pixels; /* pixels counted in that sum (non-black) */
};

void tile_stats_add(struct tile_stats *sum, const struct tile_stats *t);

/* A variance channel's value: the double rounded to float, saturated at FLT_MAX. A scene
 * bright enough (emission 1e25 and up) has a sample variance past float's range while its
 * mean is still a float; the channel then says "at least FLT_MAX" instead of inf, which
 * the master would take for a lying worker. */
static inline float tile_variance_value(double v)
{
    return v > (double)FLT_MAX ? FLT_MAX : (float)v;
}

/* Pixel blocks of a tile: the unit of an adaptive render's allocation (docs/adaptive.md).
 * Blocks are squares of tile_block_size(tile_size) pixels (TILE_BLOCK_MIN, or more for
 * tiles over TILE_BLOCK_MIN x TILE_MAX_BLOCKS_SIDE), tile_blocks_side of them in a row of
 * the tile (an edge tile's last ones are cut or empty), block b of a tile at row
 * b / side, column b % side: a 64-bit mask names any set of them (TILE's mask). 4 px, the
 * finest a 32-px tile's mask allows: the finer the blocks, the less the best allocation
 * costs (docs/adaptive.md, "Oracle"). */
#define TILE_BLOCK_MIN 4u
#define TILE_MAX_BLOCKS_SIDE 8u
#define TILE_MASK_ALL (~(uint64_t)0)
static inline uint32_t tile_block_size(uint32_t tile_size)
{
    uint32_t b = (tile_size + TILE_MAX_BLOCKS_SIDE - 1) / TILE_MAX_BLOCKS_SIDE;
    return b > TILE_BLOCK_MIN ? b : TILE_BLOCK_MIN;
}
static inline uint32_t tile_blocks_side(uint32_t tile_size)
{
    uint32_t b = tile_block_size(tile_size);
    return (tile_size + b - 1) / b;
}
/* The block of pixel (x, y) of a tile (coordinates within the tile). */
static inline uint32_t tile_pixel_block(uint32_t tile_size, uint32_t x, uint32_t y)
{
    uint32_t b = tile_block_size(tile_size);
    return y / b * tile_blocks_side(tile_size) + x / b;
}

/* The EXR layout of a frame: tiles of the render's tile size, the channels above, ZIP.
 * Master and workers both derive it from the settings, so their chunks agree. */
void tile_image_desc(struct image_desc *d, const struct render_settings *rs);

#endif
