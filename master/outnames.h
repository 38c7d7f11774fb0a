/* The names a run writes (each frame's EXR and journal, OUT.stats.json, the preview PNG)
 * checked against the files the scene read, so `-o scene.json` or `-o model.obj` is
 * refused before anything is rendered instead of destroying the input; so is a preview
 * named like the EXR, its journal or stats file, which it would replace. Called by
 * master/master.c once the scene is parsed; reads the file system, writes nothing. */
#ifndef BRUME_OUTNAMES_H
#define BRUME_OUTNAMES_H
#include <stddef.h>
#include "base/asset.h"
#include "opts.h"

/* 0 when no output name of the run names a file in inputs (same device and inode, or
 * the same resolved path) and the preview names none of the run's other outputs; else -1
 * with one line in err naming both. */
int outnames_check(const struct master_opts *o, const struct asset_dir *inputs, char *err, size_t errlen);

/* The run's stats file: OUT.stats.json, OUT the -o argument as given, or for a --frames
 * run of one frame (a farm's unit: a job array's task) that frame's output name, so that
 * tasks of one array writing frames of one -o each keep their own. 0, or -1 when it does
 * not fit in outlen. */
int outnames_stats_path(const struct master_opts *o, char *out, size_t outlen);

#endif
