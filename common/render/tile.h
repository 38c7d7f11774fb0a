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

/* The EXR layout of a frame: tiles of the render's tile size, the channels above, ZIP.
 * Master and workers both derive it from the settings, so their chunks agree. */
void tile_image_desc(struct image_desc *d, const struct render_settings *rs);

#endif
