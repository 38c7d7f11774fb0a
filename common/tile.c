/* Tile channel names and statistics (see tile.h). */
#include "tile.h"

const char *const tile_channel_names[TILE_NUM_CHANNELS] = {
    "R", "G", "B", "A", "variance.R", "variance.G", "variance.B",
};

void tile_stats_add(struct tile_stats *sum, const struct tile_stats *t)
{
    sum->samples += t->samples;
    sum->rays += t->rays;
    sum->nan_samples += t->nan_samples;
    sum->render_ns += t->render_ns;
    sum->sum_rel_stderr += t->sum_rel_stderr;
    sum->rel_stderr_pixels += t->rel_stderr_pixels;
}
