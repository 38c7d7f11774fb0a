/* The master's media preparation: applies the command-line media overrides, runs the
 * photon pass when the scene needs one (or logs why not, with the bound used) and
 * publishes the volume blob (settings + photon map) among the job's files, so that it
 * travels to every worker, late joiners included, and enters the scene hash. Called by
 * master.c's load_scene for the first frame, and again for each frame of a range when
 * master_media_per_frame says the map depends on the frame. */
#ifndef BRUME_MASTER_PHOTONS_H
#define BRUME_MASTER_PHOTONS_H
#include "base/asset.h"
#include "opts.h"
#include "scene/scene.h"

/* 1 when the photon map depends on the frame: the scene has a photon pass and geometry
 * that moves (rigid keys or deformation frames), so each frame gets its own map. A still
 * scene's map is the same for every frame: built once, reused. */
int master_media_per_frame(const struct scene *scene);
/* 0 on success (also when the scene has no media: nothing is done), -1 logged. Settles the
 * media settings (command-line overrides) and publishes them as the volume blob among the
 * files (a second call replaces it). With a photon map, the frame renders in progressive
 * passes (`asked`, the master's count, or 8 when 0), one map each; scene->settings.spp is
 * raised to a multiple of them (ceil(spp / P) per pass) and *photon_maps gets P (0
 * without a photon map). The maps themselves are traced by a photon_tracer. */
int master_media_prepare(struct scene *scene, const struct master_opts *o, uint32_t frame, struct asset_dir *assets,
                         uint32_t asked, uint32_t *photon_maps);
/* Raises rs->spp to the next multiple of passes (ceil(spp / passes) samples per pass, logged
 * when it changes). 0, or -1 (logged) when that exceeds SCENE_MAX_SPP. */
struct render_settings;
int master_passes_fit(struct render_settings *rs, uint32_t passes);

/* Traces the P maps of a frame on a thread of its own, in pass order, while the master
 * renders: map p is a pure function of (scene, seed, frame, p) (volume map, then surface
 * map; photon_map_serialise's bytes). The scene must not change while it runs. Only the
 * first `want` maps are traced until photon_tracer_want raises it (an adaptive render
 * wants the passes its rounds have given out: the cap's maps would be traced for nothing,
 * on cores the workers need). */
struct photon_tracer;
struct blob_hash;
struct photon_tracer *photon_tracer_new(const struct scene *scene, const struct master_opts *o, uint32_t frame,
                                        uint32_t passes, uint32_t want, char *err, size_t errlen);
/* Maps 0..maps-1 are wanted (at most P; a lower count than before changes nothing). */
void photon_tracer_want(struct photon_tracer *t, uint32_t maps);
/* The next map in pass order once traced: 1 with *pass, *map (the caller frees), *size,
 * the seconds it took and, unless NULL, its blob name and chunk list (*chunks: the caller
 * frees; both from the tracer's one pass over the map, blob_name_of_chunks); 0 when it is
 * not ready yet; -1 with err when tracing failed. */
int photon_tracer_poll(struct photon_tracer *t, uint32_t *pass, uint8_t **map, size_t *size, double *seconds,
                       struct blob_hash *hash, struct blob_hash **chunks, char *err, size_t errlen);
/* Joins the thread and frees what was not taken; *t becomes NULL (NULL is fine). With
 * stop, unfinished tracing is stopped (photon_trace_request_stop: for good, in this
 * process; only for a master that is leaving), else the wanted maps are waited for (none
 * past them is traced). */
void photon_tracer_free(struct photon_tracer **t, int stop);

#endif
