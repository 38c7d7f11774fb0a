/* Tile channel names, AOV layout and statistics (see tile.h): the one table of channel
 * order that the worker writes and the master assembles by. */
#include "render/tile.h"
#include <stdio.h>
#include <string.h>

const char *const tile_channel_names[TILE_NUM_CHANNELS] = {
    "R", "G", "B", "A", "variance.R", "variance.G", "variance.B",
};

static const char *const aov_channel_names[AOV_COUNT_][3] = {
    {"Z"}, {"N.X", "N.Y", "N.Z"}, {"albedo.R", "albedo.G", "albedo.B"}, {"P.X", "P.Y", "P.Z"}, {"id.object"},
    {"id.material"},
};

uint32_t tile_aov_channels(enum aov a)
{
    return a == AOV_N || a == AOV_ALBEDO || a == AOV_P ? 3 : 1;
}

const char *tile_aov_channel_name(enum aov a, uint32_t k)
{
    return aov_channel_names[a][k];
}

void tile_layout_init(struct tile_layout *l, uint32_t aovs)
{
    l->aovs = aovs & AOV_ALL;
    l->num_channels = TILE_NUM_CHANNELS;
    for (int a = 0; a < AOV_COUNT_; a++) {
        l->off[a] = -1;
        if (l->aovs & (1u << a)) {
            l->off[a] = (int)l->num_channels;
            l->num_channels += tile_aov_channels((enum aov)a);
        }
    }
}

void tile_layout_from_desc(struct tile_layout *l, const struct image_desc *d)
{
    uint32_t aovs = 0;
    for (uint32_t c = TILE_NUM_CHANNELS; c < d->num_channels; c++)
        for (int a = 0; a < AOV_COUNT_; a++)
            if (!strcmp(d->channel_names[c], aov_channel_names[a][0]))
                aovs |= 1u << a;
    tile_layout_init(l, aovs);
}

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
    for (int c = 0; c < TILE_NUM_CHANNELS; c++)
        snprintf(d->channel_names[c], sizeof d->channel_names[c], "%s", tile_channel_names[c]);
    struct tile_layout l;
    tile_layout_init(&l, rs->aovs);
    d->num_channels = TILE_NUM_CHANNELS;
    for (int a = 0; a < AOV_COUNT_; a++)
        for (uint32_t k = 0; l.off[a] >= 0 && k < tile_aov_channels((enum aov)a); k++) {
            if (a == AOV_N || a == AOV_ALBEDO) /* HALF: as OIDN and compositors take them */
                d->half_mask |= 1u << d->num_channels;
            snprintf(d->channel_names[d->num_channels++], sizeof d->channel_names[0], "%s",
                     aov_channel_names[a][k]);
        }
    d->compression = IMGIO_ZIP;
}
