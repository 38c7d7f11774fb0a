/* Scaffolding shared by the unit tests (tests/unit/test_*.c): an in-memory asset source,
 * scene files parsed from strings, quads built in code and whole-image renders. Failures
 * inside a helper fail the calling test through Criterion's asserts. */
#ifndef BRUME_TEST_HELPERS_H
#define BRUME_TEST_HELPERS_H

#include <stddef.h>
#include <stdint.h>
#include "base/asset.h"
#include "render/integrator.h"
#include "scene/scene.h"

/* A file of an in-memory folder; a folder is an array ended by {NULL}. size 0 means
 * strlen(data), so text files need no size. */
struct mem_file { const char *path; const void *data; size_t size; };

/* The asset_source read function over a folder (ctx: its first mem_file). */
int mem_read(void *ctx, const char *rel_path, char **data, size_t *size, char *err, size_t errlen);

/* The whole file at path, malloc'd (one byte more, unset), its size in *size; fails the
 * test naming the path and why (hint) when it cannot be read. */
uint8_t *test_read_file(const char *path, size_t *size, const char *hint);

/* Parses text as "scenes/t.json" with files (NULL: none) as its folder, in world space
 * (origin 0: positions stay as written); err holds 512 bytes. Returns the parser's rc. */
int test_scene_load(const char *text, const struct mem_file *files, struct scene *s, char *err);
/* Asserts that text fails to parse with an error containing want and leaves the scene
 * empty; returns the error (static) for tests that check more. */
const char *test_scene_expect_error(const char *text, const struct mem_file *files, const char *want);

/* Quad a b c d as two triangles (a b c, a c d; with flip, a c b, a d c), material mat. */
struct mesh test_quad(vec3 a, vec3 b, vec3 c, vec3 d, uint32_t mat, int flip);

/* Renders all of s (frame 0) as one tile; returns mem_alloc'd pixels of the settings'
 * tile_layout (TILE_NUM_CHANNELS floats each without AOVs). */
/* The same with the photon map `map` (or NULL) lent to the job for the render. */
float *test_render_map(const struct scene *s, struct photon_map *map, uint32_t threads, struct tile_stats *st);
float *test_render(const struct scene *s, uint32_t threads, struct tile_stats *st);
/* Mean of colour channel ch (CH_R, CH_G or CH_B) over a w x h render and its standard error,
 * from the matching variance channel. */
double test_channel_mean(const float *px, uint32_t w, uint32_t h, enum tile_channel ch, double *se);
/* Camera at z = 10 looking down -z: a w x 4 image spans x in [-2, 2] at z = 0; shutter
 * [0, 1], spp, max_depth 1, seed 3 (the moving-edge ramp tests). */
void test_ramp_camera(struct scene *s, uint32_t w, uint32_t spp);

/* A direction sampler against its density: cells of (theta in [0, th_max), azimuth)
 * around unit axis c (nt x np of them, at most 32 x 32), each cell's mass under pdf by
 * quadrature (q x q points); asserts that the masses sum to 1 within tol, that n samples
 * of sample(ctx, k), k = 0..n-1, are unit directions of density > 0 within th_max of c,
 * that at most max_light fall in cells whose expected count is below 5, and that the
 * chi-square over the other cells (at least min_cells) is below (cells - 1) + 6 sqrt(2
 * (cells - 1)). what names the sampler in the log. */
void test_direction_chi_square(const char *what, vec3 c, double th_max, int nt, int np, int q,
                               float (*pdf)(void *ctx, vec3 w), vec3 (*sample)(void *ctx, uint32_t k), void *ctx,
                               int n, double tol, int max_light, int min_cells);

#endif
