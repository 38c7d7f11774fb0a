/* The frame context: what every tile of a frame reads (scene, Embree scene, light table,
 * camera, media state, texture pyramids, the decoded photon map). Built once per frame by
 * render_job_init and shared read-only by the render threads; it owns everything built at
 * render time, the photon map included (the scene description owns none of it). It must
 * not move in memory once built (the media state points into it). Used by the worker, the
 * master's photon pass and tests; everything in render/ that shades reads it. */
#ifndef BRUME_RENDER_JOB_H
#define BRUME_RENDER_JOB_H
#include <stddef.h>
#include <stdint.h>
#include "render/accel.h"
#include "scene/camera.h"
#include "scene/light.h"
#include "scene/medium.h"

struct media_job;
struct mip;
struct motion_vis;
struct photon_map;

struct render_job {
    const struct scene *scene;
    struct accel accel;
    struct light_table lights;
    struct camera camera;
    uint32_t frame;
    struct media_job *media; /* media_track.h; NULL when the scene has no media */
    struct motion_vis *motion_vis; /* analytic motion blur (motion_vis.h); NULL: camera rays sample time */
    struct mip *mips;       /* per scene texture (NULL entries for checkers), NULL when no material has one */
    int textured;           /* a material uses a texture: rays carry differentials */
    struct photon_map **pass_maps; /* owned: the master's photon maps, one slot per pass (NULL: not installed),
                                    * or NULL without photon maps */
    uint32_t num_passes;        /* progressive photon-map passes (slots of pass_maps); 1 without a map */
    struct media_job *pass_media; /* per pass: a view of *media whose map (and radius) is that pass's; NULL
                                   * without media. Views share media's pointers and own nothing. */
    int packets;            /* camera rays go in packets (packet.h): no media, accel.packets_exact and
                             * BRUME_PACKETS not 0 (read once per frame here, not per tile) */
    uint32_t direct_samples; /* media scenes: camera rays per sample for the light seen straight from the
                              * camera (volume.direct_samples), when an emitter or an environment can be
                              * seen and the camera's medium is not a grid; else 1 (the sample's own) */
    float direct_shift[MEDIA_MAX_DIRECT_SAMPLES][2]; /* the pixel-jitter shift of direct ray i (< direct_samples; 0 for i = 0):
                              * the R2 lattice (Roberts), i (1 / phi2, 1 / phi2^2) modulo 1 */
    int rays_find_light;    /* a ray can find light by hitting or missing: an emitting material or an
                             * environment. Without one, a path's last vertex samples no further ray,
                             * which could only have found light that way */
};

int render_job_init(struct render_job *job, const struct scene *scene, uint32_t frame, uint32_t threads,
                    char *err, size_t errlen);
/* The same job moved to another frame of its scene: rebuilds what depends on the frame
 * (Embree scene and its motion steps, camera, media state) and keeps the rest (texture
 * pyramids, light table, photon map). Pixels equal a fresh render_job_init's. On failure
 * the job is freed. */
int render_job_reframe(struct render_job *job, uint32_t frame, uint32_t threads, char *err, size_t errlen);
/* Takes ownership of *map (set to NULL), replacing the job's photon maps: *map and the
 * passes' maps chained after it (next_pass) go into the pass slots; num_passes becomes
 * their count (1 for NULL). */
void render_job_set_photon_map(struct render_job *job, struct photon_map **map);
/* num_passes slots for maps installed one by one (passes 0: no maps, one pass). Not while
 * rendering. */
void render_job_set_passes(struct render_job *job, uint32_t passes);
/* Takes ownership of *map (set to NULL) as pass `pass`'s map (< num_passes), replacing the
 * one there. Only pass `pass`'s view changes: render threads may render other passes
 * meanwhile, provided a unit of this pass is handed to them only after this returns. A
 * NULL *map drops (frees) the pass's map: then no unit of this pass may be rendering. */
void render_job_set_pass_map(struct render_job *job, uint32_t pass, struct photon_map **map);
/* Pass `pass`'s map, or NULL. */
const struct photon_map *render_job_pass_map(const struct render_job *job, uint32_t pass);
/* The media state pass `pass` (< num_passes) renders with: the job's, with that pass's map. */
const struct media_job *render_job_pass_media(const struct render_job *job, uint32_t pass);
/* Frees what the job built and owns (not the scene); the job itself is the caller's
 * storage. */
void render_job_fini(struct render_job *job);

#endif
