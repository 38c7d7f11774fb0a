/* The master: loads the scene, publishes its files as blobs, starts local workers,
 * schedules tiles over a ROUTER socket, checks and keeps each returned EXR tile chunk,
 * and assembles the tiled EXR (atomically: temporary file, fsync, rename). Called by
 * master/main.c. */
#ifndef BRUME_MASTER_H
#define BRUME_MASTER_H
#include "opts.h"

/* Renders the frame (or each frame of the range) and writes the run's counters to
 * OUT.stats.json (OUT as given to -o), on failure too; returns 0 on success, 1 on failure
 * (one error line, the last thing the master prints). */
int master_run(const struct master_opts *opts);

#endif
