/* Path tracing of tiles. A render_job bundles what every tile of a frame reads (scene,
 * Embree scene, light table, camera); it is built once per frame and shared read-only by
 * the render threads. integrator_render_tile() writes a tile's interleaved channels
 * (tile.h order) and statistics; its pixels depend only on (scene, seed, frame, pixel),
 * never on the thread, tile size or order. Called by the worker (and by tests). */
#ifndef BRUME_INTEGRATOR_H
#define BRUME_INTEGRATOR_H
#include <stddef.h>
#include <stdint.h>
#include "render/accel.h"
#include "scene/camera.h"
#include "scene/light.h"
#include "scene/scene.h"
#include "render/tile.h"

struct media_job;

struct render_job {
    const struct scene *scene;
    struct accel accel;
    struct light_table lights;
    struct camera camera;
    uint32_t frame;
    vec3 **face_normals;    /* per mesh, per triangle: unit right-handed normal (zero if degenerate) */
    struct media_job *media; /* media_integrator.h; NULL when the scene has no media */
    struct mip *mips;       /* per scene texture (texshade.c), NULL when no material has one */
    int textured;           /* a material uses a texture: rays carry differentials */
};

int render_job_init(struct render_job *job, const struct scene *scene, uint32_t frame, uint32_t threads,
                    char *err, size_t errlen);
void render_job_free(struct render_job *job);
/* Next-event estimation toward one light point sampled with (pick, u, v) from surface point
 * p (material mat, shading normal ns and geometric normal ng on wo's side): the sample, the
 * BSDF value f toward it (cosine included) and its pdf, and the point a shadow ray aims at
 * (off an area light's surface). 0 when no light can arrive that way. Visibility is the
 * caller's: an occlusion ray (integrator.c) or transmittance (media_integrator.c). */
struct nee_sample {
    struct light_sample ls;
    vec3 f, target;
    float bsdf_pdf;
};
int nee_prepare(const struct render_job *job, const struct material *mat, vec3 p, vec3 ns, vec3 ng, vec3 wo,
                float pick, float u, float v, struct nee_sample *n);

/* The same job moved to another frame of its scene: rebuilds what depends on the frame
 * (Embree scene and its motion steps, camera, media state) and keeps the rest (texture
 * pyramids, light table, face normals). Pixels equal a fresh render_job_init's. On
 * failure the job is freed. */
int render_job_reframe(struct render_job *job, uint32_t frame, uint32_t threads, char *err, size_t errlen);

/* Radiance along one camera sample of pixel (px, py); *hit_any = 1 if the camera ray hit
 * geometry. May return NaN or Inf on a numerical failure (the caller counts and drops). */
vec3 integrator_sample(const struct render_job *job, uint32_t px, uint32_t py, uint32_t sample_index,
                       uint64_t *rays, int *hit_any);

/* Renders the pixel rectangle [x0, x0+w) x [y0, y0+h) into pixels (w*h*TILE_NUM_CHANNELS
 * floats). Fills stats (render_ns excluded: the caller times). */
void integrator_render_tile(const struct render_job *job, uint32_t x0, uint32_t y0, uint32_t w, uint32_t h,
                            float *pixels, struct tile_stats *stats);

#endif
