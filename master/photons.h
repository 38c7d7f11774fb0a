/* The master's media preparation: applies the command-line media overrides, runs the
 * photon pass when the scene needs one (or logs why not, with the bound used) and
 * publishes the volume blob (settings + photon map) among the job's files, so that it
 * travels to every worker, late joiners included, and enters the scene hash. Called by
 * master.c's load_scene, once per job. */
#ifndef BRUME_MASTER_PHOTONS_H
#define BRUME_MASTER_PHOTONS_H
#include "asset.h"
#include "master.h"
#include "scene.h"

/* 0 on success (also when the scene has no media: nothing is done), -1 logged. */
int master_media_prepare(struct scene *scene, const struct master_opts *o, uint32_t frame, struct asset_dir *assets);

#endif
