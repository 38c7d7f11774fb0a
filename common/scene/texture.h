/* Textures of the scene: image textures (decoded by image_load.c, a MIP pyramid per job)
 * and a procedural checkerboard whose box-filtered value has a closed form (the reference
 * for filter tests). A texture maps (u, v) through scale and offset to (s, t) and is
 * looked up with the footprint's derivatives from ray differentials (raydiff.c), with the
 * filter the texture chose (EWA by default). Owned by the scene; read-only while
 * rendering. Callers: scene_json.c and mesh_obj.c (creating), integrator.c (evaluating). */
#ifndef BRUME_TEXTURE_H
#define BRUME_TEXTURE_H
#include <stddef.h>
#include "image/mip.h"
#include "scene/scene_limits.h"
#include "base/vec.h"

#define TEXTURE_DEFAULT_FILTER TEXFILTER_EWA
#define TEXTURE_DEFAULT_MAX_ANISO 8.0f
#define TEXTURE_MAX_ANISO 64.0f

enum texture_type { TEXTURE_IMAGE, TEXTURE_CHECKER };

struct texture {
    char name[SCENE_NAME_MAX];
    enum texture_type type;
    enum texture_filter filter;
    enum texture_wrap wrap;
    float max_aniso;            /* EWA: longest / shortest axis, >= 1 */
    float scale[2], offset[2];  /* (s, t) = (u, v) * scale + offset, before the image's v flip */
    vec3 color0, color1;        /* checker: colour of even and odd squares (linear) */
    struct tex_image image;     /* TEXTURE_IMAGE: level 0 (owned) */
};

/* A texture coordinate and its derivatives per pixel step in x and y, and the offset
 * (cx, cy), in those steps, from the sample to the centre of the pixel cell it stands for
 * (raydiff_set_center, carried by the hit functions; 0 when none). Filters that integrate over the footprint (EWA,
 * trilinear, the checker's box) centre it there (tex_coord_centre); point lookups
 * (nearest, bilinear) stay at the sample, whose jitter then integrates the texture. */
struct tex_coord {
    float u, v;
    float dudx, dvdx, dudy, dvdy;
    float cx, cy;
};

/* (u, v) moved by the centring offset: u + cx dudx + cy dudy (and v); (u, v) itself when
 * that is not finite. */
void tex_coord_centre(const struct tex_coord *tc, float *u, float *v);

/* Defaults: EWA, max anisotropy 8, repeat, identity transform, white/black checker. */
void texture_init(struct texture *t, enum texture_type type, const char *name);
void texture_fini(struct texture *t);

int texture_filter_from_name(const char *name, enum texture_filter *out);
const char *texture_filter_name(enum texture_filter f);

/* The filtered value at tc. m is the image's pyramid (unused for the checker). */
vec3 texture_eval(const struct texture *t, const struct mip *m, const struct tex_coord *tc);

/* Checkerboard of unit squares (even floor(s) + floor(t): c0), box-filtered over
 * [s - ds, s + ds] x [t - dt, t + dt] in closed form; ds = dt = 0 is a point lookup. */
vec3 texture_checker_box(float s, float t, float ds, float dt, vec3 c0, vec3 c1);

#endif
