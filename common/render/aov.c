/* AOV records, pass means and pass folds (see aov.h). */
#include "render/aov.h"
#include <math.h>
#include <string.h>

/* The vector AOVs, in the order of their 3-component slots in sums and means. */
static const int vec_aov[3] = {AOV_N, AOV_ALBEDO, AOV_P};

void aov_accum_reset(struct aov_accum *acc)
{
    memset(acc->sum, 0, sizeof acc->sum);
    acc->z = INFINITY;
    acc->id_object = acc->id_material = -1.0f;
}

/* N, albedo and P (9 values, in that order) and the nearest hit into px at l's offsets. */
static void write_channels(const struct tile_layout *l, const double v[9], float z, float id_object,
                           float id_material, float *px)
{
    for (int k = 0; k < 3; k++)
        if (l->off[vec_aov[k]] >= 0)
            for (int c = 0; c < 3; c++)
                px[l->off[vec_aov[k]] + c] = (float)v[3 * k + c];
    if (l->off[AOV_Z] >= 0)
        px[l->off[AOV_Z]] = z;
    if (l->off[AOV_ID_OBJECT] >= 0)
        px[l->off[AOV_ID_OBJECT]] = id_object;
    if (l->off[AOV_ID_MATERIAL] >= 0)
        px[l->off[AOV_ID_MATERIAL]] = id_material;
}

void aov_accum_write(const struct aov_accum *acc, uint32_t n, const struct tile_layout *l, float *px)
{
    double m[9];
    for (int i = 0; i < 9; i++)
        m[i] = n ? acc->sum[i] / n : 0.0;
    write_channels(l, m, acc->z, acc->id_object, acc->id_material, px);
}

void aov_pixel_init(struct aov_pixel *ap)
{
    memset(ap, 0, sizeof *ap);
    ap->z = INFINITY;
    ap->id_object = ap->id_material = -1.0f;
}

void aov_pixel_fold(struct aov_pixel *ap, const struct tile_layout *l, const float *px)
{
    if (px[CH_A] < 0.0f)
        return; /* the pass kept no sample (PASS_ALPHA_NONE) */
    ap->n++;
    for (int k = 0; k < 3; k++)
        for (int c = 0; l->off[vec_aov[k]] >= 0 && c < 3; c++)
            ap->mean[3 * k + c] += ((double)px[l->off[vec_aov[k]] + c] - ap->mean[3 * k + c]) / ap->n;
    /* The nearest hit over the passes; without a Z channel the first pass's ids. */
    float z = l->off[AOV_Z] >= 0 ? px[l->off[AOV_Z]] : (ap->n == 1 ? 0.0f : INFINITY);
    if (z < ap->z) {
        ap->z = z;
        if (l->off[AOV_ID_OBJECT] >= 0)
            ap->id_object = px[l->off[AOV_ID_OBJECT]];
        if (l->off[AOV_ID_MATERIAL] >= 0)
            ap->id_material = px[l->off[AOV_ID_MATERIAL]];
    }
}

void aov_pixel_finish(const struct aov_pixel *ap, const struct tile_layout *l, float *px)
{
    write_channels(l, ap->mean, ap->z, ap->id_object, ap->id_material, px);
}

static int id_valid(float v, uint32_t count)
{
    /* In range first, so the conversion is defined (no floorf call: an integer test). */
    return v == -1.0f || (v >= 0.0f && v < (float)count && (float)(int32_t)v == v);
}

int aov_pixel_valid(const struct tile_layout *l, const float *px, uint32_t num_objects, uint32_t num_materials)
{
    /* x * 0 is 0 for a finite x and NaN for an infinite or NaN one: their sum is 0 exactly
     * when all 9 are finite (the master checks every pixel of every pass). */
    float z = 0.0f;
    for (int k = 0; k < 3; k++)
        if (l->off[vec_aov[k]] >= 0) {
            const float *v = &px[l->off[vec_aov[k]]];
            z += v[0] * 0.0f + v[1] * 0.0f + v[2] * 0.0f;
        }
    if (z != 0.0f)
        return 0;
    if (l->off[AOV_Z] >= 0 && !(px[l->off[AOV_Z]] >= 0.0f))
        return 0;
    if (l->off[AOV_ID_OBJECT] >= 0 && !id_valid(px[l->off[AOV_ID_OBJECT]], num_objects))
        return 0;
    if (l->off[AOV_ID_MATERIAL] >= 0 && !id_valid(px[l->off[AOV_ID_MATERIAL]], num_materials))
        return 0;
    return 1;
}

void aov_fill_miss(const struct image_desc *d, float *px, size_t pixels)
{
    for (uint32_t c = 0; c < d->num_channels; c++) {
        const char *name = d->channel_names[c];
        float v = !strcmp(name, "Z") ? INFINITY : !strcmp(name, "id.object") || !strcmp(name, "id.material") ? -1.0f : 0.0f;
        for (size_t i = 0; v != 0.0f && i < pixels; i++)
            px[i * d->num_channels + c] = v;
    }
}
