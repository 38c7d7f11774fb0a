/* Tile channel names and statistics (see tile.h): the one table of channel order that
 * the worker writes and the master assembles by. */
#include "render/tile.h"
#include <stdio.h>
#include <string.h>

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

void tile_image_desc(struct image_desc *d, const struct render_settings *rs)
{
    memset(d, 0, sizeof *d);
    d->width = rs->width;
    d->height = rs->height;
    d->tile_size = rs->tile_size;
    d->num_channels = TILE_NUM_CHANNELS;
    for (int c = 0; c < TILE_NUM_CHANNELS; c++)
        snprintf(d->channel_names[c], sizeof d->channel_names[c], "%s", tile_channel_names[c]);
    d->compression = IMGIO_ZIP;
}
