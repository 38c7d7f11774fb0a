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

void aov_accum_write(const struct aov_accum *acc, uint32_t n, const struct tile_layout *l, float *px)
{
    const double dn = n;
    for (int k = 0; k < 3; k++) {
        int o = l->off[vec_aov[k]];
        for (int c = 0; o >= 0 && c < 3; c++)
            px[o + c] = n ? (float)(acc->sum[3 * k + c] / dn) : 0.0f;
    }
    if (l->off[AOV_Z] >= 0)
        px[l->off[AOV_Z]] = acc->z;
    if (l->off[AOV_ID_OBJECT] >= 0)
        px[l->off[AOV_ID_OBJECT]] = acc->id_object;
    if (l->off[AOV_ID_MATERIAL] >= 0)
        px[l->off[AOV_ID_MATERIAL]] = acc->id_material;
}

void aov_pixel_init(struct aov_pixel *ap)
{
    memset(ap, 0, sizeof *ap);
    ap->z = INFINITY;
    ap->id_object = ap->id_material = -1.0f;
}

void aov_pixel_fold(struct aov_pixel *ap, const struct tile_layout *l, const float *px)
{
    aov_tile_fold(ap, l, px, 1);
}

void aov_pixel_finish(const struct aov_pixel *ap, const struct tile_layout *l, float *px)
{
    aov_tile_finish(ap, l, px, 1);
}

/* A layout's AOV offsets, looked up once for a tile: the vector AOVs present (vec: their
 * first channels, slot: their 3-component slot in sums and means) and the scalar ones. */
struct aov_offsets {
    int nv, vec[3], slot[3], z, id_object, id_material;
};
static void aov_offsets(const struct tile_layout *l, struct aov_offsets *o)
{
    o->nv = 0;
    for (int k = 0; k < 3; k++)
        if (l->off[vec_aov[k]] >= 0) {
            o->vec[o->nv] = l->off[vec_aov[k]];
            o->slot[o->nv++] = 3 * k;
        }
    o->z = l->off[AOV_Z];
    o->id_object = l->off[AOV_ID_OBJECT];
    o->id_material = l->off[AOV_ID_MATERIAL];
}

void aov_tile_init(struct aov_pixel *ap, size_t pixels)
{
    struct aov_pixel none;
    aov_pixel_init(&none);
    for (size_t i = 0; i < pixels; i++)
        ap[i] = none;
}

/* aov_pixel_fold's arithmetic, value for value (the same bits). */
void aov_tile_fold(struct aov_pixel *ap, const struct tile_layout *l, const float *px, size_t pixels)
{
    struct aov_offsets o;
    aov_offsets(l, &o);
    size_t nc = l->num_channels;
    for (size_t i = 0; i < pixels; i++, px += nc) {
        struct aov_pixel *a = &ap[i];
        if (px[CH_A] < 0.0f)
            continue; /* the pass kept no sample (PASS_ALPHA_NONE) */
        a->n++;
        for (int k = 0; k < o.nv; k++) {
            const float *v = &px[o.vec[k]];
            double *m = &a->mean[o.slot[k]];
            for (int c = 0; c < 3; c++)
                m[c] += ((double)v[c] - m[c]) / a->n;
        }
        float z = o.z >= 0 ? px[o.z] : (a->n == 1 ? 0.0f : INFINITY);
        if (z < a->z) {
            a->z = z;
            if (o.id_object >= 0)
                a->id_object = px[o.id_object];
            if (o.id_material >= 0)
                a->id_material = px[o.id_material];
        }
    }
}

void aov_tile_finish(const struct aov_pixel *ap, const struct tile_layout *ol, float *out, size_t pixels)
{
    struct aov_offsets o;
    aov_offsets(ol, &o);
    struct aov_pixel none;
    aov_pixel_init(&none);
    size_t nc = ol->num_channels;
    for (size_t i = 0; i < pixels; i++, out += nc) {
        const struct aov_pixel *a = ap ? &ap[i] : &none;
        for (int k = 0; k < o.nv; k++)
            for (int c = 0; c < 3; c++)
                out[o.vec[k] + c] = (float)a->mean[o.slot[k] + c];
        if (o.z >= 0)
            out[o.z] = a->z;
        if (o.id_object >= 0)
            out[o.id_object] = a->id_object;
        if (o.id_material >= 0)
            out[o.id_material] = a->id_material;
    }
}

static int id_valid(float v, uint32_t count)
{
    /* In range first, so the conversion is defined (no floorf call: an integer test). */
    return v == -1.0f || (v >= 0.0f && v < (float)count && (float)(int32_t)v == v);
}

int aov_pixel_valid(const struct tile_layout *l, const float *px, uint32_t num_objects, uint32_t num_materials)
{
    return aov_tile_first_invalid(l, px, 1, num_objects, num_materials) == 1;
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

size_t aov_tile_first_invalid(const struct tile_layout *l, const float *px, size_t pixels, uint32_t num_objects,
                              uint32_t num_materials)
{
    struct aov_offsets o;
    aov_offsets(l, &o);
    size_t nc = l->num_channels;
    for (size_t i = 0; i < pixels; i++, px += nc) {
        float z = 0.0f; /* as in aov_pixel_valid: 0 exactly when all are finite */
        for (int k = 0; k < o.nv; k++) {
            const float *v = &px[o.vec[k]];
            z += v[0] * 0.0f + v[1] * 0.0f + v[2] * 0.0f;
        }
        if (z != 0.0f || (o.z >= 0 && !(px[o.z] >= 0.0f)) ||
            (o.id_object >= 0 && !id_valid(px[o.id_object], num_objects)) ||
            (o.id_material >= 0 && !id_valid(px[o.id_material], num_materials)))
            return i;
    }
    return pixels;
}
