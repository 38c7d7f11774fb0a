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
/* 0 on success (also when the scene has no media: nothing is done), -1 logged. A second
 * call replaces the volume blob among the files. With a photon map, the frame renders in
 * progressive passes (--passes, render.passes, default 8), one map each, all in the blob;
 * scene->settings.spp is raised to a multiple of them (ceil(spp / P) per pass). *passes
 * gets their number (1 without a photon map). */
int master_media_prepare(struct scene *scene, const struct master_opts *o, uint32_t frame, struct asset_dir *assets,
                         uint32_t *passes);

#endif
