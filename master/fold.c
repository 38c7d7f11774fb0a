/* Pass folding (see fold.h). Per tile: how many passes are folded, the running per-pixel
 * batch means, and copies of passes that arrived before an earlier one; both are freed
 * once the tile is final. */
#include "fold.h"
#include "base/log.h"
#include "render/integrator.h"
#include <stdlib.h>
#include <string.h>

struct fold_tile {
    uint32_t folded;            /* passes 0..folded-1 are in acc */
    struct pass_pixel *acc;     /* per pixel, NULL before the first pass */
    float **early;              /* per pass: a copy of a pass that came before its turn, or NULL */
};

struct fold {
    struct image_desc desc;
    uint32_t passes, num_tiles, tiles_x;
    struct fold_tile *tiles;
};

struct fold *fold_new(const struct image_desc *desc, uint32_t passes)
{
    struct fold *f = mem_calloc(1, sizeof *f);
    f->desc = *desc;
    f->passes = passes;
    f->tiles_x = imgio_tiles_x(desc);
    f->num_tiles = f->tiles_x * imgio_tiles_y(desc);
    f->tiles = mem_calloc(f->num_tiles ? f->num_tiles : 1, sizeof *f->tiles);
    return f;
}

static void tile_clear(struct fold *f, struct fold_tile *t)
{
    free(t->acc);
    for (uint32_t p = 0; t->early && p < f->passes; p++)
        free(t->early[p]);
    free(t->early);
    memset(t, 0, sizeof *t);
}

void fold_reset(struct fold *f)
{
    for (uint32_t i = 0; i < f->num_tiles; i++)
        tile_clear(f, &f->tiles[i]);
}

void fold_free(struct fold **fp)
{
    struct fold *f = *fp;
    if (!f)
        return;
    fold_reset(f);
    free(f->tiles);
    free(f);
    *fp = NULL;
}

static void fold_pass(struct fold_tile *t, size_t pixels, const float *px)
{
    for (size_t i = 0; i < pixels; i++)
        pass_pixel_fold(&t->acc[i], &px[i * TILE_NUM_CHANNELS]);
    t->folded++;
}

int fold_add(struct fold *f, uint32_t tile, uint32_t pass, const float *px, float *out, struct tile_stats *stats)
{
    CHECK(tile < f->num_tiles && pass < f->passes);
    struct fold_tile *t = &f->tiles[tile];
    uint32_t x0, y0, w, h;
    imgio_tile_rect(&f->desc, tile % f->tiles_x, tile / f->tiles_x, &x0, &y0, &w, &h);
    size_t pixels = (size_t)w * h;
    if (!t->acc) {
        t->acc = mem_calloc(pixels, sizeof *t->acc);
        t->early = mem_calloc(f->passes, sizeof *t->early);
    }
    if (pass != t->folded) {
        CHECK(pass > t->folded && !t->early[pass]);
        t->early[pass] = mem_alloc(sizeof(float) * pixels * TILE_NUM_CHANNELS);
        memcpy(t->early[pass], px, sizeof(float) * pixels * TILE_NUM_CHANNELS);
        return 0;
    }
    fold_pass(t, pixels, px);
    while (t->folded < f->passes && t->early[t->folded]) {
        float *e = t->early[t->folded];
        t->early[t->folded] = NULL;
        fold_pass(t, pixels, e);
        free(e);
    }
    if (t->folded < f->passes)
        return 0;
    for (size_t i = 0; i < pixels; i++)
        pass_pixel_finish(&t->acc[i], &out[i * TILE_NUM_CHANNELS], stats);
    tile_clear(f, t);
    t->folded = f->passes; /* final: nothing more is taken */
    return 1;
}
