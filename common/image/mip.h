/* Texel images and their MIP pyramids, with the four lookups a texture can choose:
 * nearest and bilinear (level 0, unfiltered), trilinear (isotropic, between two levels)
 * and EWA (elliptically weighted average, Heckbert 1989, with the level chosen by the
 * ellipse's minor axis and a maximum anisotropy, as in pbrt-v3's MIPMap::EWA).
 * Coordinates (s, t) are in [0, 1) per repeat, s to the right, t down (row 0 on top).
 * 8-bit images stay 8-bit (sRGB-encoded or linear, decoded through a table), so a 16k
 * texture costs bytes, not floats; every level is built once per job and read-only
 * afterwards. Callers: texture.c (lookups), image_load.c (images), integrator.c (build). */
#ifndef BRUME_MIP_H
#define BRUME_MIP_H
#include <stddef.h>
#include <stdint.h>
#include "base/vec.h"

#define MIP_MAX_DIM 16384          /* width or height of a texture */
#define MIP_MAX_LEVELS 16          /* 1 + log2(MIP_MAX_DIM) */
#define MIP_EWA_LUT_SIZE 128

enum texel_format { TEXEL_U8_SRGB, TEXEL_U8_LINEAR, TEXEL_F32 };
enum texture_filter { TEXFILTER_NEAREST, TEXFILTER_BILINEAR, TEXFILTER_TRILINEAR, TEXFILTER_EWA, TEXFILTER_COUNT_ };
enum texture_wrap { TEXWRAP_REPEAT, TEXWRAP_CLAMP };

/* One image: width * height texels of `channels` (1 or 3) components, rows top to bottom.
 * data is mem_alloc'd (uint8_t for the U8 formats, float for F32). */
struct tex_image {
    uint32_t width, height, channels;
    enum texel_format format;
    void *data;
};

/* Bytes of an image of this shape, or 0 when a dimension is 0, above MIP_MAX_DIM, the
 * channel count is not 1 or 3, or the size overflows. */
size_t tex_image_bytes(uint32_t width, uint32_t height, uint32_t channels, enum texel_format format);
/* Allocates data for the shape (zeroed); 0, or -1 when tex_image_bytes says 0. */
int tex_image_alloc(struct tex_image *img, uint32_t width, uint32_t height, uint32_t channels,
                    enum texel_format format);
void tex_image_fini(struct tex_image *img);

/* The pyramid: level 0 is the image (borrowed, not copied); level k+1 is level k box-
 * filtered to max(1, floor(w / 2)) x max(1, floor(h / 2)) by exact area weights (any
 * size, not only powers of two), averaged in linear space. */
struct mip {
    uint32_t num_levels, channels;
    enum texel_format format;
    enum texture_wrap wrap;
    struct tex_image levels[MIP_MAX_LEVELS];
    int owns[MIP_MAX_LEVELS];
};

void mip_init(struct mip *m, const struct tex_image *base, enum texture_wrap wrap);
void mip_fini(struct mip *m);

/* The texel (x, y) of a level after wrapping, as linear RGB (gray is splatted). */
vec3 mip_texel(const struct mip *m, uint32_t level, int64_t x, int64_t y);

/* A filtered lookup at (s, t) with the footprint's derivative vectors (ds/dx, dt/dx) and
 * (ds/dy, dt/dy) in (s, t) units. max_aniso >= 1 (EWA only). Non-finite derivatives
 * count as zero (a point lookup); a non-finite (s, t) gives black. EWA scales the
 * derivatives by mip_ewa_box_scale() first. */
vec3 mip_lookup(const struct mip *m, enum texture_filter filter, float max_aniso, float s, float t, float dsdx,
                float dtdx, float dsdy, float dtdy);

/* The factor (about 0.78) EWA scales the footprint's axes by so that its Gaussian weights
 * have the variance of a box over the footprint: the 1-pixel footprint of a 1-spp lookup
 * then filters as the pixel's own box does, neither blurrier nor sharper. */
float mip_ewa_box_scale(void);

/* The continuous level a footprint `width` (in (s, t) units) maps to: log2 of the width
 * in level-0 texels of the larger dimension, clamped to [0, num_levels - 1]. */
float mip_level_for_width(const struct mip *m, float width);

/* The parts of the EWA lookup, exposed for tests. ewa_select picks, for the axes
 * (ds0, dt0) and (ds1, dt1), the (clamped, possibly lengthened) minor axis and the
 * continuous level; returns the level (or -1 for "bilinear at level 0": degenerate). */
float mip_ewa_select(const struct mip *m, float max_aniso, float *ds0, float *dt0, float *ds1, float *dt1);
/* EWA at one level; when rec is non-NULL, the texels visited and their normalized
 * weights are recorded there (up to cap; *count gets the number of non-zero weights). */
struct mip_ewa_record {
    int64_t *x, *y;
    float *w;
    size_t cap, count;
};
vec3 mip_ewa_level(const struct mip *m, uint32_t level, float s, float t, float ds0, float dt0, float ds1,
                   float dt1, struct mip_ewa_record *rec);

/* sRGB transfer functions (IEC 61966-2-1) on one component. */
float mip_srgb_to_linear(float c);
float mip_linear_to_srgb(float c);

#endif
