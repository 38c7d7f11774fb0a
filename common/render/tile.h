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
