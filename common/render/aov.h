/* Arbitrary output variables (render.aovs; channels in render/tile.h): what one camera
 * sample records at its first hit, the per-pixel means of a pass, and the fold of passes.
 * N, albedo and P are means over the pixel's kept samples (a miss adds zero, so they are
 * weighted by coverage like the beauty); Z is the nearest first hit over the samples
 * (+inf when none hits) and the ids are those of that nearest hit (-1: none), the first
 * sample's in sample order on a tie. Passes fold in pass order as the beauty does, so a
 * whole-tile render and the master's fold give the same bits. Callers: integrator.c
 * (samples, passes), master/fold.c (passes), master/master.c (checks workers' tiles). */
#ifndef BRUME_AOV_H
#define BRUME_AOV_H
#include "render/tile.h"
#include "scene/material.h"
#include "scene/scene.h"
#include <math.h>
#include <stddef.h>
#include <string.h>

/* One camera sample's AOVs. */
struct aov_sample {
    float z;                    /* camera distance of the first hit; INFINITY on a miss */
    /* n, albedo and p lie next to each other, in the order of aov_accum's sums, so that
     * aov_accum_add adds them as one array of 9 (vectorised). */
    vec3 n;                     /* first hit's shading normal (facing the ray) */
    vec3 albedo;                /* first non-specular hit's albedo times the specular bounces' weight */
    vec3 p;                     /* first hit's world position */
    float id_object, id_material; /* first hit's; -1 on a miss */
};
_Static_assert(offsetof(struct aov_sample, albedo) == offsetof(struct aov_sample, n) + 3 * sizeof(float) &&
                   offsetof(struct aov_sample, p) == offsetof(struct aov_sample, n) + 6 * sizeof(float),
               "aov_sample: n, albedo, p contiguous");
static inline void aov_sample_miss(struct aov_sample *a)
{
    a->z = INFINITY;
    a->n = a->p = a->albedo = v3(0, 0, 0);
    a->id_object = a->id_material = -1.0f;
}

/* Object id of a hit (accel_hit geom, prim): meshes in scene order, then spheres. */
static inline uint32_t aov_object_id(const struct scene *sc, uint32_t geom, uint32_t sphere_geom, uint32_t prim)
{
    return geom < sphere_geom ? geom : sc->num_meshes + prim;
}

/* A non-delta material's albedo for the albedo AOV (what a denoiser takes as the
 * surface's colour, as OIDN asks): the diffuse reflectance of diffuse and plastic, the
 * reflectance at normal incidence of rough metals (mirror, conductor), the tint of a rough
 * dielectric. */
static inline vec3 aov_material_albedo(const struct material *m)
{
    switch (m->type) {
    case MATERIAL_DIFFUSE:
    case MATERIAL_PLASTIC:
        return m->albedo;
    case MATERIAL_MIRROR:
        return m->reflectance;
    case MATERIAL_CONDUCTOR:
        return material_fresnel_conductor(m, 1.0f);
    case MATERIAL_DIELECTRIC:
        return m->transmittance;
    default:
        return v3(0, 0, 0);
    }
}

/* Samples of one pixel in one pass. */
struct aov_accum {
    double sum[9];              /* N, albedo, P */
    float z, id_object, id_material;
};
void aov_accum_reset(struct aov_accum *acc);
static inline void aov_accum_add(struct aov_accum *acc, const struct aov_sample *s)
{
    float v[9];
    memcpy(v, &s->n, sizeof v); /* n, albedo, p: contiguous (asserted above) */
    for (int i = 0; i < 9; i++)
        acc->sum[i] += v[i];
    if (s->z < acc->z) {
        acc->z = s->z;
        acc->id_object = s->id_object;
        acc->id_material = s->id_material;
    }
}
/* The pixel's AOV channels (at l's offsets in px) from n kept samples. */
void aov_accum_write(const struct aov_accum *acc, uint32_t n, const struct tile_layout *l, float *px);

/* A pixel's passes folded in pass order (a pass whose samples were all dropped,
 * CH_A == PASS_ALPHA_NONE, is left out, as in pass_pixel_fold). */
struct aov_pixel {
    double mean[9];
    uint32_t n;
    float z, id_object, id_material;
};
void aov_pixel_init(struct aov_pixel *ap);
void aov_pixel_fold(struct aov_pixel *ap, const struct tile_layout *l, const float *px);
void aov_pixel_finish(const struct aov_pixel *ap, const struct tile_layout *l, float *px);

/* The same over a tile's pixels (interleaved, l->num_channels floats a pixel; the
 * layout's offsets looked up once): init, fold one pass's pixels, write the final channels
 * into out (laid out as ol; ap NULL: as if no pass was folded). */
void aov_tile_init(struct aov_pixel *ap, size_t pixels);
void aov_tile_fold(struct aov_pixel *ap, const struct tile_layout *l, const float *px, size_t pixels);
void aov_tile_finish(const struct aov_pixel *ap, const struct tile_layout *ol, float *out, size_t pixels);

/* 1 when a worker's pixel holds plausible AOVs: Z >= 0 or +inf, N, albedo and P finite,
 * ids -1 or integers below num_objects / num_materials. */
int aov_pixel_valid(const struct tile_layout *l, const float *px, uint32_t num_objects, uint32_t num_materials);
/* The first of a tile's pixels (l->num_channels floats each) that aov_pixel_valid rejects,
 * or pixels when none. */
size_t aov_tile_first_invalid(const struct tile_layout *l, const float *px, size_t pixels, uint32_t num_objects,
                              uint32_t num_materials);

/* Sets the AOV channels of pixels (interleaved as d says, any layout: found by name) to
 * what a pixel where nothing is hit holds: Z +inf, ids -1 (the rest is left alone). */
void aov_fill_miss(const struct image_desc *d, float *px, size_t pixels);

#endif
